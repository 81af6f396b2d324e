// The learner's pacing as one training actor knows it (docs/architecture.md, section 4). The
// learner's StepAllowance caps the total env steps of all actors; its heartbeat says how many it
// has received, and the actor adds the steps it took since that heartbeat arrived, so several
// actors overshoot by at most their in-flight steps.
//
// DDS callbacks feed it (on_allowance, on_learner_heartbeat, wake) on their own threads; the
// actor's loop asks may_step() and, while it may not, sleeps in wait_for_news() until something
// arrives. Polling instead (every 2 ms, as the actor did until 2026-12-06) woke the actor 500
// times a second on cores the learner computes on, during the 94% of a rate-limited run an actor
// spends waiting.
//
//   AllowanceGate gate(run_id);
//   reader<StepAllowance>([&](const auto& a) { gate.on_allowance(a); });
//   while (!gate.may_step(own_steps)) {
//     const std::uint64_t seen = gate.news();
//     ...timed duties (heartbeat, rejoin)...
//     if (!gate.may_step(own_steps)) gate.wait_for_news(seen, std::chrono::milliseconds(50));
//   }
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>

#include "indrive/dds/messages.h"

namespace indrive::actor {

class AllowanceGate {
 public:
  using Clock = std::chrono::steady_clock;

  explicit AllowanceGate(std::string run_id);

  // A StepAllowance; ignored unless it is valid and of this run (false). Logs a learner restart
  // (a new learner epoch after the first).
  bool on_allowance(const msg::StepAllowance& allowance);
  // A heartbeat; only the learner's of this run count (true). `own_steps` is the steps this
  // actor has taken when it arrives.
  bool on_learner_heartbeat(const msg::Heartbeat& heartbeat, std::uint64_t own_steps);
  // Something else a waiting actor acts on arrived (a snapshot or its announcement).
  void wake();

  // True when one more step of this actor stays within the allowance; false until both an
  // allowance and a learner heartbeat have arrived.
  bool may_step(std::uint64_t own_steps) const;
  // How many accepted allowances, learner heartbeats and wake() calls have arrived so far.
  std::uint64_t news() const;
  // Blocks until news() exceeds `seen` (true) or `timeout` has gone by (false). Read `seen`
  // before checking may_step(), so news that arrives in between ends the wait at once.
  bool wait_for_news(std::uint64_t seen, Clock::duration timeout) const;

 private:
  void arrived();  // counts news and wakes waiters; called with mutex_ held

  std::string run_id_;
  mutable std::mutex mutex_;
  mutable std::condition_variable news_arrived_;
  bool have_allowance_ = false;
  bool have_received_ = false;  // a learner heartbeat of this run arrived
  std::uint64_t allowed_ = 0;
  std::uint64_t epoch_ = 0;
  std::uint64_t received_ = 0;
  std::uint64_t own_at_heartbeat_ = 0;
  std::uint64_t news_ = 0;
};

}  // namespace indrive::actor
