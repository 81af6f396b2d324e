#include "netns.h"

#include <fcntl.h>
#include <sched.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <stdexcept>

#include "testing.h"

namespace indrive::testing {
namespace {

constexpr const char* kLinkA = "veth-a";
constexpr const char* kLinkB = "veth-b";

// Runs every command in order; throws with the command and its output when one fails.
void run_all(const std::vector<std::string>& commands) {
  for (const auto& command : commands) {
    std::string output;
    if (run_command(command, output) != 0) {
      throw std::runtime_error("'" + command + "' failed: " + output);
    }
  }
}

std::string ip_program() {
  for (const char* path : {"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"}) {
    if (::access(path, X_OK) == 0) return path;
  }
  return "";
}

}  // namespace

std::unique_ptr<HostPair> HostPair::make(const Options& options, std::string& why) {
  if (::geteuid() != 0) {
    why = "two-host tests need root for network namespaces (they run as root in CI)";
    return nullptr;
  }
  const std::string ip = ip_program();
  if (ip.empty()) {
    why = "two-host tests need `ip` from iproute2 (apt-get install iproute2)";
    return nullptr;
  }
  static std::atomic<int> serial{0};
  std::unique_ptr<HostPair> pair(new HostPair());
  const std::string stem =
      "indrive-" + std::to_string(::getpid()) + "-" + std::to_string(serial.fetch_add(1));
  pair->ns_a_ = stem + "-a";
  pair->ns_b_ = stem + "-b";
  pair->multicast_ = options.multicast;
  const std::string a = ip + " -n " + pair->ns_a_, b = ip + " -n " + pair->ns_b_;
  std::vector<std::string> commands = {
      ip + " netns add " + pair->ns_a_,
      ip + " netns add " + pair->ns_b_,
      a + " link add " + kLinkA + " type veth peer name " + kLinkB + " netns " + pair->ns_b_,
      a + " addr add " + pair->address_a_ + "/24 dev " + kLinkA,
      b + " addr add " + pair->address_b_ + "/24 dev " + kLinkB,
      a + " link set lo up",
      b + " link set lo up",
      a + " link set " + kLinkA + " up",
      b + " link set " + kLinkB + " up"};
  if (options.multicast) {
    commands.push_back(a + " route replace 224.0.0.0/4 dev " + kLinkA);
    commands.push_back(b + " route replace 224.0.0.0/4 dev " + kLinkB);
  }
  try {
    run_all(commands);
  } catch (const std::exception& error) {
    why = std::string("cannot make network namespaces here: ") + error.what();
    return nullptr;  // the destructor deletes what was made
  }
  return pair;
}

HostPair::~HostPair() {
  if (home_fd_ >= 0) {
    ::setns(home_fd_, CLONE_NEWNET);
    ::close(home_fd_);
  }
  const std::string ip = ip_program();
  std::string ignored;
  for (const auto& ns : {ns_a_, ns_b_}) {
    if (!ns.empty())
      run_command(ip + " netns del " + ns, ignored);  // deletes its end of the link too
  }
}

std::vector<std::string> HostPair::on_a(const std::vector<std::string>& argv) const {
  std::vector<std::string> full = {ip_program(), "netns", "exec", ns_a_};
  full.insert(full.end(), argv.begin(), argv.end());
  return full;
}

std::vector<std::string> HostPair::on_b(const std::vector<std::string>& argv) const {
  std::vector<std::string> full = {ip_program(), "netns", "exec", ns_b_};
  full.insert(full.end(), argv.begin(), argv.end());
  return full;
}

void HostPair::enter_a() {
  if (home_fd_ >= 0) return;
  home_fd_ = ::open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC);
  const int fd = ::open(("/run/netns/" + ns_a_).c_str(), O_RDONLY | O_CLOEXEC);
  if (home_fd_ < 0 || fd < 0 || ::setns(fd, CLONE_NEWNET) != 0) {
    if (fd >= 0) ::close(fd);
    throw std::runtime_error("cannot enter network namespace " + ns_a_);
  }
  ::close(fd);
}

void HostPair::cut_link() {
  run_all({ip_program() + " -n " + ns_a_ + " link set " + kLinkA + " down"});
}

void HostPair::restore_link() {
  const std::string a = ip_program() + " -n " + ns_a_, b = ip_program() + " -n " + ns_b_;
  std::vector<std::string> commands = {a + " link set " + kLinkA + " up"};
  if (multicast_) {
    commands.push_back(a + " route replace 224.0.0.0/4 dev " + kLinkA);
    commands.push_back(b + " route replace 224.0.0.0/4 dev " + kLinkB);
  }
  run_all(commands);
}

bool HostPair::limit_rate_a_to_b(const std::string& rate, std::string& why) {
  std::string tc;
  for (const char* path : {"/usr/sbin/tc", "/sbin/tc", "/usr/bin/tc", "/bin/tc"}) {
    if (::access(path, X_OK) == 0) tc = path;
  }
  if (tc.empty()) {
    why = "no tc (iproute2) to shape the link";
    return false;
  }
  // A token bucket on A's end: `rate` on average, bursts of 64 KB (one DDS fragment), and a
  // queue of at most 200 ms, beyond which packets are dropped as on a congested link.
  const std::string command = tc + " -n " + ns_a_ + " qdisc replace dev " + kLinkA +
                              " root tbf rate " + rate + " burst 64kb latency 200ms";
  std::string output;
  if (run_command(command, output) != 0) {
    why = "'" + command + "' failed: " + output;
    return false;
  }
  return true;
}

}  // namespace indrive::testing
