// One side of the two-process DDS transfer test (dds_transfer_test.cc spawns two of these).
//
//   dds_peer publish --profiles F --domain D --run-id R --chunks N --snapshot-mb M
//                    --ready PATH --result PATH
//     Writes a PolicySnapshot before any reader exists, touches PATH (--ready), waits for a
//     trajectory reader, writes four malformed chunks and N good ones, waits for every
//     acknowledgment and writes its figures to --result.
//   dds_peer receive --profiles F --domain D --run-id R --chunks N --result PATH --timeout S
//     Joins late, checks the snapshot and every chunk against the synthetic generator, counts
//     drops, and writes its counts to --result once all arrived (exit 0) or at the timeout.
//   dds_peer intrude --profiles F --domain D --run-id R --timeout S --result PATH [--actor-id N]
//     An outsider of a run (tests/system/two_host_test.cc): reads every topic for S seconds
//     (or until SIGTERM) and counts the samples it gets from others, writes a sealed chunk as
//     actor N (default 7) every 100 ms and one snapshot of version 1000, and records which of
//     its writers could not be made (DDS Security may deny them) and how many readers of other
//     participants its writers matched. Its own readers, which also match its own writers, are
//     counted out. The counts so far are rewritten to --result every second (replaced whole),
//     so a test can wait for what it needs and then stop the peer.
//   All take --security DIR --role ROLE to run with DDS Security (a folder of
//   deploy/dds/make_security.sh and the role whose certificate and permissions to use).
#include <signal.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>

#include "indrive/basics/log.h"
#include "indrive/basics/stopwatch.h"
#include "indrive/dds/participant.h"
#include "synthetic_traffic.h"

namespace {

using Clock = std::chrono::steady_clock;
using indrive::seconds_since;
using indrive::dds::DropReason;

struct Args {
  std::string mode, profiles, run_id, ready, result, security, role;
  int domain = 0;
  int chunks = 1000;
  int snapshot_mb = 10;
  int timeout_s = 45;
  int actor_id = 7;
};

Args parse_args(int argc, char** argv) {
  Args args;
  if (argc < 2) throw std::invalid_argument("usage: dds_peer publish|receive --flags...");
  args.mode = argv[1];
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--profiles")
      args.profiles = value;
    else if (flag == "--run-id")
      args.run_id = value;
    else if (flag == "--ready")
      args.ready = value;
    else if (flag == "--result")
      args.result = value;
    else if (flag == "--security")
      args.security = value;
    else if (flag == "--role")
      args.role = value;
    else if (flag == "--domain")
      args.domain = std::stoi(value);
    else if (flag == "--chunks")
      args.chunks = std::stoi(value);
    else if (flag == "--snapshot-mb")
      args.snapshot_mb = std::stoi(value);
    else if (flag == "--timeout")
      args.timeout_s = std::stoi(value);
    else if (flag == "--actor-id")
      args.actor_id = std::stoi(value);
    else
      throw std::invalid_argument("unknown flag " + flag);
  }
  return args;
}

indrive::dds::ParticipantOptions participant_options(const Args& args) {
  return {.domain_id = args.domain,
          .profiles_file = args.profiles,
          .security_dir = args.security,
          .security_role = args.role};
}

// The four malformed chunks the publisher sends; the receiver must count one of each.
std::vector<indrive::msg::TrajectoryChunk> malformed_chunks(const std::string& run_id,
                                                            std::uint64_t first_seq) {
  using indrive::testing::make_synthetic_chunk;
  std::vector<indrive::msg::TrajectoryChunk> chunks;
  auto bad_checksum = make_synthetic_chunk(run_id, 0, first_seq);
  bad_checksum.frames_zstd()[bad_checksum.frames_zstd().size() / 2] ^= 0x5a;
  chunks.push_back(bad_checksum);
  auto wrong_schema = make_synthetic_chunk(run_id, 0, first_seq + 1);
  wrong_schema.schema_version(indrive::dds::kSchemaVersion + 1);
  chunks.push_back(wrong_schema);
  chunks.push_back(make_synthetic_chunk(run_id + "-other", 0, first_seq + 2));
  auto bad_shape = make_synthetic_chunk(run_id, 0, first_seq + 3);
  bad_shape.actions().pop_back();
  indrive::dds::seal(bad_shape);
  chunks.push_back(bad_shape);
  return chunks;
}

int publish(const Args& args) {
  indrive::dds::Participant participant(participant_options(args));
  auto policy_writer = participant.make_writer<indrive::msg::PolicySnapshot>();
  auto chunk_writer = participant.make_writer<indrive::msg::TrajectoryChunk>();

  // Prepare every chunk first, so the timing below measures DDS and not the generator.
  const auto generate_start = Clock::now();
  std::vector<indrive::msg::TrajectoryChunk> chunks;
  chunks.reserve(args.chunks);
  std::size_t wire_bytes = 0;
  for (int i = 0; i < args.chunks; ++i) {
    chunks.push_back(indrive::testing::make_synthetic_chunk(args.run_id, 0, i));
    wire_bytes += chunks.back().frames_zstd().size();
  }
  const double generate_s = seconds_since(generate_start);
  const std::size_t raw_bytes = static_cast<std::size_t>(args.chunks) * 64 * 128 * 128;

  // The snapshot goes out before any reader exists: TRANSIENT_LOCAL must keep it for them.
  const auto snapshot = indrive::testing::make_synthetic_snapshot(
      args.run_id, 7, static_cast<std::size_t>(args.snapshot_mb) << 20);
  if (!policy_writer->write(snapshot)) throw std::runtime_error("snapshot write failed");
  std::ofstream(args.ready) << "snapshot written\n";

  if (!chunk_writer->wait_for_matched(1, std::chrono::seconds(args.timeout_s))) {
    throw std::runtime_error("no trajectory reader matched in time");
  }
  const auto send_start = Clock::now();
  for (const auto& chunk : malformed_chunks(args.run_id, args.chunks)) chunk_writer->write(chunk);
  int retries = 0;
  const auto give_up = Clock::now() + std::chrono::seconds(args.timeout_s);
  for (const auto& chunk : chunks) {
    // A full KEEP_ALL history refuses the write: back-pressure from the reader, so retry.
    while (!chunk_writer->write(chunk)) {
      ++retries;
      if (Clock::now() > give_up) throw std::runtime_error("trajectory writer stayed blocked");
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  const bool acked = chunk_writer->wait_for_acknowledgments(std::chrono::seconds(args.timeout_s)) &&
                     policy_writer->wait_for_acknowledgments(std::chrono::seconds(args.timeout_s));
  const double send_s = seconds_since(send_start);

  std::ofstream result(args.result);
  result << "acked " << (acked ? 1 : 0) << "\n"
         << "chunks " << chunks.size() << "\n"
         << "wire_mb " << wire_bytes / 1e6 << "\n"
         << "raw_mb " << raw_bytes / 1e6 << "\n"
         << "compression_ratio " << static_cast<double>(raw_bytes) / wire_bytes << "\n"
         << "generate_s " << generate_s << "\n"
         << "send_s " << send_s << "\n"
         << "wire_mb_per_s " << wire_bytes / 1e6 / send_s << "\n"
         << "raw_mb_per_s " << raw_bytes / 1e6 / send_s << "\n"
         << "write_retries " << retries << "\n";
  return acked ? 0 : 1;
}

int receive(const Args& args) {
  const auto start = Clock::now();
  indrive::dds::DropCounters chunk_drops;
  std::mutex mutex;
  std::condition_variable changed;
  std::set<std::uint64_t> seen;
  std::vector<indrive::msg::TrajectoryChunk> received;
  int duplicates = 0, mismatches = 0, snapshot_ok = 0, snapshot_bad = 0;
  double snapshot_s = -1.0, first_chunk_s = -1.0, last_chunk_s = -1.0;

  indrive::dds::Participant participant(participant_options(args));
  const double participant_s = seconds_since(start);
  auto policy_reader = participant.make_reader<indrive::msg::PolicySnapshot>(
      [&](const indrive::msg::PolicySnapshot& snapshot) {
        const bool ok = indrive::dds::validate(snapshot, args.run_id) == DropReason::kOk &&
                        indrive::testing::compare_with_synthetic(snapshot).empty() &&
                        snapshot.params().size() == static_cast<std::size_t>(args.snapshot_mb)
                                                        << 20;
        std::lock_guard<std::mutex> lock(mutex);
        (ok ? snapshot_ok : snapshot_bad) += 1;
        snapshot_s = seconds_since(start);
        changed.notify_all();
      });
  auto chunk_reader = participant.make_reader<indrive::msg::TrajectoryChunk>(
      [&](const indrive::msg::TrajectoryChunk& chunk) {
        // Like the learner: validate (checksum, shape, run) on arrival and keep what passes.
        // The byte-for-byte comparison with the generator happens after the timing.
        const DropReason reason = indrive::dds::validate(chunk, args.run_id);
        chunk_drops.record(reason);
        std::lock_guard<std::mutex> lock(mutex);
        if (reason == DropReason::kOk) {
          if (!seen.insert(chunk.chunk_seq()).second) ++duplicates;
          if (first_chunk_s < 0) first_chunk_s = seconds_since(start);
          last_chunk_s = seconds_since(start);
          received.push_back(chunk);
        }
        changed.notify_all();
      });

  bool complete = false;
  {
    std::unique_lock<std::mutex> lock(mutex);
    complete = changed.wait_for(lock, std::chrono::seconds(args.timeout_s), [&] {
      return snapshot_ok + snapshot_bad > 0 && static_cast<int>(seen.size()) >= args.chunks &&
             chunk_drops.dropped() >= 4;
    });
  }
  // Readers answer a writer's heartbeats with acknowledgments every 100 ms: staying a moment
  // lets the last ones reach the publisher, which waits for them. Leaving at once made it wait
  // up to its timeout, once the announcement that this reader left was lost (2 of 25 runs of the
  // two-host security cost test; the receiver had all 1,000 chunks).
  if (complete) std::this_thread::sleep_for(std::chrono::seconds(2));
  chunk_reader.reset();  // no more callbacks from here on
  policy_reader.reset();
  std::lock_guard<std::mutex> lock(mutex);
  for (const auto& chunk : received) {
    if (const std::string difference = indrive::testing::compare_with_synthetic(chunk);
        !difference.empty()) {
      ++mismatches;
      INDRIVE_LOG(kError, "peer") << "chunk " << chunk.chunk_seq() << ": " << difference;
    }
  }
  std::ofstream result(args.result);
  result << "complete " << (complete ? 1 : 0) << "\n"
         << "snapshot_ok " << snapshot_ok << "\n"
         << "snapshot_bad " << snapshot_bad << "\n"
         << "snapshot_s " << snapshot_s << "\n"
         << "chunks_ok " << seen.size() << "\n"
         << "duplicates " << duplicates << "\n"
         << "mismatches " << mismatches << "\n"
         << "chunk_s " << (last_chunk_s - first_chunk_s) << "\n"
         << "participant_s " << participant_s << "\n";
  for (int i = 1; i < indrive::dds::kNumDropReasons; ++i) {
    const auto reason = static_cast<DropReason>(i);
    result << indrive::dds::drop_reason_name(reason) << " " << chunk_drops.count(reason) << "\n";
  }
  return complete ? 0 : 1;
}

// Counts the samples a reader of topic T gets that `own` does not call its own; nullptr when
// the reader cannot be made (the set owns it otherwise).
template <typename T>
indrive::dds::Reader<T>* counting_reader(
    indrive::dds::EndpointSet& set, std::atomic<int>& count, std::map<std::string, int>& refused,
    std::function<bool(const T&)> own = [](const T&) { return false; }) {
  try {
    return &set.reader<T>([&count, own](const T& sample) {
      if (!own(sample)) count.fetch_add(1);
    });
  } catch (const indrive::dds::DdsError&) {
    refused[std::string(indrive::dds::TopicTraits<T>::kTopic)] = 1;
    return nullptr;
  }
}

template <typename T>
indrive::dds::Writer<T>* try_writer(indrive::dds::EndpointSet& set,
                                    std::map<std::string, int>& refused) {
  try {
    return &set.writer<T>();
  } catch (const indrive::dds::DdsError&) {
    refused[std::string(indrive::dds::TopicTraits<T>::kTopic)] = 1;
    return nullptr;
  }
}

std::atomic<bool> g_stop{false};

void on_stop_signal(int) { g_stop = true; }

int intrude(const Args& args) {
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGINT, &action, nullptr);
  namespace msg = indrive::msg;
  std::map<std::string, int> refused_readers, refused_writers;
  std::atomic<int> chunks{0}, snapshots{0}, announces{0}, requests{0}, allowances{0}, results{0},
      heartbeats{0};
  const auto own_id = static_cast<std::uint32_t>(args.actor_id);
  // The participant with its endpoints (an EndpointSet), replaced as a whole when one of its
  // DDS Security handshakes stalls, as the service's actors and evaluators replace theirs
  // (actor.rejoin_after_s): a stalled handshake never completes, a new participant's does.
  struct Endpoints {
    std::unique_ptr<indrive::dds::EndpointSet> set;
    bool reads_chunks = false, reads_policy = false;
    indrive::dds::Writer<msg::TrajectoryChunk>* chunk_writer = nullptr;
    indrive::dds::Writer<msg::PolicySnapshot>* policy_writer = nullptr;
  };
  int chunks_written = 0, snapshots_written = 0, rejoins = 0;
  const auto connect = [&] {
    Endpoints e{.set = std::make_unique<indrive::dds::EndpointSet>(participant_options(args))};
    auto& set = *e.set;
    refused_readers.clear(), refused_writers.clear();
    e.reads_chunks = counting_reader<msg::TrajectoryChunk>(
                         set, chunks, refused_readers, [own_id](const msg::TrajectoryChunk& chunk) {
                           return chunk.actor_id() == own_id;
                         }) != nullptr;
    e.reads_policy = counting_reader<msg::PolicySnapshot>(set, snapshots, refused_readers,
                                                          [](const msg::PolicySnapshot& snapshot) {
                                                            return snapshot.version() == 1000;
                                                          }) != nullptr;
    counting_reader<msg::SnapshotAnnounce>(set, announces, refused_readers);
    counting_reader<msg::SnapshotRequest>(set, requests, refused_readers);
    counting_reader<msg::StepAllowance>(set, allowances, refused_readers);
    counting_reader<msg::EpisodeResult>(set, results, refused_readers);
    counting_reader<msg::Heartbeat>(set, heartbeats, refused_readers);
    e.chunk_writer = try_writer<msg::TrajectoryChunk>(set, refused_writers);
    e.policy_writer = try_writer<msg::PolicySnapshot>(set, refused_writers);
    if (e.policy_writer) {
      snapshots_written += e.policy_writer->write(
          indrive::testing::make_synthetic_snapshot(args.run_id, 1000, std::size_t{1} << 20));
    }
    return e;
  };
  auto e = connect();
  int chunk_matches = 0, policy_matches = 0;
  const auto write_result = [&] {
    const std::string partial = args.result + ".partial";
    const indrive::dds::PeerLedger::Counts peers = e.set->participant().peers();
    std::ofstream result(partial);
    result << "read_trajectory " << chunks << "\n"
           << "read_policy " << snapshots << "\n"
           << "read_policy_announce " << announces << "\n"
           << "read_snapshot_request " << requests << "\n"
           << "read_allowance " << allowances << "\n"
           << "read_episode_result " << results << "\n"
           << "read_heartbeat " << heartbeats << "\n"
           << "chunks_written " << chunks_written << "\n"
           << "snapshots_written " << snapshots_written << "\n"
           << "trajectory_readers_matched " << chunk_matches - (e.reads_chunks ? 1 : 0) << "\n"
           << "policy_readers_matched " << policy_matches - (e.reads_policy ? 1 : 0) << "\n"
           << "trajectory_writer_refused " << refused_writers["indrive/trajectory"] << "\n"
           << "policy_writer_refused " << refused_writers["indrive/policy"] << "\n"
           << "readers_refused " << refused_readers.size() << "\n"
           << "participants_authenticated " << peers.authenticated << "\n"
           << "handshakes_pending " << peers.pending << "\n"
           << "rejoins " << rejoins << "\n";
    result.close();
    std::filesystem::rename(partial, args.result);
  };
  const auto end = Clock::now() + std::chrono::seconds(args.timeout_s);
  auto next_result = Clock::now();
  for (std::uint64_t seq = 0; Clock::now() < end && !g_stop; ++seq) {
    if (e.set->participant().peers().stalled > 0) {
      ++rejoins;
      INDRIVE_LOG(kWarn, "peer") << "a DDS Security handshake stalled; recreating the participant";
      e.set.reset();
      e = connect();
    }
    if (e.chunk_writer) {
      chunks_written += e.chunk_writer->write(
          indrive::testing::make_synthetic_chunk(args.run_id, own_id, seq, 16, 32, 32));
      chunk_matches = std::max(chunk_matches, e.chunk_writer->matched());
    }
    if (e.policy_writer) policy_matches = std::max(policy_matches, e.policy_writer->matched());
    if (Clock::now() >= next_result) {
      write_result();
      next_result += std::chrono::seconds(1);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  write_result();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Args args = parse_args(argc, argv);
    if (args.mode == "publish") return publish(args);
    if (args.mode == "receive") return receive(args);
    if (args.mode == "intrude") return intrude(args);
    throw std::invalid_argument("mode must be publish, receive or intrude, not " + args.mode);
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "peer") << error.what();
    return 2;
  }
}
