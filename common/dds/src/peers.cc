#include "indrive/dds/peers.h"

namespace indrive::dds {

namespace {

double seconds(PeerLedger::Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

void PeerLedger::discovered(const std::string& guid, bool offers_identity, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  auto [it, inserted] = peers_.try_emplace(guid);
  // A participant already authenticated or refused keeps its state: discovery also reports
  // changes of a known participant's QoS.
  if (!inserted) return;
  it->second.state = offers_identity ? State::kPending : State::kUnsecured;
  it->second.discovered_at = now;
}

double PeerLedger::authenticated(const std::string& guid, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  ++authenticated_total_;
  auto [it, inserted] = peers_.try_emplace(guid);
  const double waited = inserted ? 0.0 : seconds(now - it->second.discovered_at);
  if (inserted) it->second.discovered_at = now;
  it->second.state = State::kAuthenticated;
  return waited;
}

bool PeerLedger::refused(const std::string& guid) {
  std::lock_guard lock(mutex_);
  Peer& peer = peers_[guid];
  if (peer.state == State::kUnsecured) return false;
  ++refused_total_;
  peer.state = State::kRefused;
  return true;
}

void PeerLedger::left(const std::string& guid) {
  std::lock_guard lock(mutex_);
  peers_.erase(guid);
}

std::vector<PeerLedger::Stalled> PeerLedger::newly_stalled(Clock::time_point now,
                                                           Clock::duration after) {
  std::lock_guard lock(mutex_);
  std::vector<Stalled> out;
  for (auto& [guid, peer] : peers_) {
    if (peer.state != State::kPending || peer.stall_reported) continue;
    if (now - peer.discovered_at < after) continue;
    peer.stall_reported = true;
    out.push_back({guid, seconds(now - peer.discovered_at)});
  }
  return out;
}

PeerLedger::Counts PeerLedger::counts() const {
  std::lock_guard lock(mutex_);
  Counts counts;
  counts.authenticated = authenticated_total_;
  counts.refused = refused_total_;
  for (const auto& [guid, peer] : peers_) {
    if (peer.state == State::kRefused) continue;
    ++counts.present;
    counts.pending += peer.state == State::kPending;
    counts.stalled += peer.state == State::kPending && peer.stall_reported;
    counts.unsecured += peer.state == State::kUnsecured;
  }
  return counts;
}

}  // namespace indrive::dds
