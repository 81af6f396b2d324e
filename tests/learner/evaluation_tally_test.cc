#include "indrive/learner/evaluation_tally.h"

#include <gtest/gtest.h>

namespace indrive::learner {
namespace {

msg::EpisodeResult result(std::uint64_t version, const std::string& town, bool success,
                          float completion) {
  msg::EpisodeResult r;
  r.sender_role(msg::ROLE_EVALUATOR);
  r.policy_version(version);
  r.town(town);
  r.success(success);
  r.route_completion(completion);
  return r;
}

TEST(EvaluationTallyTest, NoEvaluatorMeansNoEvalFields) {
  EvaluationTally tally;
  nlohmann::json record = nlohmann::json::object();
  tally.write_new(record);
  EXPECT_TRUE(record.empty()) << record.dump();
}

TEST(EvaluationTallyTest, TheNewestVersionIsReportedOverallAndPerTown) {
  EvaluationTally tally;
  tally.add(result(3, "town01", true, 1.0f));
  tally.add(result(4, "town01", true, 1.0f));
  tally.add(result(4, "town02", false, 0.5f));
  tally.add(result(4, "town02", false, 0.0f));
  tally.add(result(3, "town02", false, 0.1f));  // a late result of an older version
  nlohmann::json record = nlohmann::json::object();
  tally.write_new(record);
  EXPECT_EQ(record["eval_results"], 5);
  EXPECT_EQ(record["eval_policy_version"], 4);
  EXPECT_EQ(record["eval_episodes"], 3);
  EXPECT_DOUBLE_EQ(record["eval_success_rate"].get<double>(), 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(record["eval_route_completion"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(record["eval_town01_success_rate"].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(record["eval_town02_success_rate"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(record["eval_town02_route_completion"].get<double>(), 0.25);
}

TEST(EvaluationTallyTest, ALineWithoutNewResultsCarriesOnlyTheCount) {
  EvaluationTally tally;
  tally.add(result(1, "town02", true, 1.0f));
  nlohmann::json first = nlohmann::json::object();
  tally.write_new(first);
  ASSERT_TRUE(first.contains("eval_success_rate"));
  nlohmann::json second = nlohmann::json::object();
  tally.write_new(second);
  EXPECT_EQ(second["eval_results"], 1);
  EXPECT_FALSE(second.contains("eval_success_rate")) << second.dump();
  // More episodes of the same version accumulate across lines.
  tally.add(result(1, "town02", false, 0.0f));
  nlohmann::json third = nlohmann::json::object();
  tally.write_new(third);
  EXPECT_EQ(third["eval_episodes"], 2);
  EXPECT_DOUBLE_EQ(third["eval_success_rate"].get<double>(), 0.5);
}

TEST(EvaluationTallyTest, TownsBecomeKeysAndCompletionIsClamped) {
  EXPECT_EQ(EvaluationTally::key_of("maps/x.xodr"), "maps_x_xodr");
  EXPECT_EQ(EvaluationTally::key_of(""), "unnamed");
  EvaluationTally tally;
  tally.add(result(2, "maps/x.xodr", false, 7.0f));  // a hostile sender's value
  nlohmann::json record = nlohmann::json::object();
  tally.write_new(record);
  EXPECT_DOUBLE_EQ(record["eval_maps_x_xodr_route_completion"].get<double>(), 1.0);
}

}  // namespace
}  // namespace indrive::learner
