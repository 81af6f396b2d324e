// What one DDS participant knows of the others in its domain: when each was discovered, whether
// DDS Security authenticated or refused it, and which secure handshakes have been pending too
// long. The participant (participant.h) feeds it from Fast DDS's discovery and authentication
// callbacks and logs what it records; the ledger itself only keeps the books, on a clock the
// caller passes in, so it is tested without a network.
#pragma once

#include <chrono>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace indrive::dds {

class PeerLedger {
 public:
  using Clock = std::chrono::steady_clock;

  struct Counts {
    int present = 0;        // discovered and not gone since
    int authenticated = 0;  // DDS Security handshakes completed (over the ledger's life)
    int refused = 0;        // identities DDS Security refused (over the ledger's life)
    int pending = 0;        // present, offering an identity, handshake not completed
    int stalled = 0;        // of those, the ones newly_stalled() has returned
    int unsecured = 0;      // present with no handshake to come (either side without security)
  };

  struct Stalled {
    std::string guid;
    double pending_s = 0.0;
  };

  // A participant seen by discovery. `offers_identity`: both sides use DDS Security (it
  // announced an identity), so a handshake follows; otherwise none ever will.
  void discovered(const std::string& guid, bool offers_identity, Clock::time_point now);
  // Its handshake completed; returns the seconds since it was discovered (0 when unknown).
  double authenticated(const std::string& guid, Clock::time_point now);
  // DDS Security refused it. Returns false for a participant discovered without an identity
  // (Fast DDS reports those as refused too; they stay counted as unsecured, not as refused).
  bool refused(const std::string& guid);
  // It left (lease expired or removed); a later discovery starts afresh.
  void left(const std::string& guid);

  // The participants whose handshake has been pending for at least `after`, each returned once
  // per discovery: the caller warns about each stall a single time.
  std::vector<Stalled> newly_stalled(Clock::time_point now, Clock::duration after);

  Counts counts() const;

 private:
  enum class State { kPending, kAuthenticated, kRefused, kUnsecured };
  struct Peer {
    State state = State::kPending;
    Clock::time_point discovered_at{};
    bool stall_reported = false;
  };

  mutable std::mutex mutex_;
  std::map<std::string, Peer> peers_;
  int authenticated_total_ = 0;
  int refused_total_ = 0;
};

}  // namespace indrive::dds
