// Where an actor's PolicySnapshots arrive: DDS threads hand in snapshots and announces, the
// acting thread takes the newest valid snapshot between steps.
//
// A snapshot is accepted only if it validates (run id, schema, checksum) and its architecture
// descriptor equals the actor's own; otherwise it is dropped, counted, and the reason logged.
// Announces of a version newer than any received make the actor re-request it (late joiners
// can miss transient-local data in Fast DDS 2.9).
//
//   SnapshotInbox inbox(run_id, service::architecture_descriptor(agent_config), 2.0);
//   reader = participant.make_reader<msg::PolicySnapshot>([&](auto& s) { inbox.offer(s); });
//   if (auto snapshot = inbox.take_newer_than(held_version)) policy.load_snapshot(...);
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "indrive/dds/messages.h"

namespace indrive::actor {

class SnapshotInbox {
 public:
  using Clock = std::chrono::steady_clock;

  // run_id: the run this actor belongs to; architecture: its own descriptor;
  // request_after_s: how long an announced version may be missing before a re-request.
  SnapshotInbox(std::string run_id, std::string architecture, double request_after_s);

  // Offers a received snapshot (any thread). Returns true when it was kept as the newest.
  bool offer(const msg::PolicySnapshot& snapshot);
  // Records a received announce (any thread).
  void announce(const msg::SnapshotAnnounce& announce);
  // The kept snapshot if its version is above `version`, else nullptr (acting thread).
  std::shared_ptr<const msg::PolicySnapshot> take_newer_than(std::uint64_t version);
  // True when an announced version newer than `held_version` has been missing for longer than
  // request_after_s (counted from the first announce of a version newer than the snapshot held,
  // or from the last snapshot received) and no request was made within that time; marks the
  // request as made.
  bool should_request(std::uint64_t held_version, Clock::time_point now);

  // Snapshots dropped by validation, per reason.
  const dds::DropCounters& drops() const { return drops_; }
  // Snapshots rejected because their architecture descriptor differs from ours.
  std::uint64_t architecture_rejects() const;
  // Newest version announced by the learner (0: none yet).
  std::uint64_t announced_version() const;
  // The version the learner announced as its last when it spent its budget (0: not yet).
  std::uint64_t final_version() const;

 private:
  std::string run_id_;
  std::string architecture_;
  Clock::duration request_after_;
  mutable std::mutex mutex_;
  std::shared_ptr<const msg::PolicySnapshot> newest_;
  std::uint64_t announced_ = 0;
  std::uint64_t final_ = 0;
  Clock::time_point announced_since_{};
  Clock::time_point last_request_{};
  std::uint64_t architecture_rejects_ = 0;
  dds::DropCounters drops_;
};

}  // namespace indrive::actor
