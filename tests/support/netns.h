// Two "hosts" on one machine for tests: two Linux network namespaces joined by a veth pair,
// each with its own address (10.77.0.1 on A, 10.77.0.2 on B) and its own loopback. A process
// started with on_a()/on_b() sees only its namespace's interfaces, so whatever crosses from
// A to B goes over the pair's link, which a test can cut and restore. Needs root and `ip`
// (iproute2); make() says why it cannot when it cannot, for GTEST_SKIP.
//
//   std::string why;
//   auto hosts = testing::HostPair::make({}, why);
//   if (!hosts) GTEST_SKIP() << why;
//   hosts->enter_a();                                  // this test's own DDS participants on A
//   Child evaluator(hosts->on_b({bin / "indrive-actor", "--evaluate", ...}), log);
//   hosts->cut_link(); ... hosts->restore_link();
#pragma once

#include <memory>
#include <string>
#include <vector>

namespace indrive::testing {

class HostPair {
 public:
  struct Options {
    // Route 224.0.0.0/4 over the link on both hosts, so multicast discovery crosses it.
    // Off: no multicast leaves either host (the discovery-server setups).
    bool multicast = true;
  };

  // Makes both namespaces and the link; nullptr with `why` set when it cannot.
  static std::unique_ptr<HostPair> make(const Options& options, std::string& why);
  ~HostPair();  // returns the calling thread to its own namespace, deletes both namespaces
  HostPair(const HostPair&) = delete;
  HostPair& operator=(const HostPair&) = delete;

  const std::string& address_a() const { return address_a_; }
  const std::string& address_b() const { return address_b_; }

  // A command line that runs `argv` on host A or B (through `ip netns exec`, which execs it,
  // so the child's pid is the program's).
  std::vector<std::string> on_a(const std::vector<std::string>& argv) const;
  std::vector<std::string> on_b(const std::vector<std::string>& argv) const;

  // Moves the calling thread onto host A: sockets it opens from now on, and threads it starts,
  // are A's. Call it before creating the test's DDS participants; the destructor, on the
  // same thread, moves it back.
  void enter_a();

  // Takes A's end of the link down (B loses its carrier), and brings it back with the
  // multicast routes that taking it down deleted.
  void cut_link();
  void restore_link();

  // Shapes what A sends to B to `rate` (tc's units, "8mbit"), as a slow link between hosts
  // would; false with `why` set when tc is missing or refuses.
  bool limit_rate_a_to_b(const std::string& rate, std::string& why);

 private:
  HostPair() = default;
  std::string ns_a_, ns_b_;
  std::string address_a_ = "10.77.0.1", address_b_ = "10.77.0.2";
  bool multicast_ = true;
  int home_fd_ = -1;  // the namespace the thread came from, while it is on A
};

}  // namespace indrive::testing
