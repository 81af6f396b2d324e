// The installed tree and the container set-up, checked without a container engine:
// `cmake --install` into a temporary prefix, then every docker-compose service's command is
// run through the image's entrypoint against that prefix (as the container would, from
// share/indrive) with --check-config; the installed programs find their data beside
// themselves; the Dockerfile builds through deploy/setup.sh without -march=native and its
// runtime stage installs the package of every shared library the programs link.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <yaml-cpp/yaml.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include "child_process.h"
#include "testing.h"

namespace indrive {
namespace {

using testing::slurp;

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

struct Output {
  int status = -1;
  std::string text;  // stdout and stderr
};

// Runs a shell command line and returns its exit status and output.
Output run(const std::string& command) {
  Output output;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return output;
  std::array<char, 4096> buffer{};
  std::size_t read = 0;
  while ((read = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) {
    output.text.append(buffer.data(), read);
  }
  const int status = ::pclose(pipe);
  output.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return output;
}

std::string quote(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// yaml-cpp does not apply `<<` merge keys; the compose file uses one for shared settings.
YAML::Node merged(const YAML::Node& service) {
  YAML::Node result(YAML::NodeType::Map);
  if (service["<<"]) {
    for (const auto& entry : service["<<"]) result[entry.first.as<std::string>()] = entry.second;
  }
  for (const auto& entry : service) {
    if (entry.first.as<std::string>() != "<<") result[entry.first.as<std::string>()] = entry.second;
  }
  return result;
}

// Compose's ${NAME:-default} and ${NAME-default} with the variables unset.
std::string interpolate_defaults(const std::string& text) {
  static const std::regex variable(R"(\$\{[A-Z_]+:?-([^}]*)\})");
  return std::regex_replace(text, variable, "$1");
}

// One installed tree shared by the tests of this file.
class InstalledTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir("indrive-install");
    const Output install =
        run(std::string(INDRIVE_CMAKE_COMMAND) + " --install " + quote(INDRIVE_BUILD_DIR) +
            " --prefix " + quote((dir_->path() / "prefix").string()));
    install_log_ = new std::string(install.text);
    installed_ = install.status == 0;
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete install_log_;
  }
  void SetUp() override { ASSERT_TRUE(installed_) << *install_log_; }

  static fs::path prefix() { return dir_->path() / "prefix"; }
  static fs::path share() { return prefix() / "share/indrive"; }

  // Runs `argv` through the image's entrypoint from share/indrive, as a container would.
  static Output in_container(const std::vector<std::string>& argv, const std::string& env) {
    // Appended piece by piece: GCC 12 warns (-Wrestrict, a false positive) on "..." + string.
    std::string command = "cd ";
    command += quote(share().string());
    command += " && env -u FASTRTPS_DEFAULT_PROFILES_FILE -u INDRIVE_DATA_DIR TMPDIR=";
    command += quote(dir_->path().string());
    command += " PATH=";
    command += quote((prefix() / "bin").string());
    command += ":\"$PATH\" ";
    command += env;
    command += " ";
    command += quote((share() / "deploy/docker/entrypoint.sh").string());
    for (const auto& arg : argv) {
      command += " ";
      command += quote(arg);
    }
    return run(command);
  }

  static testing::TempDir* dir_;
  static std::string* install_log_;
  static bool installed_;
};
testing::TempDir* InstalledTest::dir_ = nullptr;
std::string* InstalledTest::install_log_ = nullptr;
bool InstalledTest::installed_ = false;

TEST_F(InstalledTest, InstallPutsProgramsAndDataUnderThePrefix) {
  for (const char* program : {"indrive", "indrive-actor", "indrive-learner", "indrive-env"}) {
    EXPECT_TRUE(fs::is_regular_file(prefix() / "bin" / program)) << program;
  }
  for (const char* file :
       {"deploy/dds/single_host.xml", "deploy/dds/default.xml", "deploy/dds/discovery_server.xml",
        "deploy/configs/smoke.yaml", "deploy/configs/pretrain_disag.yaml",
        "envserver/data/towns/town01.nod.xml", "envserver/data/routes/town02.routes.yaml",
        "envserver/data/routes/left/town01.routes.yaml", "deploy/docker/entrypoint.sh"}) {
    EXPECT_TRUE(fs::is_regular_file(share() / file)) << file;
  }
  // The scripts a user runs from the installed tree are executable.
  for (const char* script : {"deploy/docker/entrypoint.sh", "deploy/dds/make_security.sh"}) {
    const auto permissions = fs::status(share() / script).permissions();
    EXPECT_NE(permissions & fs::perms::owner_exec, fs::perms::none) << script;
  }
}

TEST_F(InstalledTest, InstalledProgramsFindTheirDataBesideThemselves) {
  // No flag, no FASTRTPS_DEFAULT_PROFILES_FILE: the shipped profile of the installed tree, not
  // the source tree's, even when started from elsewhere.
  const std::string config = (share() / "deploy/configs/smoke.yaml").string();
  const std::string base = "cd / && env -u FASTRTPS_DEFAULT_PROFILES_FILE -u INDRIVE_DATA_DIR ";
  const Output installed =
      run(base + quote((prefix() / "bin/indrive-learner").string()) + " --config " + quote(config) +
          " --run-dir " + quote((dir_->path() / "runs/r").string()) + " --check-config");
  ASSERT_EQ(installed.status, 0) << installed.text;
  EXPECT_THAT(installed.text, HasSubstr((share() / "deploy/dds/single_host.xml").string()));

  // INDRIVE_DATA_DIR overrides it, and a wrong value fails with what to do.
  const fs::path other = dir_->path() / "other-data";
  fs::create_directories(other / "deploy/dds");
  fs::copy_file(share() / "deploy/dds/single_host.xml", other / "deploy/dds/single_host.xml",
                fs::copy_options::overwrite_existing);
  std::string actor = " ";  // appended: GCC 12's -Wrestrict false positive on " " + string
  actor += quote((prefix() / "bin/indrive-actor").string()) + " --config " + quote(config) +
           " --run-dir " + quote((dir_->path() / "runs/r").string()) + " --check-config";
  const Output overridden = run(base + "INDRIVE_DATA_DIR=" + quote(other.string()) + actor);
  ASSERT_EQ(overridden.status, 0) << overridden.text;
  EXPECT_THAT(overridden.text, HasSubstr((other / "deploy/dds/single_host.xml").string()));
  const Output wrong = run(base + "INDRIVE_DATA_DIR=/nonexistent-indrive-data" + actor);
  EXPECT_NE(wrong.status, 0);
  EXPECT_THAT(wrong.text, HasSubstr("INDRIVE_DATA_DIR is set to '/nonexistent-indrive-data'"));
}

TEST_F(InstalledTest, EveryComposeServiceRunsAValidCommand) {
  const YAML::Node compose =
      YAML::LoadFile(testing::source_path("deploy/docker/docker-compose.yml"));
  const YAML::Node services = compose["services"];
  ASSERT_TRUE(services.IsMap());
  std::set<std::string> names;
  int indrive_services = 0;
  for (const auto& entry : services) {
    const std::string name = entry.first.as<std::string>();
    names.insert(name);
    const YAML::Node service = merged(entry.second);
    ASSERT_TRUE(service["command"].IsSequence()) << name << ": command must be a list";
    std::vector<std::string> argv;
    for (const auto& arg : service["command"]) {
      argv.push_back(interpolate_defaults(arg.as<std::string>()));
    }
    if (argv.front() == "discovery-server") continue;  // checked below
    ++indrive_services;
    EXPECT_TRUE(service["build"]["dockerfile"].as<std::string>() == "deploy/docker/Dockerfile")
        << name;
    // The run directory is on the runs volume.
    bool runs_volume = false;
    for (const auto& volume : service["volumes"]) {
      runs_volume = runs_volume || volume.as<std::string>().ends_with(":/runs");
    }
    EXPECT_TRUE(runs_volume) << name << " must mount the runs volume at /runs";
    for (auto& arg : argv) {
      if (arg.starts_with("/runs/")) arg = (dir_->path() / "runs" / arg.substr(6)).string();
    }
    argv.push_back("--check-config");
    const Output checked = in_container(argv, "INDRIVE_DISCOVERY_SERVER=localhost:11811");
    EXPECT_EQ(checked.status, 0) << name << ":\n" << checked.text;
    EXPECT_THAT(checked.text, HasSubstr("config ok: run 'compose', preset tiny")) << name;
    EXPECT_THAT(checked.text, HasSubstr("deploy/dds/discovery_server.xml")) << name;
    // The programs take the server's address from the variable the entrypoint passes on.
    EXPECT_THAT(
        checked.text,
        HasSubstr("discovery server localhost:11811 (127.0.0.1) from $INDRIVE_DISCOVERY_SERVER"))
        << name;
  }
  EXPECT_EQ(indrive_services, 4);
  for (const char* name : {"discovery", "learner", "actor-0", "actor-1", "evaluator"}) {
    EXPECT_TRUE(names.contains(name)) << name;
  }
}

TEST_F(InstalledTest, CheckFailsOnABadCommand) {
  // The check can fail: an unknown flag, and a config file that is not there.
  const Output unknown =
      in_container({"indrive-actor", "--run-dir", "/tmp/x", "--evaluat", "--check-config"},
                   "INDRIVE_DISCOVERY_SERVER=");
  EXPECT_NE(unknown.status, 0) << unknown.text;
  const Output missing = in_container({"indrive-learner", "--config", "deploy/configs/nope.yaml",
                                       "--run-dir", "/tmp/x", "--check-config"},
                                      "INDRIVE_DISCOVERY_SERVER=");
  EXPECT_NE(missing.status, 0) << missing.text;
  // Without a discovery server the entrypoint picks the multicast UDP profile.
  const Output multicast =
      in_container({"indrive-learner", "--config", "deploy/configs/smoke.yaml", "--run-dir",
                    (dir_->path() / "runs/m").string(), "--check-config"},
                   "INDRIVE_DISCOVERY_SERVER=");
  EXPECT_EQ(multicast.status, 0) << multicast.text;
  EXPECT_THAT(multicast.text, HasSubstr("deploy/dds/default.xml"));
}

// The installed entrypoint runs the discovery server on this host's address and the port of
// INDRIVE_DISCOVERY_SERVER, and a stop (SIGTERM, as compose sends it) ends it with code 0.
TEST_F(InstalledTest, DiscoveryServerEntrypointServesItsPortAndStopsCleanly) {
  if (run("command -v fastdds").status != 0) {
    GTEST_SKIP() << "fastdds (fastdds-tools) is not installed here";
  }
  if (run("getent ahostsv4 \"$(cat /etc/hostname)\"").status != 0) {
    GTEST_SKIP() << "this host's own name does not resolve";
  }
  const int port = 21000 + testing::unique_domain_id();
  char bound[16];
  std::snprintf(bound, sizeof bound, ":%04X ", port);  // as /proc/net/udp writes a local port
  const std::string entrypoint = quote((share() / "deploy/docker/entrypoint.sh").string());
  const Output out =
      run("INDRIVE_DISCOVERY_SERVER=server:" + std::to_string(port) + " sh " + entrypoint +
          " discovery-server & pid=$!; for i in $(seq 100); do " + "grep -q '" + bound +
          "' /proc/net/udp && break; sleep 0.1; done; " + "echo bound=$(grep -c '" + bound +
          "' /proc/net/udp); " + "kill -TERM $pid; wait $pid; echo status=$?; sleep 0.5; " +
          "echo released=$(grep -c '" + bound + "' /proc/net/udp)");
  EXPECT_THAT(out.text, HasSubstr("entrypoint: discovery server on"));
  EXPECT_THAT(out.text, Not(HasSubstr("bound=0"))) << "nothing listened on port " << port;
  EXPECT_THAT(out.text, HasSubstr("status=0")) << "a stop asked for is a clean end";
  EXPECT_THAT(out.text, HasSubstr("released=0")) << "the server outlived the stop";
}

// Packages named in the Dockerfile's runtime stage (the last FROM).
std::set<std::string> runtime_packages(const std::string& dockerfile) {
  const std::size_t stage = dockerfile.rfind("\nFROM ");
  std::string runtime = dockerfile.substr(stage);
  const std::size_t install = runtime.find("apt-get install");
  std::string list = runtime.substr(install, runtime.find("&&", install) - install);
  std::set<std::string> packages;
  static const std::regex name(R"(\s([a-z0-9][a-z0-9.+-]+))");
  for (std::sregex_iterator it(list.begin(), list.end(), name), end; it != end; ++it) {
    packages.insert((*it)[1]);
  }
  return packages;
}

// How the image is built is checked by building and running it (deploy_container_test, label
// container); here: every library the installed programs link comes from a package the image's
// runtime stage installs.
TEST_F(InstalledTest, DockerfileShipsEveryRuntimeLibrary) {
  const std::string dockerfile = slurp(testing::source_path("deploy/docker/Dockerfile"));

  if (run("command -v dpkg-query && command -v ldd").status != 0) {
    GTEST_SKIP() << "no dpkg/ldd: cannot map libraries to packages here";
  }
  const std::set<std::string> packages = runtime_packages(dockerfile);
  EXPECT_TRUE(packages.contains("sumo") && packages.contains("fastdds-tools"));
  // Packages every debian:12 image has.
  const std::set<std::string> base = {"libc6", "libgcc-s1", "libstdc++6", "zlib1g", "libzstd1"};
  std::set<std::string> missing;
  std::set<std::string> seen;  // sonames already mapped (the programs share most)
  int mapped = 0;
  for (const char* program : {"indrive", "indrive-actor", "indrive-learner", "indrive-env"}) {
    const Output libraries = run("ldd " + quote((prefix() / "bin" / program).string()));
    ASSERT_EQ(libraries.status, 0) << libraries.text;
    // Only the libraries the program links directly are ours to name; apt pulls the rest.
    const Output needed = run("objdump -p " + quote((prefix() / "bin" / program).string()) +
                              " | awk '/NEEDED/ {print $2}'");
    std::istringstream names(needed.text);
    std::string soname;
    while (names >> soname) {
      if (!seen.insert(soname).second) continue;
      const std::regex line("\\s" + std::regex_replace(soname, std::regex(R"([.+])"), R"(\$&)") +
                            R"( => (\S+))");
      std::smatch match;
      if (!std::regex_search(libraries.text, match, line)) continue;
      // Merged /usr: dpkg may have recorded the /lib or the /usr/lib spelling of the file.
      const std::string real = fs::canonical(match[1].str()).string();
      std::string lib_spelling = real;
      if (lib_spelling.starts_with("/usr/lib/")) lib_spelling = lib_spelling.substr(4);
      const Output owner =
          run("dpkg-query -S " + quote(real) + " 2>/dev/null || dpkg-query -S " +
              quote(lib_spelling) + " 2>/dev/null || dpkg-query -S " + quote(match[1].str()));
      if (owner.status != 0) continue;  // not from a package (e.g. a local build)
      ++mapped;
      std::string package = owner.text.substr(0, owner.text.find_first_of(":,"));
      if (!packages.contains(package) && !base.contains(package)) {
        missing.insert(package + " (" + soname + ")");
      }
    }
  }
  // Fast DDS, OpenCV, SUMO, yaml-cpp, pugixml, ...: the check must have seen them.
  EXPECT_GE(mapped, 10) << "too few libraries mapped to packages for the check to mean much";
  EXPECT_TRUE(missing.empty()) << "add to the Dockerfile's runtime stage: "
                               << ::testing::PrintToString(missing);
}

}  // namespace
}  // namespace indrive
