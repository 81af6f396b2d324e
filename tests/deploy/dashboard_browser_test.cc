// The dashboard as a person sees it: the page of a real short training run (indrive-train-local),
// opened in headless Chromium. No console message and no script error; every chart holds one
// point per metrics line; a screenshot of the right size with the charts' colours in it; a
// page for two runs has both in its legends.
//
// Needs Chromium (Debian's `chromium`, installed by `deploy/setup.sh test`): without it the
// test is skipped, except under CI=true, where that is a failure.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <regex>

#include "child_process.h"
#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const fs::path kBin = INDRIVE_BIN_DIR;

bool have_chromium() {
  std::string output;
  return testing::run_command("command -v chromium", output) == 0;
}

#define REQUIRE_CHROMIUM()                                                    \
  do {                                                                        \
    if (!have_chromium()) {                                                   \
      const char* ci = std::getenv("CI");                                     \
      ASSERT_FALSE(ci != nullptr && std::string(ci) == "true")                \
          << "chromium is missing; deploy/setup.sh test installs it";         \
      GTEST_SKIP() << "chromium is not installed (apt-get install chromium)"; \
    }                                                                         \
  } while (false)

// Headless Chromium on a page; `what` is "--dump-dom" or "--screenshot=FILE". Returns what it
// printed (stdout and stderr: the DOM, and the page's console messages as CONSOLE lines).
std::string chromium(const fs::path& page, const std::string& what, const fs::path& profile) {
  const std::string command =
      "timeout 120 chromium --headless=new --no-sandbox --disable-gpu --hide-scrollbars "
      "--user-data-dir=" +
      profile.string() +
      " --enable-logging=stderr --v=0 --window-size=1280,1600 --virtual-time-budget=5000 " + what +
      " 'file://" + fs::absolute(page).string() + "' 2>&1";
  std::string output;
  EXPECT_EQ(testing::run_command(command, output), 0) << output;
  return output;
}

// A data-* attribute of <body> in a dumped DOM, HTML entities undone.
std::string body_attribute(const std::string& dom, const std::string& name) {
  const std::regex pattern("<body[^>]*\\sdata-" + name + "=\"([^\"]*)\"");
  std::smatch match;
  if (!std::regex_search(dom, match, pattern)) return "";
  std::string value = match[1];
  for (const auto& [entity, text] : std::vector<std::pair<std::string, std::string>>{
           {"&quot;", "\""}, {"&lt;", "<"}, {"&gt;", ">"}, {"&amp;", "&"}}) {
    for (auto at = value.find(entity); at != std::string::npos; at = value.find(entity, at)) {
      value.replace(at, entity.size(), text);
      at += text.size();
    }
  }
  return value;
}

// Lines of metrics.jsonl that have `key`.
int lines_with(const fs::path& metrics, const std::string& key) {
  std::ifstream in(metrics);
  int n = 0;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && nlohmann::json::parse(line).contains(key)) ++n;
  }
  return n;
}

class DashboardBrowser : public ::testing::Test {
 protected:
  // One real short run for every test of the suite: 400 env steps of the tiny model.
  static void SetUpTestSuite() {
    run_root_ = new testing::TempDir("indrive-dashboard");
    const fs::path run = run_root_->path() / "short";
    const fs::path log = run_root_->path() / "train.log";
    testing::Child train(
        {(kBin / "indrive-train-local").string(), "--config",
         testing::source_path("deploy/configs/smoke.yaml").string(), "--run-dir", run.string(),
         "--set", "env.densities=5", "--set", "agent.replay.prefill=64", "--set",
         "learner.log_interval_s=0.2", "--set", "run.budget_env_steps=400"},
        log, {{"OMP_NUM_THREADS", "1"}});
    train_exit_ = train.wait(300s);
    train_log_ = testing::slurp(log);
  }
  static void TearDownTestSuite() { delete run_root_; }

  void SetUp() override { ASSERT_EQ(train_exit_, 0) << train_log_; }

  static fs::path run() { return run_root_->path() / "short"; }

  static testing::TempDir* run_root_;
  static int train_exit_;
  static std::string train_log_;
};
testing::TempDir* DashboardBrowser::run_root_ = nullptr;
int DashboardBrowser::train_exit_ = -1;
std::string DashboardBrowser::train_log_;

TEST_F(DashboardBrowser, ARealRunsPageDrawsEveryMetricsLineWithoutAnError) {
  REQUIRE_CHROMIUM();
  testing::TempDir dir;
  const fs::path log = dir.path() / "dashboard.log";
  testing::Child dashboard({(kBin / "indrive").string(), "dashboard", run().string()}, log);
  ASSERT_EQ(dashboard.wait(60s), 0) << testing::slurp(log);
  const fs::path page = run() / "index.html";
  ASSERT_TRUE(fs::exists(page)) << testing::slurp(log);

  const std::string dom = chromium(page, "--dump-dom", dir.path() / "profile");
  EXPECT_EQ(dom.find(":CONSOLE"), std::string::npos) << "the page wrote to the console:\n" << dom;
  ASSERT_EQ(body_attribute(dom, "ready"), "1") << "the page's script did not finish";
  EXPECT_EQ(body_attribute(dom, "errors"), "[]");
  const auto points = nlohmann::json::parse(body_attribute(dom, "points"));
  const int recon_lines = lines_with(run() / "metrics.jsonl", "wm/recon");
  ASSERT_GT(recon_lines, 2) << "too short a run to check anything";
  EXPECT_EQ(points["wm/recon"]["short"].get<int>(), recon_lines);
  EXPECT_EQ(points["expl/entropy"]["short"].get<int>(),
            lines_with(run() / "metrics.jsonl", "expl/entropy"));
  EXPECT_GE(std::stoi(body_attribute(dom, "charts")), 20);

  const fs::path shot = dir.path() / "page.png";
  chromium(page, "--screenshot=" + shot.string(), dir.path() / "profile");
  const cv::Mat image = cv::imread(shot.string());
  ASSERT_FALSE(image.empty()) << "no screenshot at " << shot;
  EXPECT_EQ(image.cols, 1280);
  EXPECT_EQ(image.rows, 1600);
  // The header (#263238), the series' blue (#1f77b4) in the charts, and a mostly light page.
  int header = 0, blue = 0, light = 0;
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      const auto p = image.at<cv::Vec3b>(y, x);  // BGR
      header += std::abs(p[0] - 0x38) < 6 && std::abs(p[1] - 0x32) < 6 && std::abs(p[2] - 0x26) < 6;
      blue +=
          std::abs(p[0] - 0xb4) < 40 && std::abs(p[1] - 0x77) < 40 && std::abs(p[2] - 0x1f) < 40;
      light += p[0] > 230 && p[1] > 230 && p[2] > 230;
    }
  }
  const double total = double(image.rows) * image.cols;
  EXPECT_GT(header / total, 0.02) << "no page header in the screenshot";
  EXPECT_GT(blue, 2000) << "no chart lines in the screenshot";
  EXPECT_GT(light / total, 0.5) << "the page is not mostly light: not rendered?";
  EXPECT_LT(light / total, 0.99) << "the page is blank";
}

TEST_F(DashboardBrowser, APageOfTwoRunsShowsBothInItsLegends) {
  REQUIRE_CHROMIUM();
  testing::TempDir dir;
  const fs::path other = dir.path() / "other";
  fs::copy(run(), other, fs::copy_options::recursive);
  const fs::path page = dir.path() / "both.html";
  const fs::path log = dir.path() / "dashboard.log";
  testing::Child dashboard({(kBin / "indrive").string(), "dashboard", run().string(),
                            other.string(), "--out", page.string()},
                           log);
  ASSERT_EQ(dashboard.wait(60s), 0) << testing::slurp(log);
  const std::string dom = chromium(page, "--dump-dom", dir.path() / "profile");
  ASSERT_EQ(body_attribute(dom, "ready"), "1");
  EXPECT_EQ(body_attribute(dom, "errors"), "[]");
  const auto points = nlohmann::json::parse(body_attribute(dom, "points"));
  EXPECT_TRUE(points["wm/recon"].contains("short")) << points["wm/recon"].dump();
  EXPECT_TRUE(points["wm/recon"].contains("other")) << points["wm/recon"].dump();
}

}  // namespace
}  // namespace indrive
