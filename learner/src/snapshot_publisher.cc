#include "indrive/learner/snapshot_publisher.h"

#include <algorithm>
#include <string>
#include <utility>

#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/learner/checkpoint.h"

namespace indrive::learner {
namespace {

// Versions reserved at a time: one file write per this many snapshots.
constexpr std::uint64_t kVersionReserveBlock = 100;

}  // namespace

VersionReservation::VersionReservation(std::filesystem::path file) : file_(std::move(file)) {
  if (!std::filesystem::exists(file_)) return;
  const auto bytes = read_file(file_);
  try {
    reserved_ = std::stoull(std::string(bytes.begin(), bytes.end()));
  } catch (const std::exception&) {
    throw CheckpointError("file " + file_.string() +
                          " does not hold a policy version; delete it only if no actor of this "
                          "run still holds a snapshot");
  }
}

void VersionReservation::reserve(std::uint64_t version) {
  if (version <= reserved_) return;
  reserved_ = version + kVersionReserveBlock - 1;
  atomic_write(file_, std::to_string(reserved_));
}

void VersionReservation::release(std::uint64_t published) {
  if (reserved_ <= published) return;
  try {
    atomic_write(file_, std::to_string(published));
    reserved_ = published;
  } catch (const IoError& error) {
    INDRIVE_LOG(kWarn, "learner") << "reserved policy versions not released: " << error.what()
                                  << "; a restart skips to v" << reserved_ + 1;
  }
}

SnapshotPublisher::SnapshotPublisher(dds::EndpointSet& endpoints, std::string run_id, double hold_s)
    : run_id_(std::move(run_id)),
      snapshot_writer_(endpoints.writer<msg::PolicySnapshot>()),
      announce_writer_(endpoints.writer<msg::SnapshotAnnounce>()),
      hold_s_(hold_s),
      hold_(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(hold_s))) {
  endpoints.reader<msg::SnapshotRequest>([this](const msg::SnapshotRequest& request) {
    if (dds::validate(request, run_id_) != dds::DropReason::kOk) return;
    requested_.store(true);
  });
}

bool SnapshotPublisher::ready() const {
  return !newest_ || std::chrono::steady_clock::now() - last_write_ >= hold_ || delivered();
}

bool SnapshotPublisher::delivered() const {
  // A zero timeout only looks: true when nothing written is unacknowledged by a matched reader.
  return snapshot_writer_.wait_for_acknowledgments(std::chrono::milliseconds(0));
}

void SnapshotPublisher::publish(msg::PolicySnapshot snapshot, bool done) {
  snapshot.run_id(run_id_);
  dds::seal(snapshot);
  requested_.store(false);  // before the write: a request arriving after it is served by it
  snapshot_writer_.write(snapshot);
  last_write_ = std::chrono::steady_clock::now();
  newest_ = std::move(snapshot);
  due_ = false;
  held_ = false;
  announce(done);
}

bool SnapshotPublisher::take_due(std::int64_t updates) {
  if (!due_) return false;
  if (!ready()) {
    if (!held_) {
      held_ = true;
      ++holds_;
      if (std::chrono::steady_clock::now() - last_hold_log_ >= std::chrono::seconds(60)) {
        last_hold_log_ = std::chrono::steady_clock::now();
        INDRIVE_LOG(kInfo, "learner")
            << "snapshot due at " << updates << " updates waits: a reader has not yet "
            << "acknowledged v" << newest_->version() << " (" << newest_->params().size() / 1e6
            << " MB), so a new one would start it over; it goes when every reader has it, or "
               "after learner.snapshot_hold_s (logged at most once a minute)";
      }
    }
    return false;
  }
  if (held_ && !delivered()) {
    ++holds_expired_;
    INDRIVE_LOG(kWarn, "learner") << "v" << newest_->version()
                                  << " was not acknowledged by every reader within "
                                     "learner.snapshot_hold_s = "
                                  << hold_s_ << " s; publishing the next anyway (a reader has "
                                  << "gone, or its link carries less than one snapshot per "
                                  << hold_s_ << " s)";
  }
  held_ = false;
  due_ = false;
  return true;
}

void SnapshotPublisher::write_final_file(const std::filesystem::path& path,
                                         const agent::AgentConfig& agent) const {
  if (!newest_) return;
  try {
    agent::write_snapshot_file(
        path, newest_->params(), agent,
        agent::SnapshotProvenance{
            .run_id = run_id_, .version = newest_->version(), .env_steps = newest_->env_steps()});
    INDRIVE_LOG(kInfo, "learner") << "final snapshot v" << newest_->version() << " written to "
                                  << path.string();
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "learner")
        << "the final snapshot v" << newest_->version() << " could not be written to "
        << path.string() << " (" << error.what()
        << "); evaluators still receive it over DDS while the learner "
           "runs";
  }
}

int SnapshotPublisher::readers() const {
  return std::min(snapshot_writer_.matched(), announce_writer_.matched());
}

bool SnapshotPublisher::wait_until_delivered(std::chrono::milliseconds timeout) {
  return snapshot_writer_.wait_for_acknowledgments(timeout);
}

void SnapshotPublisher::announce(bool done) {
  if (!newest_) return;
  msg::SnapshotAnnounce message;
  message.run_id(run_id_);
  message.version(newest_->version());
  message.checksum(newest_->checksum());
  message.size_bytes(newest_->params().size());
  message.learner_done(done);
  dds::seal(message);
  announce_writer_.write(message);
  last_announce_ = std::chrono::steady_clock::now();
}

bool SnapshotPublisher::republish(bool done) {
  if (!newest_ || !ready()) return false;
  snapshot_writer_.write(*newest_);
  last_write_ = std::chrono::steady_clock::now();
  announce(done);
  return true;
}

bool SnapshotPublisher::serve_request(bool done) {
  if (!requested_.load() || !newest_ || !ready()) return false;
  requested_.store(false);  // before the write, as in publish()
  return republish(done);
}

void SnapshotPublisher::announce_final(bool done) {
  if (!newest_) return;
  announce(done);
  if (!announce_writer_.wait_for_acknowledgments(std::chrono::seconds(5))) {
    INDRIVE_LOG(kWarn, "learner") << "not every reader acknowledged the final announce of v"
                                  << newest_->version() << " within 5 s";
  }
}

double SnapshotPublisher::seconds_since_announce() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - last_announce_).count();
}

}  // namespace indrive::learner
