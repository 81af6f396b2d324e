#include "indrive/basics/check.h"

#include <gtest/gtest.h>

namespace {

TEST(CheckDeathTest, FailedCheckAbortsWithFileLineAndMessage) {
  const int rows = 3;
  EXPECT_DEATH({ INDRIVE_CHECK(rows == 4) << "rows must be 4"; },
               "check_test.cc:[0-9]+: check failed: rows == 4 rows must be 4");
  EXPECT_DEATH({ INDRIVE_CHECK_EQ(rows, 5) << "mismatch"; }, "rows = 3, 5 = 5: mismatch");
}

TEST(Check, PassingCheckDoesNothing) {
  int evaluated = 0;
  INDRIVE_CHECK(true) << ++evaluated;
  EXPECT_EQ(evaluated, 0);
}

}  // namespace
