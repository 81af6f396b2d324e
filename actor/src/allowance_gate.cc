#include "indrive/actor/allowance_gate.h"

#include <algorithm>
#include <utility>

#include "indrive/basics/log.h"

namespace indrive::actor {

AllowanceGate::AllowanceGate(std::string run_id) : run_id_(std::move(run_id)) {}

void AllowanceGate::arrived() {
  ++news_;
  news_arrived_.notify_all();
}

bool AllowanceGate::on_allowance(const msg::StepAllowance& allowance) {
  if (dds::validate(allowance, run_id_) != dds::DropReason::kOk) return false;
  std::lock_guard<std::mutex> lock(mutex_);
  allowed_ = allowance.total_env_steps();
  have_allowance_ = true;
  if (allowance.learner_epoch() != epoch_) {
    if (epoch_ != 0) {
      INDRIVE_LOG(kInfo, "actor") << "learner restarted (epoch " << allowance.learner_epoch()
                                  << ")";
    }
    epoch_ = allowance.learner_epoch();
  }
  arrived();
  return true;
}

bool AllowanceGate::on_learner_heartbeat(const msg::Heartbeat& heartbeat, std::uint64_t own_steps) {
  if (heartbeat.role() != msg::ROLE_LEARNER) return false;
  if (dds::validate(heartbeat, run_id_) != dds::DropReason::kOk) return false;
  std::lock_guard<std::mutex> lock(mutex_);
  received_ = heartbeat.env_steps();
  own_at_heartbeat_ = own_steps;
  have_received_ = true;
  arrived();
  return true;
}

void AllowanceGate::wake() {
  std::lock_guard<std::mutex> lock(mutex_);
  arrived();
}

bool AllowanceGate::may_step(std::uint64_t own_steps) const {
  std::lock_guard<std::mutex> lock(mutex_);
  // Both are needed: the allowance is a total over the run, and only the learner's heartbeat
  // says how much of it is spent (a resumed learner has spent some before any actor steps).
  if (!have_allowance_ || !have_received_) return false;
  const std::uint64_t estimate = received_ + (own_steps - std::min(own_steps, own_at_heartbeat_));
  return estimate < allowed_;
}

std::uint64_t AllowanceGate::news() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return news_;
}

bool AllowanceGate::wait_for_news(std::uint64_t seen, Clock::duration timeout) const {
  std::unique_lock<std::mutex> lock(mutex_);
  return news_arrived_.wait_for(lock, timeout, [&] { return news_ != seen; });
}

}  // namespace indrive::actor
