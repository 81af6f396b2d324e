// Tests of page_writer.h: the learner's companion page writer. With stand-in programs: the
// command line, the last words through the pipe, a writer that fails, one that is missing. With
// the real `indrive dashboard`: a live page that follows appended metrics lines and ends with
// what the learner said, and a learner killed without a word.
#include "indrive/learner/page_writer.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include "child_process.h"
#include "testing.h"

namespace indrive::learner {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// A shell script that records its arguments and standard input, then exits with `code`.
fs::path stand_in(const fs::path& dir, int code) {
  const fs::path script = dir / "stand-in.sh";
  std::ofstream(script) << "#!/bin/sh\necho \"$@\" > " << (dir / "args").string() << "\ncat > "
                        << (dir / "stdin").string() << "\nexit " << code << "\n";
  fs::permissions(script, fs::perms::owner_all);
  return script;
}

bool eventually(std::chrono::milliseconds timeout, const std::function<bool()>& condition) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < until) {
    if (condition()) return true;
    std::this_thread::sleep_for(50ms);
  }
  return condition();
}

void append_metrics(const fs::path& run, int from, int to) {
  std::ofstream out(run / "metrics.jsonl", std::ios::app);
  for (int i = from; i < to; ++i) {
    out << "{\"env_steps\":" << 100 * i << ",\"updates\":" << 3 * i
        << ",\"wm/loss\":" << 10.0 / (i + 1) << ",\"expl/entropy\":" << 2.0 - 0.01 * i << "}\n";
  }
}

// The points of the newest write that logs/dashboard.log reports (-1 before the first).
long newest_points(const fs::path& run) {
  const std::string log = testing::slurp(run / "logs" / "dashboard.log");
  long points = -1;
  const std::regex written(R"((\d+) points)");
  for (auto it = std::sregex_iterator(log.begin(), log.end(), written);
       it != std::sregex_iterator(); ++it) {
    points = std::stol((*it)[1]);
  }
  return points;
}

TEST(PageWriterTest, StartsTheDashboardWatchAndHandsItTheLastWordsThroughThePipe) {
  testing::TempDir dir;
  const fs::path run = dir.path() / "run";
  PageWriter writer(stand_in(dir.path(), 0), run, 2.5);
  ASSERT_TRUE(writer.running());
  EXPECT_TRUE(writer.finish("ended: budget reached\nat 400 env steps"));
  EXPECT_EQ(testing::slurp(dir.path() / "args"),
            "dashboard " + run.string() + " --watch 2.5 --until-eof\n");
  // One line, whatever the text held.
  EXPECT_EQ(testing::slurp(dir.path() / "stdin"), "ended: budget reached at 400 env steps\n");
  EXPECT_TRUE(fs::exists(run / "logs" / "dashboard.log"));
  EXPECT_GE(writer.cpu_seconds(), 0.0);
  EXPECT_GT(writer.wall_seconds(), 0.0);
  EXPECT_FALSE(writer.running());
  EXPECT_FALSE(writer.finish("again")) << "only the first call counts";
}

TEST(PageWriterTest, TrainingEndedSaysHowFarTheRunGotAndWhy) {
  EXPECT_EQ(training_ended(false, 400, 100, "learner", 0),
            "ended: budget reached at 400 env steps and 100 updates, learner exit code 0");
  EXPECT_EQ(training_ended(true, 12, 0, "indrive-train-local", 1),
            "ended: stopped by a signal at 12 env steps and 0 updates, indrive-train-local exit "
            "code 1");
}

TEST(PageWriterTest, AWriterThatFailsIsReportedAndAMissingOneLeavesThePageOff) {
  testing::TempDir dir;
  PageWriter failing(stand_in(dir.path(), 3), dir.path() / "run", 1.0);
  ASSERT_TRUE(failing.running());
  EXPECT_FALSE(failing.finish("ended"));

  PageWriter missing(dir.path() / "no-such-program", dir.path() / "run", 1.0);
  EXPECT_FALSE(missing.running());
  EXPECT_FALSE(missing.finish("ended"));

  PageWriter off(stand_in(dir.path(), 0), dir.path() / "run", 0.0);
  EXPECT_FALSE(off.running()) << "an interval of 0 starts nothing";
}

TEST(PageWriterTest, TheRealPageIsLiveFollowsTheMetricsAndEndsWithTheLearnersWords) {
  testing::TempDir dir;
  const fs::path run = dir.path() / "run";
  fs::create_directories(run);
  append_metrics(run, 0, 5);
  PageWriter writer(fs::path(INDRIVE_BIN_DIR) / "indrive", run, 1.0);
  ASSERT_TRUE(writer.running());
  ASSERT_TRUE(eventually(30s, [&] { return newest_points(run) > 0; }))
      << testing::slurp(run / "logs" / "dashboard.log");
  const long first = newest_points(run);
  const std::string live = testing::slurp(run / "index.html");
  EXPECT_NE(live.find("http-equiv=\"refresh\" content=\"1\""), std::string::npos);
  EXPECT_NE(live.find("class=\"live\""), std::string::npos);

  append_metrics(run, 5, 25);
  EXPECT_TRUE(eventually(30s, [&] { return newest_points(run) > first; }))
      << "a rewrite holds the appended lines: " << testing::slurp(run / "logs" / "dashboard.log");

  ASSERT_TRUE(writer.finish("ended: budget reached at 2400 env steps, learner exit code 0"));
  const std::string ended = testing::slurp(run / "index.html");
  EXPECT_EQ(ended.find("http-equiv=\"refresh\""), std::string::npos) << "no reload once ended";
  EXPECT_NE(ended.find("<span class=\"ended\">ended: budget reached at 2400 env steps, learner "
                       "exit code 0</span>"),
            std::string::npos);
}

TEST(PageWriterTest, ALearnerKilledWithoutAWordLeavesAnEndedPageThatSaysSo) {
  testing::TempDir dir;
  const fs::path run = dir.path() / "run";
  fs::create_directories(run);
  append_metrics(run, 0, 5);
  // A stand-in learner: starts the writer, lets it write once, then dies without finish().
  const pid_t learner = ::fork();
  ASSERT_GE(learner, 0);
  if (learner == 0) {
    PageWriter writer(fs::path(INDRIVE_BIN_DIR) / "indrive", run, 1.0);
    for (int i = 0; i < 600 && newest_points(run) <= 0; ++i) ::usleep(50'000);
    ::_exit(newest_points(run) > 0 ? 0 : 1);  // no destructor: as a SIGKILL would leave it
  }
  int status = 0;
  ASSERT_EQ(::waitpid(learner, &status, 0), learner);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << testing::slurp(run / "logs" / "dashboard.log");
  EXPECT_TRUE(eventually(30s, [&] {
    return testing::slurp(run / "index.html").find("without a last word") != std::string::npos;
  })) << testing::slurp(run / "logs" / "dashboard.log");
  EXPECT_EQ(testing::slurp(run / "index.html").find("http-equiv=\"refresh\""), std::string::npos);
}

}  // namespace
}  // namespace indrive::learner
