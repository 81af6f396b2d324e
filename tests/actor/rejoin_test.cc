#include "indrive/actor/rejoin.h"

#include <gtest/gtest.h>

namespace indrive::actor {
namespace {

TEST(RejoinSchedule, TheWaitDoublesPerUnansweredReplacementUpToTheCap) {
  RejoinSchedule schedule(20.0, 160.0);
  ASSERT_TRUE(schedule.enabled());
  EXPECT_DOUBLE_EQ(schedule.wait_s(), 20.0);
  const double expected[] = {40.0, 80.0, 160.0, 160.0, 160.0};
  for (double wait : expected) {
    schedule.replaced();
    EXPECT_DOUBLE_EQ(schedule.wait_s(), wait);
  }
  EXPECT_EQ(schedule.unanswered(), 5);
  for (int i = 0; i < 1000; ++i) schedule.replaced();  // days of waiting: still the cap
  EXPECT_DOUBLE_EQ(schedule.wait_s(), 160.0);
}

TEST(RejoinSchedule, HearingTheLearnerBringsBackTheShortWait) {
  RejoinSchedule schedule(20.0, 160.0);
  schedule.replaced();
  schedule.replaced();
  EXPECT_DOUBLE_EQ(schedule.wait_s(), 80.0);
  schedule.heard();
  EXPECT_EQ(schedule.unanswered(), 0);
  EXPECT_DOUBLE_EQ(schedule.wait_s(), 20.0);
}

TEST(RejoinSchedule, ACapBelowTheFirstWaitMeansAFixedWait) {
  RejoinSchedule fixed(20.0, 0.0);
  fixed.replaced();
  fixed.replaced();
  EXPECT_DOUBLE_EQ(fixed.wait_s(), 20.0);
}

TEST(RejoinSchedule, ZeroMeansNever) {
  EXPECT_FALSE(RejoinSchedule(0.0, 160.0).enabled());
  EXPECT_TRUE(RejoinSchedule(0.5, 160.0).enabled());
}

}  // namespace
}  // namespace indrive::actor
