#include "indrive/basics/log.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace indrive::log {
namespace {

struct Captured {
  Level level;
  std::string category;
  std::string message;
};

class LogTest : public ::testing::Test {
 protected:
  void SetUp() override {
    set_sink([this](const Record& r) {
      lines_.push_back({r.level, std::string(r.category), std::string(r.message)});
    });
    set_level(Level::kInfo);
  }
  void TearDown() override {
    set_sink({});
    set_level(Level::kInfo);
  }
  std::vector<Captured> lines_;
};

TEST_F(LogTest, SinkReceivesLevelCategoryAndMessage) {
  INDRIVE_LOG(kWarn, "dds") << "dropped " << 3 << " chunks";
  ASSERT_EQ(lines_.size(), 1u);
  EXPECT_EQ(lines_[0].level, Level::kWarn);
  EXPECT_EQ(lines_[0].category, "dds");
  EXPECT_EQ(lines_[0].message, "dropped 3 chunks");
}

TEST_F(LogTest, RecordsBelowTheLevelAreNotFormatted) {
  int evaluated = 0;
  auto side_effect = [&] { return ++evaluated; };
  INDRIVE_LOG(kDebug, "nn") << side_effect();
  EXPECT_TRUE(lines_.empty());
  EXPECT_EQ(evaluated, 0);
  set_level(Level::kDebug);
  INDRIVE_LOG(kDebug, "nn") << side_effect();
  EXPECT_EQ(lines_.size(), 1u);
  EXPECT_EQ(evaluated, 1);
}

TEST(LogLevel, ParsesNamesAndRejectsOthers) {
  EXPECT_EQ(parse_level("debug"), Level::kDebug);
  EXPECT_EQ(parse_level("error"), Level::kError);
  EXPECT_EQ(level_name(Level::kWarn), "warn");
  EXPECT_THROW(parse_level("verbose"), std::invalid_argument);
}

}  // namespace
}  // namespace indrive::log
