// The learner's side of policy snapshots, the counterpart of the actor's SnapshotInbox: policy
// versions reserved on disk before one is handed out, the PolicySnapshot written and kept as the
// newest, written again when a late joiner asks for it (SnapshotRequest), and the
// SnapshotAnnounce that tells actors and evaluators the newest version and whether the run is
// done.
//
// The snapshot writer keeps one sample (KEEP_LAST 1), so a new snapshot written while a reader
// is still fetching the last one replaces it under that reader: on a link slower than the
// learner publishes, the reader would never hold a whole snapshot. So a snapshot is written only
// once every matched reader has acknowledged the last one, or when the last one has waited
// `hold_s` (a reader that is gone keeps its match until its lease ends and must not stop the
// others' snapshots for longer). The learner marks a snapshot due every snapshot_every updates;
// take_due() says when it may go, so a slow reader gets fewer snapshots, each of them whole, and
// the parameters are taken when it goes. The run's last snapshot is also kept as a file
// (write_final_file), so it can be evaluated without the learner.
//
//   VersionReservation versions(run.checkpoints() / "policy_versions_reserved");
//   SnapshotPublisher publisher(endpoints, run_id, hold_s);
//   publisher.mark_due();                           // every snapshot_every updates
//   if (publisher.take_due(updates)) {              // else: held for a reader, try again later
//     versions.reserve(version);                    // before the version leaves the process
//     publisher.publish(std::move(snapshot), done); // sealed, written, announced
//   }
//   if (publisher.serve_request(done)) ++served;    // a late joiner's request, when it can be
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "indrive/agent/agent_config.h"
#include "indrive/dds/messages.h"
#include "indrive/dds/participant.h"

namespace indrive::learner {

// Policy versions reserved in blocks, written to a file before any of them is published, so a
// learner killed between checkpoints never hands out a version twice after its restart.
class VersionReservation {
 public:
  // Reads the reserved mark (0 without a file); throws CheckpointError when the file holds no
  // version.
  explicit VersionReservation(std::filesystem::path file);
  // The highest version reserved on disk.
  std::uint64_t reserved() const { return reserved_; }
  // Makes sure `version` is reserved on disk, a block at a time; throws IoError when the file
  // cannot be written.
  void reserve(std::uint64_t version);
  // After the final checkpoint, lowers the mark to the newest version `published`, so a clean
  // restart continues right after it; a failure to write is logged and harmless (the larger
  // reservation stays valid).
  void release(std::uint64_t published);

 private:
  std::filesystem::path file_;
  std::uint64_t reserved_ = 0;
};

class SnapshotPublisher {
 public:
  // Creates the snapshot and announce writers and the request reader on `endpoints`, which must
  // outlive the publisher's use (the set tears them down).
  // hold_s: how long a written snapshot may wait for every reader's acknowledgment before the
  // next one is written anyway.
  SnapshotPublisher(dds::EndpointSet& endpoints, std::string run_id, double hold_s);

  // Whether a new snapshot may be written now: none was written yet, every matched reader has
  // acknowledged the last one, or it was written hold_s ago or more.
  bool ready() const;
  // Whether every matched reader has acknowledged every snapshot written (true before the first).
  bool delivered() const;
  // Seals and writes `snapshot` (its version and contents filled in), keeps it as the newest and
  // announces it, whether or not ready() (the final snapshot of a run does not wait); a due
  // snapshot is no longer due.
  void publish(msg::PolicySnapshot snapshot, bool done);

  // Marks a snapshot due.
  void mark_due() { due_ = true; }
  bool due() const { return due_; }
  // True when a snapshot is due and may be written now (ready()); it is then no longer due.
  // While it may not, it stays due and counts once as held (logged at most once a minute, with
  // `updates`, the learner's count); one written because hold_s ran out before every reader had
  // the last one counts as an expired hold (logged).
  bool take_due(std::int64_t updates);
  // Due snapshots held for a reader, and holds that ran out, in this process.
  std::uint64_t holds() const { return holds_; }
  std::uint64_t holds_expired() const { return holds_expired_; }

  // Writes the newest snapshot to `path` as a snapshot file of `agent` with its provenance (run,
  // version, env steps); a failure is logged, not thrown: the run's end still goes over DDS.
  void write_final_file(const std::filesystem::path& path, const agent::AgentConfig& agent) const;
  // Announces the newest snapshot (nothing before the first).
  void announce(bool done);
  // Writes the newest snapshot again and announces it; false when there is none yet, or when
  // the last write is still on its way to some reader (!ready()): writing it again would start
  // that reader over, and the sample on its way reaches every matched reader, the asker too.
  bool republish(bool done);
  // Waits up to `timeout` until every matched reader has acknowledged the newest snapshot.
  bool wait_until_delivered(std::chrono::milliseconds timeout);
  // The last announce, written reliably: waits (up to 5 s) until every matched reader has it,
  // since the heartbeat's "done" is best effort and can be lost as the process exits.
  void announce_final(bool done);
  // Serves a SnapshotRequest of this run that came since the newest snapshot was last written:
  // writes it again (republish) and returns true. A request that cannot be served yet (no
  // snapshot, or the last write still unacknowledged: !ready()) stays pending for a later call;
  // a snapshot written by publish() serves it as well.
  bool serve_request(bool done);
  // Whether a request waits to be served.
  bool request_pending() const { return requested_.load(); }

  // Readers matched by both the snapshot and the announce writer (the fewer of the two). The
  // announce is volatile: a reader that this side has not matched yet misses it, even when that
  // reader already matched this writer from its side (discovery is not symmetric in time).
  int readers() const;

  const std::optional<msg::PolicySnapshot>& newest() const { return newest_; }
  // Seconds since the last announce (very many before the first).
  double seconds_since_announce() const;

 private:
  std::string run_id_;
  dds::Writer<msg::PolicySnapshot>& snapshot_writer_;
  dds::Writer<msg::SnapshotAnnounce>& announce_writer_;
  std::atomic<bool> requested_{false};
  std::optional<msg::PolicySnapshot> newest_;
  double hold_s_;
  std::chrono::steady_clock::duration hold_;
  bool due_ = false;
  bool held_ = false;  // the due snapshot waits for a reader to acknowledge the last one
  std::uint64_t holds_ = 0;
  std::uint64_t holds_expired_ = 0;
  std::chrono::steady_clock::time_point last_hold_log_{};
  std::chrono::steady_clock::time_point last_write_{};
  std::chrono::steady_clock::time_point last_announce_{};  // the epoch: due at once
};

}  // namespace indrive::learner
