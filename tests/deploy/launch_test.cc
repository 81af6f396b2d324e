#include "indrive/deploy/launch.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "testing.h"

namespace indrive::deploy {
namespace {

TEST(LaunchPlan, StartsOneLearnerActorsAndEvaluatorsWithSharedArguments) {
  testing::TempDir dir;
  const LaunchOptions options{.config = "smoke.yaml",
                              .runs_dir = dir.path(),
                              .run_id = "smoke",
                              .actors = 2,
                              .evaluators = 1,
                              .domain_id = 7,
                              .dds_security = "/srv/run-security",
                              .overrides = {"train.updates=10"},
                              .bin_dir = "/opt/indrive/bin"};
  const auto plan = launch_plan(options);
  ASSERT_EQ(plan.size(), 4u);
  EXPECT_EQ(plan[0].name, "learner");
  EXPECT_TRUE(plan[0].essential);
  EXPECT_FALSE(plan[0].finishes_run);
  EXPECT_EQ(plan[0].restart, RestartPolicy::kOnFailure);  // resumes from its checkpoint
  EXPECT_GT(plan[0].backoff.max_restarts, 0);
  EXPECT_EQ(plan[0].argv[0], "/opt/indrive/bin/indrive-learner");
  EXPECT_EQ(plan[1].name, "actor-0");
  EXPECT_EQ(plan[2].name, "actor-1");
  EXPECT_EQ(plan[2].restart, RestartPolicy::kOnFailure);
  EXPECT_EQ(plan[3].name, "evaluator-0");
  EXPECT_EQ(plan[3].argv[1], "--evaluate");
  EXPECT_TRUE(plan[3].finishes_run);  // evaluates the final snapshot after the learner ends
  EXPECT_FALSE(plan[1].finishes_run);
  for (const auto& spec : plan) {
    const auto& a = spec.argv;
    auto after = [&](const std::string& flag) {
      const auto it = std::find(a.begin(), a.end(), flag);
      return it == a.end() || it + 1 == a.end() ? std::string() : *(it + 1);
    };
    EXPECT_EQ(after("--config"), "smoke.yaml") << spec.name;
    EXPECT_EQ(after("--run-dir"), (dir.path() / "smoke").string()) << spec.name;
    EXPECT_EQ(after("--domain"), "7") << spec.name;
    // One folder for all: each program picks its own role's files from it.
    EXPECT_EQ(after("--dds-security"), "/srv/run-security") << spec.name;
    EXPECT_EQ(after("--set"), "train.updates=10") << spec.name;
    EXPECT_EQ(spec.log_file.parent_path(), dir.path() / "smoke" / "logs") << spec.name;
  }
  EXPECT_TRUE(std::filesystem::is_directory(dir.path() / "smoke" / "logs"));
}

}  // namespace
}  // namespace indrive::deploy
