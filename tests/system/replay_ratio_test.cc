// The replay ratio with real processes (learner and two actors, tiny preset): it holds over a
// run whatever the speed of the machine, and the async mode lifts it so that a slow learner
// does not slow the actors down. Each test prints the figures it measured.
#include <gtest/gtest.h>
#include <signal.h>

#include <cstdio>
#include <fstream>
#include <regex>

#include "process_harness.h"
#include "testing.h"

namespace indrive {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using testing::Child;
using testing::ProcessWatch;
using testing::SeenHeartbeat;
using testing::wait_until;

constexpr double kStepsPerUpdate = 8 * 16;  // tiny preset: batch 8 x length 16

class ReplayRatioTest : public ::testing::Test {
 protected:
  void SetUp() override {
    domain_ = testing::unique_domain_id();
    config_ = dir_.path() / "ratio.yaml";
    std::ofstream(config_) << testing::tiny_service_config();
  }

  // A learner and two actors of run `run_id` with the same overrides.
  struct Run {
    fs::path run_dir;
    std::unique_ptr<Child> learner, actor0, actor1;
  };
  Run start(const std::string& run_id, const std::vector<std::string>& overrides) {
    Run run{.run_dir = dir_.path() / "runs" / run_id};
    auto argv = [&](const std::string& program) {
      return testing::service_args(program, config_, run.run_dir, domain_, profile_, overrides);
    };
    run.learner = std::make_unique<Child>(argv("indrive-learner"), log(run_id, "learner"));
    for (int id : {0, 1}) {
      auto args = argv("indrive-actor");
      args.insert(args.end(), {"--id", std::to_string(id)});
      (id == 0 ? run.actor0 : run.actor1) =
          std::make_unique<Child>(args, log(run_id, "actor-" + std::to_string(id)));
    }
    return run;
  }
  fs::path log(const std::string& run_id, const std::string& name) const {
    return dir_.path() / (run_id + "-" + name + ".log");
  }
  std::string logs(const std::string& run_id) const {
    std::string text;
    for (const char* name : {"learner", "actor-0", "actor-1"}) {
      std::string body = testing::slurp(log(run_id, name));
      if (body.size() > 6000) body = "...\n" + body.substr(body.size() - 6000);
      text += std::string("----- ") + name + "\n" + body;
    }
    return text;
  }
  // Share of an actor's run time spent waiting at the allowance (its last log line).
  double wait_share(const std::string& run_id, const std::string& actor) const {
    const std::string text = testing::slurp(log(run_id, actor));
    std::smatch match;
    if (!std::regex_search(text, match, std::regex("waited ([-+.eE0-9]+) s of ([-+.eE0-9]+) s"))) {
      return -1.0;
    }
    return std::stod(match[1]) / std::max(1e-9, std::stod(match[2]));
  }

  testing::TempDir dir_{"indrive-ratio"};
  int domain_ = 0;
  fs::path config_;
  fs::path profile_ = testing::source_path("deploy/dds/single_host.xml");
};

TEST_F(ReplayRatioTest, HoldsWithinFivePercentOverARunWithTwoActors) {
  constexpr std::int64_t kBudget = 1600;
  constexpr double kRatio = 4.0;  // one update per 32 env steps
  // Two actors may each run ahead of training by one update's steps, the slack and an open
  // chunk (see keeps_ratio).
  constexpr double kLead = 2 * (32 + 16 + 16);
  // snapshot_every above the run's updates: the only snapshot is the final one.
  Run run = start("limited", {"run.budget_env_steps=" + std::to_string(kBudget),
                              "learner.replay_ratio=4", "learner.snapshot_every=100000"});
  // The learner ends the run by itself once the budget's updates are done.
  ASSERT_EQ(run.learner->wait(150s), 0) << logs("limited");
  run.actor0->signal(SIGTERM);
  run.actor1->signal(SIGTERM);
  EXPECT_EQ(run.actor0->wait(30s), 0) << logs("limited");
  EXPECT_EQ(run.actor1->wait(30s), 0) << logs("limited");

  // replayed / env steps at every metrics line: never above the ratio; from half the budget on
  // (when the learner has caught up with the prefill, which both actors overshoot because each
  // counts only its own unsent steps) never further behind than the actors' lead; over the
  // whole run within 5%.
  const auto lines = testing::read_metrics(run.run_dir / "metrics.jsonl");
  ASSERT_GE(lines.size(), 3u);
  double low = 1e9, high = 0.0;
  int late_lines = 0;
  for (const auto& line : lines) {
    const double env_steps = line.value("env_steps", 0.0);
    EXPECT_TRUE(testing::keeps_ratio(line, kRatio, kStepsPerUpdate, env_steps)) << line.dump();
    if (env_steps < kBudget / 2) continue;
    EXPECT_TRUE(testing::keeps_ratio(line, kRatio, kStepsPerUpdate, kLead)) << line.dump();
    const double ratio = line.value("updates", 0.0) * kStepsPerUpdate / env_steps;
    low = std::min(low, ratio);
    high = std::max(high, ratio);
    ++late_lines;
  }
  const auto& last = lines.back();
  const double final_ratio =
      last.value("updates", 0.0) * kStepsPerUpdate / last.value("env_steps", 1.0);
  EXPECT_NEAR(final_ratio, kRatio, kRatio * 0.05) << last.dump();
  EXPECT_GE(last.value("env_steps", 0), kBudget);
  // The budget's end publishes the final parameters, so evaluators of the run have a policy.
  EXPECT_EQ(last.value("snapshots_published", -1), 1) << last.dump();
  std::printf(
      "[figures] replay ratio over a %lld-step run with 2 actors: final %.3f (target %.1f, "
      "%lld env steps, %lld updates); %.3f..%.3f over %d metrics lines after half the budget; "
      "actors waited %.0f%% and %.0f%% of their time\n",
      static_cast<long long>(kBudget), final_ratio, kRatio,
      static_cast<long long>(last.value("env_steps", 0)),
      static_cast<long long>(last.value("updates", 0)), low, high, late_lines,
      100.0 * wait_share("limited", "actor-0"), 100.0 * wait_share("limited", "actor-1"));
}

TEST_F(ReplayRatioTest, AsyncModeIsNotLimitedByASlowLearner) {
  // Replay ratio 128 makes the learner the bottleneck: one update (8 x 16 steps) per env step.
  // Each mode runs 6 s past the learner's first update; the actors' own stop lines give their
  // steps per second and the share of time they waited at the allowance.
  struct Measured {
    double steps_per_s[2] = {0.0, 0.0};
    double wait_share[2] = {0.0, 0.0};
    double ratio = 0.0;
  };
  auto measure = [&](const std::string& run_id, bool async) {
    Measured out;
    ProcessWatch watch(domain_, profile_);
    Run run = start(run_id, {"learner.replay_ratio=128",
                             std::string("learner.async=") + (async ? "true" : "false")});
    SeenHeartbeat beat;
    EXPECT_TRUE(wait_until(90s, [&] {
      return watch.heartbeat(msg::ROLE_LEARNER, 0, beat) && beat.updates > 0;
    })) << logs(run_id);
    std::this_thread::sleep_for(6s);
    run.actor0->signal(SIGTERM);
    run.actor1->signal(SIGTERM);
    EXPECT_EQ(run.actor0->wait(30s), 0) << logs(run_id);
    EXPECT_EQ(run.actor1->wait(30s), 0) << logs(run_id);
    if (watch.heartbeat(msg::ROLE_LEARNER, 0, beat)) {
      out.ratio = static_cast<double>(beat.updates) * kStepsPerUpdate /
                  std::max(1.0, static_cast<double>(beat.env_steps));
    }
    run.learner->signal(SIGTERM);
    EXPECT_EQ(run.learner->wait(60s), 0) << logs(run_id);
    for (int id : {0, 1}) {
      const std::string name = "actor-" + std::to_string(id);
      const std::string text = testing::slurp(log(run_id, name));
      std::smatch match;
      EXPECT_TRUE(std::regex_search(
          text, match,
          std::regex("stops: ([0-9]+) steps.*waited ([-+.eE0-9]+) s of ([-+.eE0-9]+) s")))
          << text;
      if (match.empty()) continue;
      const double total_s = std::max(1e-9, std::stod(match[3]));
      out.steps_per_s[id] = std::stod(match[1]) / total_s;
      out.wait_share[id] = std::stod(match[2]) / total_s;
    }
    return out;
  };
  const Measured limited = measure("limited", false);
  const Measured async = measure("async", true);
  std::printf(
      "[figures] slow learner (replay ratio 128): rate-limited actors %.1f and %.1f env "
      "steps/s, waited %.0f%%/%.0f%% (learner ratio so far %.1f, still catching up with the "
      "prefill both actors overshot); async actors %.1f and %.1f env steps/s, waited "
      "%.0f%%/%.0f%% (ratio %.2f)\n",
      limited.steps_per_s[0], limited.steps_per_s[1], 100 * limited.wait_share[0],
      100 * limited.wait_share[1], limited.ratio, async.steps_per_s[0], async.steps_per_s[1],
      100 * async.wait_share[0], 100 * async.wait_share[1], async.ratio);
  // Rate-limited actors spend most of their time waiting for the learner; async ones only
  // wait for the learner's first allowance at the start (which, on a machine loaded by other
  // jobs, can be a third of a short run), so they step clearly faster.
  for (int id : {0, 1}) {
    EXPECT_GT(limited.wait_share[id], 0.5) << "actor " << id;
    EXPECT_LT(async.wait_share[id], 0.5) << "actor " << id;
    EXPECT_GT(async.steps_per_s[id], 2.0 * limited.steps_per_s[id]) << "actor " << id;
  }
}

}  // namespace
}  // namespace indrive
