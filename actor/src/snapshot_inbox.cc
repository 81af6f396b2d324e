#include "indrive/actor/snapshot_inbox.h"

#include <algorithm>

#include "indrive/basics/log.h"

namespace indrive::actor {

SnapshotInbox::SnapshotInbox(std::string run_id, std::string architecture, double request_after_s)
    : run_id_(std::move(run_id)),
      architecture_(std::move(architecture)),
      request_after_(std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(request_after_s))) {}

bool SnapshotInbox::offer(const msg::PolicySnapshot& snapshot) {
  const dds::DropReason reason = dds::validate(snapshot, run_id_);
  if (reason != dds::DropReason::kOk) {
    drops_.record(reason);
    INDRIVE_LOG(kWarn, "actor") << "dropped snapshot v" << snapshot.version() << " of run '"
                                << snapshot.run_id() << "': " << dds::drop_reason_name(reason);
    return false;
  }
  if (snapshot.architecture() != architecture_) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++architecture_rejects_;
    INDRIVE_LOG(kError, "actor") << "rejected snapshot v" << snapshot.version()
                                 << ": its architecture '" << snapshot.architecture()
                                 << "' does not match this actor's '" << architecture_
                                 << "'; start actors and learner with the same preset and sizes";
    return false;
  }
  auto copy = std::make_shared<const msg::PolicySnapshot>(snapshot);
  std::lock_guard<std::mutex> lock(mutex_);
  if (newest_ != nullptr && newest_->version() >= snapshot.version()) return false;
  newest_ = std::move(copy);
  // Something arrived: a newer announced version is given request_after_s from now.
  announced_since_ = Clock::now();
  drops_.record(dds::DropReason::kOk);
  return true;
}

void SnapshotInbox::announce(const msg::SnapshotAnnounce& announce) {
  if (dds::validate(announce, run_id_) != dds::DropReason::kOk) return;
  std::lock_guard<std::mutex> lock(mutex_);
  if (announce.version() > announced_) {
    // The wait before a request counts from when a version newer than the held one was first
    // announced, not from the newest announce: a learner announcing faster than request_after_s
    // must not put off the request for ever.
    const std::uint64_t held = newest_ ? newest_->version() : 0;
    if (announced_ <= held) announced_since_ = Clock::now();
    announced_ = announce.version();
  }
  if (announce.learner_done()) final_ = std::max(final_, announce.version());
}

std::shared_ptr<const msg::PolicySnapshot> SnapshotInbox::take_newer_than(std::uint64_t version) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (newest_ == nullptr || newest_->version() <= version) return nullptr;
  return newest_;
}

bool SnapshotInbox::should_request(std::uint64_t held_version, Clock::time_point now) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::uint64_t have = newest_ ? std::max(newest_->version(), held_version) : held_version;
  if (announced_ <= have) return false;
  if (now - announced_since_ < request_after_) return false;
  if (last_request_ != Clock::time_point{} && now - last_request_ < request_after_) return false;
  last_request_ = now;
  return true;
}

std::uint64_t SnapshotInbox::architecture_rejects() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return architecture_rejects_;
}

std::uint64_t SnapshotInbox::announced_version() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return announced_;
}

std::uint64_t SnapshotInbox::final_version() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return final_;
}

}  // namespace indrive::actor
