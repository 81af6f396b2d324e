// The service in real containers: deploy/docker/compose_run.sh makes the base image when it is
// missing, builds the image (layers cached when the sources did not change), runs the compose
// file (discovery server, learner, 2 actors, evaluator) over the Discovery Server profile to
// the end of the smoke run and writes the report. Label `container`: minutes to tens of
// minutes, so never part of the default test run; skipped where no container engine is
// installed. Run it with `ctest --test-dir build -L container --verbose`.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>
#include <vector>

#include "child_process.h"
#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

// Runs a shell command line, echoing its output as it comes (the run takes minutes), and
// returns its exit status and output.
int run_echoed(const std::string& command, std::string& output) {
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return -1;
  std::array<char, 4096> line{};
  while (std::fgets(line.data(), line.size(), pipe) != nullptr) {
    output += line.data();
    std::fputs(line.data(), stdout);
    std::fflush(stdout);
  }
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The text after `prefix` on the script's line that starts with it ("" when none).
std::string figure(const std::string& output, const std::string& prefix) {
  std::istringstream lines(output);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind(prefix, 0) == 0) return line.substr(prefix.size());
  }
  return "";
}

std::vector<std::string> split(const std::string& line, char separator) {
  std::vector<std::string> fields;
  std::istringstream stream(line);
  for (std::string field; std::getline(stream, field, separator);) fields.push_back(field);
  return fields;
}

long long json_integer(const std::string& line, const std::string& key) {
  std::smatch match;
  const std::regex pattern("\"" + key + "\":([0-9]+)");
  return std::regex_search(line, match, pattern) ? std::stoll(match[1]) : -1;
}

TEST(ContainerTest, ComposeRunTrainsEvaluatesTheLastSnapshotAndReports) {
  std::string ignored;
  if (testing::run_command("command -v podman || command -v docker", ignored) != 0) {
    GTEST_SKIP() << "no container engine (podman or docker) is installed: apt-get install "
                    "podman runc podman-compose mmdebstrap";
  }
  testing::TempDir runs("indrive-container");
  const std::string run_id = "container-test";
  std::string output;
  const int status =
      run_echoed("bash " + testing::source_path("deploy/docker/compose_run.sh").string() +
                     " --build --runs-dir " + runs.path().string() + " --run-id " + run_id,
                 output);
  if (status == 3) GTEST_SKIP() << "compose_run.sh found no usable engine: " << output;
  ASSERT_EQ(status, 0) << output;

  // Every container ended on its own (learner, evaluator) or on `compose stop` (actors,
  // discovery server) with exit code 0.
  const std::string codes = figure(output, "compose_run: exit codes");
  EXPECT_THAT(codes, HasSubstr("learner=0"));
  EXPECT_THAT(codes, HasSubstr("evaluator=0"));
  EXPECT_THAT(codes, Not(::testing::ContainsRegex("=[1-9]"))) << codes;

  // The learner spent the smoke config's budget.
  const fs::path run = runs.path() / run_id;
  const YAML::Node config = YAML::LoadFile(testing::source_path("deploy/configs/smoke.yaml"));
  const long long budget = config["run"]["budget_env_steps"].as<long long>();
  std::ifstream metrics(run / "metrics.jsonl");
  std::string last;
  for (std::string line; std::getline(metrics, line);) {
    if (!line.empty()) last = line;
  }
  ASSERT_FALSE(last.empty()) << "no metrics.jsonl in " << run;
  EXPECT_GE(json_integer(last, "env_steps"), budget) << last;
  const long long final_version = json_integer(last, "policy_version");
  ASSERT_GT(final_version, 0) << last;

  // The evaluator's rows are of the final snapshot.
  std::ifstream results(run / "eval" / "evaluator-0.csv");
  std::string header;
  ASSERT_TRUE(std::getline(results, header)) << "no eval/evaluator-0.csv in " << run;
  const std::vector<std::string> columns = split(header, ',');
  const auto column = std::find(columns.begin(), columns.end(), "policy_version");
  ASSERT_NE(column, columns.end()) << header;
  const std::size_t index = static_cast<std::size_t>(column - columns.begin());
  int rows = 0;
  for (std::string line; std::getline(results, line);) {
    if (line.empty()) continue;
    const std::vector<std::string> fields = split(line, ',');
    ASSERT_GT(fields.size(), index) << line;
    EXPECT_EQ(std::stoll(fields[index]), final_version) << line;
    ++rows;
  }
  EXPECT_GT(rows, 0) << "the evaluator wrote no results";

  // The report, with its table.
  const std::string report_path = figure(output, "compose_run: report ");
  EXPECT_EQ(fs::path(report_path), run / "report.md");
  const std::string report = testing::slurp(run / "report.md");
  EXPECT_THAT(report, ::testing::ContainsRegex("\n\\|.*\\|"));
  std::printf("container test: image build %s s, compose run %s s, %d evaluation rows of v%lld\n",
              figure(output, "compose_run: image build seconds ").c_str(),
              figure(output, "compose_run: compose run seconds ").c_str(), rows, final_version);
}

}  // namespace
}  // namespace indrive
