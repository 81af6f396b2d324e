// A training actor's or an evaluator's link to the learner of its run: one DDS participant with
// the learner's snapshots (a SnapshotInbox), the snapshot re-request and the episode results,
// what the learner's heartbeats say (when it was last heard, the version it called its last),
// and the rule by which a process that hears nothing of its learner replaces its participant.
//
// Why a participant is replaced: on one host a process killed with SIGKILL leaves shared-memory
// ports behind that Fast DDS resets in every process that touches them, and once (in CI, under
// load) an actor restarted after such a kill never heard the learner within 60 s; the cause was
// not reproduced in about 50 local runs. With DDS Security a new participant's handshake with the
// learner can stall for good (in about 55 runs of the two-host security test, once for an actor
// over UDP, which heard nothing for 150 s while another trained; once for a late evaluator, which
// waited 120 s for its first snapshot while every other participant had authenticated it). A new
// participant is discovered, and its handshake starts, afresh; a learner that is merely gone is
// found again the same way when it returns.
//
// The rule (maybe_rejoin): a participant that has heard nothing of the learner since it was made
// is replaced after RejoinSchedule::wait_s() of its life; each such replacement doubles the next
// wait, up to the schedule's maximum. A participant that has heard the learner and then falls
// silent is replaced only where `replace_silent_over_shm` is set and it uses shared memory: across
// hosts, silence means a cut link, where replacing it loses the chunks the old participant still
// held for the learner (tests/system/two_host_test.cc); a participant that never heard the
// learner holds none (no allowance, no chunk).
//
//   LearnerLink link(service, {.role = "actor", .requester_role = msg::ROLE_ACTOR, ...},
//                    {.add_endpoints = [&](dds::EndpointSet& set, LearnerLink&) { ...its own...
//                    }});
//   if (auto snapshot = link.inbox().take_newer_than(held)) ...;
//   if (link.inbox().should_request(held, now)) link.request_snapshot();
//   if (link.maybe_rejoin()) ...say who we are to the new participant's peers...;
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "indrive/actor/rejoin.h"
#include "indrive/actor/snapshot_inbox.h"
#include "indrive/dds/participant.h"
#include "indrive/service/run_config.h"

namespace indrive::actor {

class LearnerLink;

struct LearnerLinkOptions {
  std::string role;  // the participant's role ("actor", "evaluator") and log channel
  msg::Role requester_role = msg::ROLE_ACTOR;  // or msg::ROLE_EVALUATOR
  std::uint32_t id = 0;                        // the actor id or evaluator index
  std::string architecture;      // the process's architecture descriptor (snapshot filter)
  double request_after_s = 2.0;  // SnapshotInbox: an announced version missing this long
  double rejoin_after_s = 0.0;   // RejoinSchedule; <= 0 never replaces the participant
  double rejoin_max_s = 0.0;
  bool replace_silent_over_shm = false;  // see the rule above
};

// What the owning process adds to each participant and hears from it (DDS threads call these).
struct LearnerLinkHooks {
  // The process's own readers and writers, made on every new participant before the link's
  // (the link is passed for its heard(): the hook may run before the constructor returns).
  std::function<void(dds::EndpointSet&, LearnerLink&)> add_endpoints;
  // A snapshot or an announce reached the inbox.
  std::function<void()> on_snapshot_news;
  // Every heartbeat received (of any role or run: the hook filters).
  std::function<void(const msg::Heartbeat&)> on_heartbeat;
};

class LearnerLink {
 public:
  using Clock = std::chrono::steady_clock;

  // Makes the first participant (throws dds::DdsError when it cannot be made).
  LearnerLink(const service::ServiceConfig& service, LearnerLinkOptions options,
              LearnerLinkHooks hooks = {});
  // The participant goes first: its readers' callbacks use the inbox and the hooks.
  ~LearnerLink();
  LearnerLink(const LearnerLink&) = delete;
  LearnerLink& operator=(const LearnerLink&) = delete;

  SnapshotInbox& inbox() { return inbox_; }
  const SnapshotInbox& inbox() const { return inbox_; }
  // The current participant's writers (a replacement makes new ones).
  dds::Writer<msg::EpisodeResult>& results() { return *results_; }
  dds::EndpointSet& endpoints() { return *endpoints_; }

  // Asks the learner to send its newest snapshot again.
  void request_snapshot();

  // Something of the learner of this run arrived that the link's own readers do not see (an
  // actor's accepted StepAllowance): counts as hearing the learner.
  void heard();
  // Seconds since the learner was last heard (since the link was made when never).
  double silent_s() const;
  // When the learner was last heard; Clock::time_point{} when never.
  Clock::time_point heard_at() const;
  // The version the learner declared its last, by its reliable final announce or its "done"
  // heartbeat (0: not yet).
  std::uint64_t final_version() const;

  // Replaces the participant when the rule above says so; true when it did.
  bool maybe_rejoin();
  // Participants replaced so far.
  std::uint64_t rejoins() const { return rejoins_; }

 private:
  void connect();

  const service::ServiceConfig& service_;
  LearnerLinkOptions options_;
  LearnerLinkHooks hooks_;
  SnapshotInbox inbox_;
  RejoinSchedule rejoin_;
  std::uint64_t rejoins_ = 0;
  const Clock::time_point created_ = Clock::now();
  Clock::time_point connected_at_{};
  std::atomic<Clock::rep> heard_at_{0};  // steady-clock ticks; 0: never
  std::atomic<std::uint64_t> learner_done_{0};
  std::unique_ptr<dds::EndpointSet> endpoints_;
  dds::Writer<msg::EpisodeResult>* results_ = nullptr;
  dds::Writer<msg::SnapshotRequest>* requests_ = nullptr;
};

}  // namespace indrive::actor
