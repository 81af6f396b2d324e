#include "testing.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <random>
#include <stdexcept>
#include <system_error>

namespace indrive::testing {

TempDir::TempDir(const std::string& prefix) {
  std::random_device device;
  const auto base = std::filesystem::temp_directory_path();
  for (int attempt = 0; attempt < 100; ++attempt) {
    auto candidate = base / (prefix + "-" + std::to_string(::getpid()) + "-" +
                             std::to_string(device() % 1000000));
    std::error_code error;
    if (std::filesystem::create_directories(candidate, error)) {
      path_ = std::move(candidate);
      return;
    }
  }
  throw std::runtime_error("could not create a temporary directory under " + base.string());
}

TempDir::~TempDir() {
  std::error_code error;
  std::filesystem::remove_all(path_, error);
}

int unique_domain_id() {
  // Domain ids 0..232 are valid; keep 0 free for users. A test process claims an id by
  // holding an exclusive lock on a file named after it until the process exits, so two test
  // processes running at the same time never share a domain. Children of a test use the id
  // their parent passes them and never call this.
  static int claimed = -1;
  if (claimed >= 0) return claimed;
  const auto folder = std::filesystem::temp_directory_path() / "indrive-test-domains";
  std::error_code error;
  std::filesystem::create_directories(folder, error);
  const int start = static_cast<int>(::getpid() % 200);
  for (int i = 0; i < 200; ++i) {
    const int id = 1 + (start + i) % 200;
    const auto path = folder / std::to_string(id);
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
      claimed = id;  // fd stays open: the lock is released when the process exits
      return claimed;
    }
    ::close(fd);
  }
  throw std::runtime_error("no free DDS domain id for this test: 200 test processes hold one");
}

std::filesystem::path source_path(const std::string& relative) {
  return std::filesystem::path(INDRIVE_SOURCE_DIR) / relative;
}

std::vector<std::filesystem::path> shipped_configs() {
  std::vector<std::filesystem::path> configs;
  for (const auto& entry : std::filesystem::directory_iterator(source_path("deploy/configs"))) {
    if (entry.path().extension() == ".yaml") configs.push_back(entry.path());
  }
  std::sort(configs.begin(), configs.end());
  return configs;
}

int run_command(const std::string& command, std::string& output) {
  output.clear();
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return -1;
  char buffer[4096];
  while (const std::size_t read = std::fread(buffer, 1, sizeof(buffer), pipe)) {
    output.append(buffer, read);
  }
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

void make_security_folder(const std::filesystem::path& dir) {
  const std::string log = dir.string() + ".log";
  const std::string command = "bash '" + source_path("deploy/dds/make_security.sh").string() +
                              "' '" + dir.string() + "' > '" + log + "' 2>&1";
  if (std::system(command.c_str()) != 0) {
    std::ifstream in(log);
    throw std::runtime_error("make_security.sh failed: " +
                             std::string(std::istreambuf_iterator<char>(in), {}));
  }
}

void allow_publishing(const std::filesystem::path& dir, const std::string& role,
                      const std::string& topic) {
  const auto xml_path = dir / ("permissions-" + role + ".xml");
  std::ifstream in(xml_path);
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto publish = xml.find("<publish>");
  const auto topics = xml.find("<topics>", publish);
  if (publish == std::string::npos || topics == std::string::npos) {
    throw std::runtime_error(xml_path.string() + " has no <publish><topics> list");
  }
  xml.insert(topics + std::string("<topics>").size(), "<topic>" + topic + "</topic>");
  std::ofstream(xml_path) << xml;
  const std::string sign = "openssl smime -sign -text -md sha256 -in '" + xml_path.string() +
                           "' -signer '" + (dir / "ca.pem").string() + "' -inkey '" +
                           (dir / "ca.key").string() + "' -out '" +
                           (dir / ("permissions-" + role + ".p7s")).string() + "'";
  if (std::system(sign.c_str()) != 0) throw std::runtime_error("'" + sign + "' failed");
}

std::vector<ThreadSignals> thread_signals(int pid) {
  namespace fs = std::filesystem;
  const fs::path tasks =
      fs::path("/proc") / (pid == 0 ? std::string("self") : std::to_string(pid)) / "task";
  std::vector<ThreadSignals> threads;
  std::error_code error;
  for (auto it = fs::directory_iterator(tasks, error); !error && it != fs::directory_iterator();
       it.increment(error)) {
    std::ifstream status(it->path() / "status");
    ThreadSignals thread;
    for (std::string line; std::getline(status, line);) {
      if (line.rfind("Name:", 0) == 0) thread.name = line.substr(line.find_first_not_of(" \t", 5));
      if (line.rfind("SigBlk:", 0) == 0) thread.blocked = std::stoull(line.substr(7), nullptr, 16);
    }
    threads.push_back(thread);
  }
  return threads;
}

}  // namespace indrive::testing
