// The small wire messages and the snapshot, as the actors, evaluators and the learner handle
// them: CDR -> wire checks -> snapshot inbox (offer, announce, re-request) -> the parameter blob
// loaded into a policy; results and requests as the learner counts them.
// Input: one byte (bit 0 re-seals the message with a valid checksum, bits 1-3 pick the type),
// then the CDR sample.
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>

#include "fuzz_agent.h"
#include "fuzz_cdr.h"
#include "fuzz_support.h"
#include "indrive/actor/snapshot_inbox.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/run_dir.h"
#include "indrive/nn/serialize.h"
#include "indrive/service/run_config.h"

namespace {

using namespace indrive;

enum Kind : std::uint8_t {
  kSnapshot,
  kAnnounce,
  kRequest,
  kAllowance,
  kResult,
  kHeartbeat,
  kKinds
};

msg::PolicySnapshot real_snapshot() {
  const auto config = fuzz::micro_agent();
  agent::Agent agent(config);
  msg::PolicySnapshot snapshot;
  snapshot.run_id("fuzz");
  snapshot.version(7);
  snapshot.preset(config.preset);
  snapshot.architecture(service::architecture_descriptor(config));
  snapshot.heads(msg::HEAD_ENCODER | msg::HEAD_RSSM | msg::HEAD_EXPLORATION_ACTOR);
  snapshot.phase(msg::PHASE_PRETRAIN);
  snapshot.env_steps(1234);
  snapshot.updates(56);
  snapshot.params(agent.snapshot());
  indrive::dds::seal(snapshot);
  return snapshot;
}

template <typename T>
void seed(const fuzz::fs::path& dir, const std::string& name, Kind kind, const T& message) {
  std::vector<std::uint8_t> input = {static_cast<std::uint8_t>(kind << 1)};
  const auto cdr = fuzz::to_cdr(message);
  input.insert(input.end(), cdr.begin(), cdr.end());
  fuzz::write_seed(dir, name, input);
}

void make_seeds(const fuzz::fs::path& dir) {
  const auto snapshot = real_snapshot();
  seed(dir, "snapshot", kSnapshot, snapshot);
  seed(dir, "announce", kAnnounce, indrive::dds::announce_for(snapshot));
  msg::SnapshotRequest request;
  request.run_id("fuzz");
  request.requester_role(msg::ROLE_EVALUATOR);
  request.requester_id(2);
  indrive::dds::seal(request);
  seed(dir, "request", kRequest, request);
  msg::StepAllowance allowance;
  allowance.run_id("fuzz");
  allowance.total_env_steps(5000);
  allowance.replay_ratio(32);
  allowance.learner_epoch(2);
  allowance.policy_version(7);
  indrive::dds::seal(allowance);
  seed(dir, "allowance", kAllowance, allowance);
  msg::EpisodeResult result;
  result.run_id("fuzz");
  result.sender_role(msg::ROLE_ACTOR);
  result.town("town01");
  result.route("right_loop");
  result.density(10);
  result.success(false);
  result.failure_reason("collision");
  result.steps(321);
  result.route_completion(0.4f);
  result.reach_segments(12);
  indrive::dds::seal(result);
  seed(dir, "result", kResult, result);
  msg::Heartbeat beat;
  beat.role(msg::ROLE_LEARNER);
  beat.run_id("fuzz");
  beat.state("running");
  beat.env_steps(999);
  indrive::dds::seal(beat);
  seed(dir, "heartbeat", kHeartbeat, beat);
}

struct Receiver {
  agent::AgentConfig config = fuzz::micro_agent();
  actor::SnapshotInbox inbox{"fuzz", service::architecture_descriptor(config), 0.1};
  agent::Policy policy{config};
  EpisodeStats episodes;
  std::uint64_t held = 0;
};

template <typename T>
bool decode(const std::uint8_t* data, std::size_t size, T& message) {
  if (!fuzz::from_cdr(std::span(data + 1, size - 1), message)) return false;
  if (data[0] & 1) indrive::dds::seal(message);
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  // One receiver for the whole run, as a long-lived actor has: state carried between
  // messages is part of what is tested.
  static Receiver receiver;
  switch (static_cast<Kind>((data[0] >> 1) % kKinds)) {
    case kSnapshot: {
      msg::PolicySnapshot snapshot;
      if (!decode(data, size, snapshot)) return 0;
      receiver.inbox.offer(snapshot);
      if (auto newest = receiver.inbox.take_newer_than(receiver.held)) {
        receiver.held = newest->version();
        fuzz::accept<nn::SerializationError>(
            [&] { receiver.policy.load_snapshot(newest->params()); });
      }
      break;
    }
    case kAnnounce: {
      msg::SnapshotAnnounce announce;
      if (!decode(data, size, announce)) return 0;
      receiver.inbox.announce(announce);
      receiver.inbox.should_request(receiver.held, actor::SnapshotInbox::Clock::now());
      break;
    }
    case kRequest: {
      msg::SnapshotRequest request;
      if (decode(data, size, request)) indrive::dds::validate(request, "fuzz");
      break;
    }
    case kAllowance: {
      msg::StepAllowance allowance;
      if (decode(data, size, allowance)) indrive::dds::validate(allowance, "fuzz");
      break;
    }
    case kResult: {
      msg::EpisodeResult result;
      if (!decode(data, size, result)) return 0;
      if (indrive::dds::validate(result, "fuzz") == indrive::dds::DropReason::kOk &&
          result.sender_role() == msg::ROLE_ACTOR) {
        receiver.episodes.add(result.steps(), result.reach_segments());
        nlohmann::json record;
        receiver.episodes.write(record);
      }
      break;
    }
    case kHeartbeat: {
      msg::Heartbeat beat;
      if (decode(data, size, beat)) indrive::dds::validate(beat, "fuzz");
      break;
    }
    case kKinds:
      break;
  }
  return 0;
}
