#include "indrive/actor/learner_link.h"

#include <algorithm>
#include <utility>

#include "indrive/basics/log.h"
#include "indrive/dds/security.h"

namespace indrive::actor {

LearnerLink::LearnerLink(const service::ServiceConfig& service, LearnerLinkOptions options,
                         LearnerLinkHooks hooks)
    : service_(service),
      options_(std::move(options)),
      hooks_(std::move(hooks)),
      inbox_(service.run_id(), options_.architecture, options_.request_after_s),
      rejoin_(options_.rejoin_after_s, options_.rejoin_max_s) {
  connect();
}

LearnerLink::~LearnerLink() { endpoints_.reset(); }

void LearnerLink::connect() {
  endpoints_ = std::make_unique<dds::EndpointSet>(service_.participant_options(options_.role));
  if (hooks_.add_endpoints) hooks_.add_endpoints(*endpoints_, *this);
  results_ = &endpoints_->writer<msg::EpisodeResult>();
  requests_ = &endpoints_->writer<msg::SnapshotRequest>();
  endpoints_->reader<msg::PolicySnapshot>([this](const msg::PolicySnapshot& snapshot) {
    inbox_.offer(snapshot);
    if (hooks_.on_snapshot_news) hooks_.on_snapshot_news();
  });
  endpoints_->reader<msg::SnapshotAnnounce>([this](const msg::SnapshotAnnounce& announce) {
    inbox_.announce(announce);
    if (hooks_.on_snapshot_news) hooks_.on_snapshot_news();
  });
  endpoints_->reader<msg::Heartbeat>([this](const msg::Heartbeat& heartbeat) {
    if (heartbeat.role() == msg::ROLE_LEARNER &&
        dds::validate(heartbeat, service_.run_id()) == dds::DropReason::kOk) {
      heard();
      if (heartbeat.state() == "done") learner_done_.store(heartbeat.policy_version());
    }
    if (hooks_.on_heartbeat) hooks_.on_heartbeat(heartbeat);
  });
  connected_at_ = Clock::now();
}

void LearnerLink::request_snapshot() {
  msg::SnapshotRequest request;
  request.run_id(service_.run_id());
  request.version(0);
  request.requester_role(options_.requester_role);
  request.requester_id(options_.id);
  dds::seal(request);
  requests_->write(request);
}

void LearnerLink::heard() { heard_at_.store(Clock::now().time_since_epoch().count()); }

LearnerLink::Clock::time_point LearnerLink::heard_at() const {
  return Clock::time_point{Clock::duration(heard_at_.load())};
}

double LearnerLink::silent_s() const {
  const Clock::time_point since = std::max(heard_at(), created_);
  return std::chrono::duration<double>(Clock::now() - since).count();
}

std::uint64_t LearnerLink::final_version() const {
  return std::max(learner_done_.load(), inbox_.final_version());
}

bool LearnerLink::maybe_rejoin() {
  if (!rejoin_.enabled()) return false;
  const double connected_s = std::chrono::duration<double>(Clock::now() - connected_at_).count();
  const bool never_heard = heard_at() < connected_at_;  // nothing since this participant was made
  if (!never_heard) rejoin_.heard();
  const double wait_s = rejoin_.wait_s();
  if (silent_s() < wait_s || connected_s < wait_s) return false;
  if (!never_heard &&
      !(options_.replace_silent_over_shm && endpoints_->participant().uses_shared_memory())) {
    return false;
  }
  ++rejoins_;
  if (never_heard) rejoin_.replaced();
  INDRIVE_LOG(kWarn, options_.role)
      << options_.role << " " << options_.id << " heard nothing of the learner of run '"
      << service_.run_id() << "' for " << wait_s << " s; recreating its DDS participant (rejoin "
      << rejoins_ << "; the next after " << rejoin_.wait_s() << " s of silence)";
  results_ = nullptr;
  requests_ = nullptr;
  endpoints_.reset();
  connect();
  return true;
}

}  // namespace indrive::actor
