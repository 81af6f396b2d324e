// deploy/experiments/paper_grid.sh publish: what a grid leaves under runs/ is copied into a
// results page that can be committed, and nothing unfinished or machine-specific goes with it.
#include <gtest/gtest.h>

#include <chrono>

#include "child_process.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/nn/serialize.h"
#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const fs::path kSource = INDRIVE_SOURCE_DIR;
const fs::path kBin = INDRIVE_BIN_DIR;

using testing::write_text;

// Two metrics lines of a pretraining run, with what the summary reads.
const std::string kPretrainMetrics =
    "{\"env_steps\": 100, \"expl/entropy\": 1.5, \"expl/return_scale\": 2.0, "
    "\"intrinsic/raw_reward\": 0.001, \"expl/reward\": 1.0}\n"
    "{\"env_steps\": 200, \"expl/entropy\": 0.5, \"expl/return_scale\": 4.0, "
    "\"intrinsic/raw_reward\": 0.002, \"expl/reward\": 2.0, "
    "\"episode_length_last20\": 300, \"episode_reach_last20\": 7, "
    "\"coverage_fraction_visited\": 0.5}\n";

// A finished run directory as `paper_grid.sh chain` leaves it (DONE, metrics, resolved config
// naming paths on this machine, the training run's whole-model snapshot file).
void write_finished_run(const fs::path& dir, agent::Agent& agent,
                        const agent::AgentConfig& config) {
  write_text(dir / "metrics.jsonl", kPretrainMetrics);
  write_text(dir / "config.yaml",
             "run:\n  dir: " + (kSource / "runs/paper-grid/s0/pretrain-disag").string() + "\n");
  const nn::ParamGroup* whole[] = {&agent.world_model().params(),
                                   &agent.exploration().actor_params()};
  agent::write_snapshot_file(dir / "snapshot.params", nn::save_params(whole), config);
  EpisodeCsvWriter(dir / "train-episodes.csv")
      .write({.run_id = "pretrain-disag", .eval_kind = "training", .steps = 150});
  write_text(dir / "DONE", "");
}

TEST(PaperGridPublish, CopiesFinishedRunsAndEvaluationsAndLeavesOutTheRest) {
  testing::TempDir dir;
  const fs::path out = dir.path() / "grid", page = dir.path() / "page";
  const agent::AgentConfig tiny = agent::preset("tiny");
  agent::Agent agent(tiny);
  write_finished_run(out / "s0/pretrain-disag", agent, tiny);
  // A run stopped midway (no DONE) and a finished evaluation with one evaluator's rows.
  write_text(out / "s0/finetune-lf-disag/metrics.jsonl", "{\"env_steps\": 10}\n");
  const fs::path rows = kSource / "docs/results/method/eval/s0-zeroshot-disag-evaluator-0.csv";
  fs::create_directories(out / "s0/zeroshot-disag/eval");
  fs::copy_file(rows, out / "s0/zeroshot-disag/eval/evaluator-0.csv");
  write_text(out / "s0/zeroshot-disag/DONE", "");

  const fs::path log = dir.path() / "publish.log";
  testing::Child publish(
      {"/bin/bash", (kSource / "deploy/experiments/paper_grid.sh").string(), "publish", "--out",
       out.string(), "--page", page.string(), "--bin", kBin.string()},
      log);
  ASSERT_EQ(publish.wait(120s), 0) << testing::slurp(log);
  const std::string said = testing::slurp(log);

  EXPECT_EQ(testing::slurp(page / "runs/s0-pretrain-disag/metrics.jsonl"),
            testing::slurp(out / "s0/pretrain-disag/metrics.jsonl"));
  EXPECT_EQ(testing::slurp(page / "runs/s0-pretrain-disag/train-episodes.csv"),
            testing::slurp(out / "s0/pretrain-disag/train-episodes.csv"));
  const std::string config = testing::slurp(page / "runs/s0-pretrain-disag/config.yaml");
  EXPECT_EQ(config.find(kSource.string()), std::string::npos) << config;
  EXPECT_NE(config.find("dir: runs/paper-grid/s0/pretrain-disag"), std::string::npos) << config;
  // Seed 0 is the default of --snapshot-seeds: its file is rewritten with what acting runs.
  EXPECT_EQ(agent::read_snapshot_file(page / "snapshots/s0-pretrain-disag.params").blob,
            agent.snapshot());
  EXPECT_EQ(testing::slurp(page / "eval/s0-zeroshot-disag-evaluator-0.csv"), testing::slurp(rows));
  EXPECT_FALSE(fs::exists(page / "runs/s0-finetune-lf-disag"));
  EXPECT_NE(said.find("not finished, left out: " + (out / "s0/finetune-lf-disag").string()),
            std::string::npos)
      << said;
  EXPECT_NE(testing::slurp(page / "pretrain-summary.md").find("| s0 | disag | 200 | 0.50 | 300"),
            std::string::npos)
      << testing::slurp(page / "pretrain-summary.md");
  EXPECT_NE(testing::slurp(page / "report.md").find("Zero-shot"), std::string::npos)
      << testing::slurp(page / "report.md");

  // Without --page the command says what it needs.
  const fs::path bad_log = dir.path() / "bad.log";
  testing::Child bad({"/bin/bash", (kSource / "deploy/experiments/paper_grid.sh").string(),
                      "publish", "--out", out.string(), "--bin", kBin.string()},
                     bad_log);
  EXPECT_EQ(bad.wait(30s), 2);
  EXPECT_NE(testing::slurp(bad_log).find("--page"), std::string::npos) << testing::slurp(bad_log);
}

// The repository path is taken literally when a run's config is made relative, whatever
// characters it holds (a copy of the script in a folder with '#', '.', ' ' and '&').
TEST(PaperGridPublish, MachinePathsAreRemovedLiterally) {
  testing::TempDir dir;
  const fs::path root = dir.path() / "repo #1 & co.x";
  fs::create_directories(root / "deploy/experiments");
  fs::copy_file(kSource / "deploy/experiments/paper_grid.sh",
                root / "deploy/experiments/paper_grid.sh");
  const fs::path out = dir.path() / "grid", page = dir.path() / "page";
  const fs::path run = out / "s1/pretrain-rnd";
  write_text(run / "metrics.jsonl", kPretrainMetrics);
  write_text(run / "config.yaml", "run:\n  dir: " + (root / "runs/g/s1/pretrain-rnd").string() +
                                      "\n  other: /elsewhere/repo #1 & coAx/kept\n");
  write_text(run / "DONE", "");
  fs::create_directories(out / "s1/zeroshot-rnd/eval");
  fs::copy_file(kSource / "docs/results/method/eval/s1-zeroshot-rnd-evaluator-0.csv",
                out / "s1/zeroshot-rnd/eval/evaluator-0.csv");
  write_text(out / "s1/zeroshot-rnd/DONE", "");
  const fs::path log = dir.path() / "publish.log";
  testing::Child publish(
      {"/bin/bash", (root / "deploy/experiments/paper_grid.sh").string(), "publish", "--out",
       out.string(), "--page", page.string(), "--bin", kBin.string(), "--snapshot-seeds", "0"},
      log);
  ASSERT_EQ(publish.wait(120s), 0) << testing::slurp(log);
  EXPECT_EQ(testing::slurp(page / "runs/s1-pretrain-rnd/config.yaml"),
            "run:\n  dir: runs/g/s1/pretrain-rnd\n  other: /elsewhere/repo #1 & coAx/kept\n");
}

// chain --trained-in: the training runs of another --out are linked, not trained again (to
// evaluate the same policies on another route set), and a run missing there is an error that
// says where to train it, before anything is trained here.
TEST(PaperGridChain, TrainedInLinksTheOtherGridsFinishedRunsInsteadOfTraining) {
  testing::TempDir dir;
  const fs::path trained = dir.path() / "grid", out = dir.path() / "grid-left";
  write_text(trained / "s0/pretrain-disag/DONE", "");
  write_text(trained / "s0/pretrain-disag/snapshot.params", "weights");
  const auto chain = [&](const std::string& method, const fs::path& log) {
    testing::Child run(
        {"/bin/bash", (kSource / "deploy/experiments/paper_grid.sh").string(), "chain", "--out",
         out.string(), "--trained-in", trained.string(), "--route-set", "left", "--seed", "0",
         "--method", method, "--stages", "pretrain", "--bin", kBin.string()},
        log);
    return run.wait(60s);
  };
  const fs::path linked_log = dir.path() / "linked.log";
  ASSERT_EQ(chain("disag", linked_log), 0) << testing::slurp(linked_log);
  const fs::path linked = out / "s0/pretrain-disag";
  ASSERT_TRUE(fs::is_symlink(linked)) << testing::slurp(linked_log);
  EXPECT_EQ(fs::canonical(linked), fs::canonical(trained / "s0/pretrain-disag"));
  EXPECT_EQ(testing::slurp(linked / "snapshot.params"), "weights");
  EXPECT_FALSE(fs::exists(trained / "s0/pretrain-disag/train.log")) << "nothing was trained";

  const fs::path missing_log = dir.path() / "missing.log";
  EXPECT_NE(chain("icm", missing_log), 0);
  const std::string said = testing::slurp(missing_log);
  EXPECT_NE(said.find("pretrain-icm is not a finished run; train it there first"),
            std::string::npos)
      << said;
  EXPECT_FALSE(fs::exists(out / "s0/pretrain-icm"));
}

// --towns carla: every evaluation runs on the CARLA towns, once per protocol, and the training
// runs start on carla_town01. Stand-in programs record how they were called.
TEST(PaperGridChain, CarlaTownsEvaluateUnderBothProtocols) {
  testing::TempDir dir;
  const fs::path bin = dir.path() / "bin", out = dir.path() / "grid";
  for (const std::string program : {"indrive", "indrive-actor", "indrive-train-local"}) {
    write_text(bin / program,
               "#!/bin/sh\necho \"$*\" >> \"" + (dir.path() / "calls").string() + "\"\n");
    fs::permissions(bin / program, fs::perms::owner_all);
  }
  write_text(out / "s0/pretrain-disag/DONE", "");
  write_text(out / "s0/pretrain-disag/snapshot.params", "weights");
  const fs::path log = dir.path() / "chain.log";
  testing::Child run({"/bin/bash", (kSource / "deploy/experiments/paper_grid.sh").string(), "chain",
                      "--out", out.string(), "--towns", "carla", "--code-budget", "5000", "--seed",
                      "0", "--method", "disag", "--stages", "zeroshot", "--bin", bin.string()},
                     log);
  ASSERT_EQ(run.wait(60s), 0) << testing::slurp(log);
  const std::string calls = testing::slurp(dir.path() / "calls");
  // Two evaluators per protocol, each on both CARLA towns.
  std::size_t evaluators = 0, code = 0;
  for (std::size_t at = calls.find("--evaluate"); at != std::string::npos;
       at = calls.find("--evaluate", at + 1)) {
    const std::string line = calls.substr(at, calls.find('\n', at) - at);
    ++evaluators;
    EXPECT_NE(line.find("eval.towns=carla_town01,carla_town02"), std::string::npos) << line;
    if (line.find("eval.protocol=indrive_code") != std::string::npos) {
      ++code;
      EXPECT_NE(line.find("zeroshot-disag-code"), std::string::npos) << line;
      EXPECT_NE(line.find("eval.indrive_code_budget_steps=5000"), std::string::npos) << line;
    } else {
      EXPECT_NE(line.find("eval.protocol=strict"), std::string::npos) << line;
    }
  }
  EXPECT_EQ(evaluators, 4u) << calls;
  EXPECT_EQ(code, 2u) << calls;
  EXPECT_TRUE(fs::exists(out / "s0/zeroshot-disag/DONE"));
  EXPECT_TRUE(fs::exists(out / "s0/zeroshot-disag-code/DONE"));

  const fs::path bad_log = dir.path() / "bad.log";
  testing::Child bad({"/bin/bash", (kSource / "deploy/experiments/paper_grid.sh").string(), "chain",
                      "--towns", "carla02", "--bin", bin.string()},
                     bad_log);
  EXPECT_EQ(bad.wait(60s), 2);
  EXPECT_NE(testing::slurp(bad_log).find("--towns must be ours"), std::string::npos);
}

// An evaluation stopped part-way (an evaluator failed or was killed: no DONE) goes on with the
// rows it has when the same policy is evaluated with the same settings, and starts afresh when
// the snapshot changed. Stand-in programs record their calls and exit with a chosen code.
TEST(PaperGridChain, AStoppedEvaluationGoesOnOnlyForTheSameSnapshot) {
  testing::TempDir dir;
  const fs::path bin = dir.path() / "bin", out = dir.path() / "grid";
  const fs::path calls = dir.path() / "calls", code = dir.path() / "exit-code";
  for (const std::string program : {"indrive", "indrive-actor", "indrive-train-local"}) {
    write_text(bin / program, "#!/bin/sh\necho \"$*\" >> \"" + calls.string() +
                                  "\"\nexit $(cat \"" + code.string() + "\")\n");
    fs::permissions(bin / program, fs::perms::owner_all);
  }
  write_text(out / "s0/pretrain-disag/DONE", "");
  write_text(out / "s0/pretrain-disag/snapshot.params", "weights");
  const fs::path eval = out / "s0/zeroshot-disag";
  int runs = 0;
  const auto chain = [&](const std::string& exit_code) {
    write_text(code, exit_code);
    const fs::path log = dir.path() / ("chain-" + std::to_string(++runs) + ".log");
    testing::Child run({"/bin/bash", (kSource / "deploy/experiments/paper_grid.sh").string(),
                        "chain", "--out", out.string(), "--seed", "0", "--method", "disag",
                        "--stages", "zeroshot", "--bin", bin.string()},
                       log);
    const int status = run.wait(60s);  // before the log is read
    return std::make_pair(status, testing::slurp(log));
  };

  // The evaluators fail: no DONE; the rows they wrote stay.
  EXPECT_NE(chain("1").first, 0);
  EXPECT_FALSE(fs::exists(eval / "DONE"));
  EXPECT_NE(testing::slurp(calls).find("eval.resume=true"), std::string::npos);
  write_text(eval / "eval/evaluator-0.csv", "rows of the stopped evaluation\n");

  // Run again, same snapshot: it goes on with them.
  auto [status, log] = chain("0");
  ASSERT_EQ(status, 0) << log;
  EXPECT_NE(log.find("going on with the episodes not yet in its eval/"), std::string::npos) << log;
  EXPECT_TRUE(fs::exists(eval / "eval/evaluator-0.csv"));
  EXPECT_TRUE(fs::exists(eval / "DONE"));

  // Another snapshot (retrained): the old rows are dropped.
  fs::remove(eval / "DONE");
  write_text(out / "s0/pretrain-disag/snapshot.params", "other weights");
  std::tie(status, log) = chain("0");
  ASSERT_EQ(status, 0) << log;
  EXPECT_EQ(log.find("going on with"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(eval / "eval/evaluator-0.csv"));
}

}  // namespace
}  // namespace indrive
