// The service across two hosts: two network namespaces joined by a veth pair on one machine
// (tests/support/netns.h), learner and actors on host A, a remote evaluator (and in the link
// test a remote actor) on host B. Only the namespaces' own addresses exist, so everything that
// crosses between A and B goes over the link: multicast discovery over the UDP profile, the
// discovery server over its profile with multicast off, and a cut of the link mid-run. Needs
// root (CI runs as root); elsewhere the tests skip and say why. Each test prints its figures.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <thread>

#include "indrive/dds/participant.h"
#include "netns.h"
#include "process_harness.h"
#include "testing.h"

namespace indrive {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using testing::Child;
using testing::HostPair;
using testing::ProcessWatch;
using testing::SeenHeartbeat;
using testing::wait_until;

// The line Fast DDS logs when fragments of a sample come from a writer it has not matched.
const std::regex kUnknownWriterFragments(
    R"( W \[fastdds\] \[RTPS_MSG_IN\].*DATA_FRAG from unknown writer)");

class TwoHosts : public ::testing::Test {
 protected:
  void make_hosts(bool multicast) {
    std::string why;
    hosts_ = HostPair::make({.multicast = multicast}, why);
    if (!hosts_) GTEST_SKIP() << why;
    domain_ = testing::unique_domain_id();
    run_dir_ = dir_.path() / "runs" / "twohost";
    config_ = dir_.path() / "twohost.yaml";
    std::ofstream(config_) << testing::tiny_service_config();
    hosts_->enter_a();  // the watch of each test is a participant on host A
  }
  void TearDown() override {
    children_.clear();  // SIGKILLs what a failed test left running, before the hosts go
    ::unsetenv(dds::kDiscoveryServerEnvVar);
  }

  std::vector<std::string> args(const std::string& program,
                                std::vector<std::string> overrides = {}) const {
    auto argv = testing::service_args(program, config_, run_dir_, domain_, profile_, overrides);
    if (!discovery_server_.empty())
      argv.insert(argv.end(), {"--discovery-server", discovery_server_});
    if (!security_.empty()) argv.insert(argv.end(), {"--dds-security", security_.string()});
    return argv;
  }
  Child& start(const std::vector<std::string>& argv, const std::string& name) {
    children_.push_back(std::make_unique<Child>(argv, dir_.path() / (name + ".log")));
    return *children_.back();
  }
  Child& learner() {
    return start(hosts_->on_a(args("indrive-learner", learner_overrides_)), "learner");
  }
  Child& actor(int id, bool remote) {
    auto argv = args("indrive-actor");
    argv.insert(argv.end(), {"--id", std::to_string(id)});
    return start(remote ? hosts_->on_b(argv) : hosts_->on_a(argv),
                 "actor-" + std::to_string(id) + (remote ? "-on-b" : ""));
  }
  Child& evaluator(const std::vector<std::string>& overrides) {
    auto argv = args("indrive-actor", overrides);
    argv.insert(argv.end(), {"--evaluate", "--id", "0"});
    return start(hosts_->on_b(argv), "evaluator-on-b");
  }

  // Each log's DDS lines and its other warnings and errors (up to 40 each), then its last 3,000
  // characters: a failure here is usually decided in the first seconds of discovery, long
  // scrolled away.
  std::string logs() const {
    std::string text;
    const std::regex notable(R"( (W|E) \[|\[dds\])");
    for (const auto& entry : fs::directory_iterator(dir_.path())) {
      if (entry.path().extension() != ".log") continue;
      const std::string body = testing::slurp(entry.path());
      text += "----- " + entry.path().filename().string() + "\n";
      std::istringstream lines(body);
      int dds = 0, other = 0;
      for (std::string line; std::getline(lines, line);) {
        if (!std::regex_search(line, notable)) continue;
        // DDS lines first in rank: a learner's warnings about dropped chunks fill any cap.
        int& kept = line.find("[dds]") != std::string::npos ? dds : other;
        if (kept < 40) text += line + "\n", ++kept;
      }
      text += body.size() > 3000 ? "... (last 3000 characters)\n" + body.substr(body.size() - 3000)
                                 : "... (all of it)\n" + body;
    }
    return text;
  }
  // Lines of every log that match `pattern`.
  int count_lines(const std::regex& pattern) const {
    int count = 0;
    for (const auto& entry : fs::directory_iterator(dir_.path())) {
      if (entry.path().extension() != ".log") continue;
      std::ifstream in(entry.path());
      for (std::string line; std::getline(in, line);) count += std::regex_search(line, pattern);
    }
    return count;
  }
  // The newest version in an evaluator log's "evaluates snapshot vN" lines (0: none yet), and
  // how many such lines it has.
  std::pair<std::uint64_t, int> evaluated(const std::string& name) const {
    const std::string text = testing::slurp(dir_.path() / (name + ".log"));
    std::uint64_t newest = 0;
    int count = 0;
    const std::regex line("evaluates snapshot v([0-9]+)");
    for (auto it = std::sregex_iterator(text.begin(), text.end(), line);
         it != std::sregex_iterator(); ++it) {
      newest = std::max<std::uint64_t>(newest, std::stoull((*it)[1]));
      ++count;
    }
    return {newest, count};
  }
  // The first number after `pattern` (a regex with one group) in a log, or -1.
  long long logged(const std::string& name, const std::string& pattern) const {
    const std::string text = testing::slurp(dir_.path() / (name + ".log"));
    std::smatch match;
    return std::regex_search(text, match, std::regex(pattern)) ? std::stoll(match[1]) : -1;
  }
  // The "key value" lines a dds_peer writes to its --result file.
  static std::map<std::string, double> figures(const fs::path& path) {
    std::map<std::string, double> values;
    std::ifstream in(path);
    std::string key;
    double value = 0;
    while (in >> key >> value) values[key] = value;
    return values;
  }
  std::vector<std::string> peer(const std::string& mode, const std::vector<std::string>& flags,
                                const std::string& role = "") const {
    std::vector<std::string> argv = {INDRIVE_DDS_PEER,  mode,       "--profiles",
                                     profile_.string(), "--domain", std::to_string(domain_)};
    argv.insert(argv.end(), flags.begin(), flags.end());
    if (!role.empty()) argv.insert(argv.end(), {"--security", security_.string(), "--role", role});
    return argv;
  }

  std::vector<nlohmann::json> metrics() const {
    return testing::read_metrics(run_dir_ / "metrics.jsonl");
  }
  // The newest snapshot version an evaluator's result for town01 put on a learner metrics line
  // (0: none yet).
  std::uint64_t newest_logged_evaluation() const {
    std::uint64_t newest = 0;
    for (const auto& line : metrics()) {
      if (line.contains("eval_policy_version") && line.contains("eval_town01_success_rate")) {
        newest = std::max(newest, line["eval_policy_version"].get<std::uint64_t>());
      }
    }
    return newest;
  }

  // Learner and two actors on A, an evaluator joining late on B: it must get a snapshot at
  // least as new as the newest one published when it started. Returns the seconds it took.
  void late_evaluator_gets_the_newest_snapshot(const std::string& label) {
    ProcessWatch watch(domain_, profile_);
    std::vector<Child*> service = {&learner(), &actor(0, false), &actor(1, false)};
    ASSERT_TRUE(wait_until(120s, [&] {
      return watch.min_newest_chunk_version({0, 1}) >= 2 && watch.newest_snapshot() >= 4;
    })) << logs();
    const std::uint64_t newest_at_join = watch.newest_snapshot();
    const auto joined = testing::SteadyClock::now();
    Child& remote = evaluator({"eval.wait_for_done=false", "eval.towns=town01"});
    ASSERT_TRUE(wait_until(90s, [&] { return evaluated("evaluator-on-b").first > 0; })) << logs();
    const double after_s = testing::seconds_since(joined);
    EXPECT_GE(evaluated("evaluator-on-b").first, newest_at_join) << logs();
    // Fast DDS's warning for fragments that reach a reader they are not meant for is harmless
    // and hidden (common/dds/src/participant.cc, SinkConsumer); it once flooded every log.
    EXPECT_EQ(count_lines(kUnknownWriterFragments), 0) << logs();
    std::printf(
        "[figures] %s: evaluator on host %s had snapshot v%llu (newest at its start v%llu) "
        "%.2f s after its process started on the other host; %d 'DATA_FRAG from unknown "
        "writer' lines in all logs\n",
        label.c_str(), hosts_->address_b().c_str(),
        static_cast<unsigned long long>(evaluated("evaluator-on-b").first),
        static_cast<unsigned long long>(newest_at_join), after_s,
        count_lines(kUnknownWriterFragments));
    remote.signal(SIGTERM);
    EXPECT_EQ(remote.wait(30s), 0) << logs();
    for (Child* child : service) child->signal(SIGTERM);
    for (Child* child : service) EXPECT_EQ(child->wait(60s), 0) << logs();
  }

  std::unique_ptr<HostPair> hosts_;
  testing::TempDir dir_{"indrive-twohost"};
  int domain_ = 0;
  fs::path run_dir_;
  fs::path config_;
  fs::path profile_ = testing::source_path("deploy/dds/default.xml");
  std::string discovery_server_;
  fs::path security_;  // a make_security.sh folder every service process uses, when set
  std::vector<std::string> learner_overrides_;
  std::vector<std::unique_ptr<Child>> children_;
};

TEST_F(TwoHosts, ALateEvaluatorOnTheOtherHostGetsTheNewestSnapshotOverUdp) {
  make_hosts(/*multicast=*/true);
  if (IsSkipped()) return;
  late_evaluator_gets_the_newest_snapshot("UDP, multicast discovery");
}

// A link slower than the learner publishes: shaped to 16 Mbit/s, with the snapshot writer's
// throughput limit set below that (dds.snapshot_rate_mb_s=1.6, docs/operations.md), one tiny
// snapshot takes over a second to cross while the learner makes one every 2 updates here. Were
// each new snapshot written at once, it would replace the last in the writer's history under the
// evaluator still fetching it, and the evaluator would never hold a whole one: the learner holds
// a due snapshot until every reader has the last (learner.snapshot_hold_s).
TEST_F(TwoHosts, ALateEvaluatorBehindASlowLinkStillGetsASnapshot) {
  make_hosts(/*multicast=*/true);
  if (IsSkipped()) return;
  const char* rate = std::getenv("INDRIVE_LINK_RATE");  // for experiments; 16mbit by default
  std::string why;
  if (!hosts_->limit_rate_a_to_b(rate != nullptr ? rate : "16mbit", why)) GTEST_SKIP() << why;
  if (const char* hold = std::getenv("INDRIVE_SNAPSHOT_HOLD_S"))  // for experiments
    learner_overrides_.push_back(std::string("learner.snapshot_hold_s=") + hold);
  // The snapshot writer below the link's 2 MB/s; the profile's 100 MB/s would overflow the
  // link's queue (tested: no snapshot in 90 s at 16-40 Mbit/s).
  const char* limit = std::getenv("INDRIVE_SNAPSHOT_RATE_MB_S");  // for experiments
  learner_overrides_.push_back(std::string("dds.snapshot_rate_mb_s=") +
                               (limit != nullptr ? limit : "1.6"));
  late_evaluator_gets_the_newest_snapshot(std::string("link shaped to ") +
                                          (rate != nullptr ? rate : "16mbit"));
  const auto lines = metrics();
  ASSERT_FALSE(lines.empty());
  const auto& last = lines.back();
  // The learner held snapshots for the evaluator, and went on publishing to the actors on A.
  EXPECT_GT(last.value("snapshots_held", 0), 0) << last.dump();
  EXPECT_GT(last.value("snapshots_published", 0), 4) << last.dump();
  std::printf(
      "[figures] slow link: %lld snapshots published, %lld held for a reader, %lld "
      "written after the hold ran out, %lld updates\n",
      static_cast<long long>(last.value("snapshots_published", 0)),
      static_cast<long long>(last.value("snapshots_held", 0)),
      static_cast<long long>(last.value("snapshot_holds_expired", 0)),
      static_cast<long long>(last.value("updates", 0)));
}

// Multicast is routed nowhere here, so only the discovery server (on A, at A's address, given
// to every process with --discovery-server and to the watch by $INDRIVE_DISCOVERY_SERVER) can
// make the processes find each other.
TEST_F(TwoHosts, ALateEvaluatorOnTheOtherHostGetsTheNewestSnapshotThroughADiscoveryServer) {
  make_hosts(/*multicast=*/false);
  if (IsSkipped()) return;
  profile_ = testing::source_path("deploy/dds/discovery_server.xml");
  const std::string port = std::to_string(11811 + domain_);
  discovery_server_ = hosts_->address_a() + ":" + port;
  ::setenv(dds::kDiscoveryServerEnvVar, discovery_server_.c_str(), 1);
  start(hosts_->on_a(
            {INDRIVE_DISCOVERY_SERVER_PROGRAM, "-i", "0", "-l", hosts_->address_a(), "-p", port}),
        "discovery-server");
  late_evaluator_gets_the_newest_snapshot("discovery server " + discovery_server_ +
                                          ", no multicast");
}

// A remote actor and a continuous evaluator on B; the link is down for 20 s while training goes
// on at A. Both keep their snapshot and carry on; nothing damaged or partial reaches replay;
// after the link returns the evaluator evaluates a snapshot newer than any it had.
TEST_F(TwoHosts, TwentySecondsWithoutTheLinkAreSurvived) {
  make_hosts(/*multicast=*/true);
  if (IsSkipped()) return;
  ProcessWatch watch(domain_, profile_);
  learner();
  actor(0, false);
  Child& remote_actor = actor(1, true);
  Child& remote_evaluator =
      evaluator({"eval.wait_for_done=false", "eval.continuous=true", "eval.towns=town01",
                 "eval.routes=straight", "eval.densities=5", "eval.episodes_per_cell=1"});
  ASSERT_TRUE(wait_until(150s, [&] {
    return watch.min_newest_chunk_version({0, 1}) >= 2 && evaluated("evaluator-on-b").first >= 2;
  })) << logs();

  const std::uint64_t evaluated_before = evaluated("evaluator-on-b").first;
  hosts_->cut_link();
  const double cut_at = watch.now_s();
  const char* cut_s = std::getenv("INDRIVE_LINK_CUT_S");  // for experiments; 20 s by default
  std::this_thread::sleep_for(
      std::chrono::duration<double>(cut_s != nullptr ? std::atof(cut_s) : 20.0));
  const std::uint64_t published_during_cut = watch.newest_snapshot();
  EXPECT_TRUE(remote_actor.running()) << logs();
  EXPECT_TRUE(remote_evaluator.running()) << logs();
  hosts_->restore_link();
  const double restored_at = watch.now_s();

  // The remote actor's heartbeat comes back, with a policy newer than any before the cut ...
  SeenHeartbeat beat;
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.heartbeat(msg::ROLE_ACTOR, 1, beat) && beat.time_s > restored_at;
  })) << logs();
  const double heard_again_s = beat.time_s - restored_at;
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.heartbeat(msg::ROLE_ACTOR, 1, beat) && beat.time_s > restored_at &&
           beat.policy_version >= published_during_cut;
  })) << logs();
  const double actor_back_s = beat.time_s - restored_at;
  // ... and the evaluator evaluates one it could not have had before the link returned.
  ASSERT_TRUE(wait_until(120s, [&] {
    return evaluated("evaluator-on-b").first >= published_during_cut;
  })) << logs();
  const double evaluator_back_s = watch.now_s() - restored_at;
  // Its result for that version crosses the link to the learner's metrics.
  ASSERT_TRUE(wait_until(90s, [&] { return newest_logged_evaluation() >= published_during_cut; }))
      << logs();
  const double result_logged_s = watch.now_s() - restored_at;

  for (auto& child : children_) child->signal(SIGTERM);
  for (auto& child : children_) EXPECT_EQ(child->wait(60s), 0) << logs();
  const auto lines = metrics();
  ASSERT_FALSE(lines.empty());
  const auto& last = lines.back();
  // Every chunk the learner took is whole and checked; none came damaged or twice.
  EXPECT_EQ(last.value("dropped_bad_checksum", -1), 0) << last.dump();
  EXPECT_EQ(last.value("dropped_bad_shape", -1), 0) << last.dump();
  EXPECT_EQ(last.value("dropped_duplicate", -1), 0) << last.dump();
  EXPECT_EQ(last.value("dropped_undecodable", -1), 0) << last.dump();
  // And none was lost: the remote actor's reliable writer held what it wrote while the link was
  // down and delivered it after (a replaced participant would have lost them).
  EXPECT_EQ(last.value("sequence_gaps", -1), 0) << last.dump();
  EXPECT_EQ(count_lines(kUnknownWriterFragments), 0) << logs();
  // The remote evaluator's results are on the learner's metrics lines, with its town.
  EXPECT_GE(last.value("eval_results", 0), 2) << last.dump();
  std::printf(
      "[figures] link down %.1f s (from %.1f s): remote actor heard again %.2f s after the link "
      "returned, with snapshot v%llu after %.2f s; evaluator evaluated v%llu (v%llu before the "
      "cut) "
      "%.2f s after, its result in the learner's metrics %.2f s after; learner: %lld chunks, "
      "%lld sequence gaps (chunks lost), %lld dropped; "
      "%d 'DATA_FRAG from unknown writer' lines\n",
      restored_at - cut_at, cut_at, heard_again_s,
      static_cast<unsigned long long>(beat.policy_version), actor_back_s,
      static_cast<unsigned long long>(evaluated("evaluator-on-b").first),
      static_cast<unsigned long long>(evaluated_before), evaluator_back_s, result_logged_s,
      static_cast<long long>(last.value("chunks", 0)),
      static_cast<long long>(last.value("sequence_gaps", 0)),
      static_cast<long long>(last.value("dropped_chunks", 0)),
      count_lines(kUnknownWriterFragments));
}

// DDS Security across the link: the service on A and every participant on B hold certificates
// of one run's folder (deploy/dds/make_security.sh), except an outsider without any. The
// outsider reads no sample of any topic and none of its chunks reaches replay; a participant
// with an actor's certificate cannot publish a snapshot; an evaluator's certificate gets the
// newest snapshot, joining late.
TEST_F(TwoHosts, SecurityLetsTheRolesInAndKeepsOutsidersOut) {
  make_hosts(/*multicast=*/true);
  if (IsSkipped()) return;
  security_ = dir_.path() / "security";
  testing::make_security_folder(security_);
  const std::string run_id = "twohost";  // the run directory's name is the run id
  ProcessWatch watch(dds::ParticipantOptions{.domain_id = domain_,
                                             .profiles_file = profile_.string(),
                                             .security_dir = security_.string(),
                                             .security_role = "observer"});
  std::vector<Child*> service = {&learner(), &actor(0, false), &actor(1, false)};
  // The observer replaces its participant if one of its own handshakes stalls (process_harness.h).
  ASSERT_TRUE(wait_until(
      150s,
      [&] {
        watch.replace_if_stalled();
        return watch.min_newest_chunk_version({0, 1}) >= 2 && watch.newest_snapshot() >= 4;
      }))
      << watch.replacements() << " observer participants replaced\n"
      << logs();

  // On B: an outsider with no certificate (chunks as actor 7), and a participant with an actor's
  // certificate (chunks as actor 8) that also tries to publish a snapshot; both would publish
  // snapshot version 1000. Their chunks are synthetic (16 steps of 32x32 frames) with the run's
  // id: what reaches the learner is dropped as bad_shape, named in its log.
  const fs::path outsider_result = dir_.path() / "outsider.txt";
  const fs::path actor_result = dir_.path() / "actor-certificate.txt";
  // The peers run until the certified one has been matched both ways, by the learner (its log
  // names actor 8's dropped chunks), by the observer (it saw actor 8's chunks) and as a reader
  // of snapshots, then the test stops them. A fixed window failed twice in CI: the secure
  // handshakes of six participants across the link took more than 20 s once and more than
  // 40 s (for the learner and the certified peer) once on a loaded machine.
  const std::vector<std::string> flags = {"--run-id", run_id, "--timeout", "240"};
  auto outsider_flags = flags, actor_flags = flags;
  outsider_flags.insert(outsider_flags.end(),
                        {"--result", outsider_result.string(), "--actor-id", "7"});
  actor_flags.insert(actor_flags.end(), {"--result", actor_result.string(), "--actor-id", "8"});
  Child& outsider = start(hosts_->on_b(peer("intrude", outsider_flags)), "outsider-on-b");
  Child& actor_certificate =
      start(hosts_->on_b(peer("intrude", actor_flags, "actor")), "actor-certificate-on-b");

  const std::uint64_t newest_at_join = watch.newest_snapshot();
  const auto joined = testing::SteadyClock::now();
  Child& remote = evaluator({"eval.wait_for_done=false", "eval.towns=town01"});
  ASSERT_TRUE(wait_until(120s, [&] { return evaluated("evaluator-on-b").first > 0; })) << logs();
  const double evaluator_s = testing::seconds_since(joined);
  EXPECT_GE(evaluated("evaluator-on-b").first, newest_at_join) << logs();

  const auto chunks_seen_of = [&](std::uint32_t actor_id) {
    int count = 0;
    for (const auto& chunk : watch.chunks()) count += chunk.actor_id == actor_id;
    return count;
  };
  const fs::path learner_log_path = dir_.path() / "learner.log";
  ASSERT_TRUE(wait_until(180s,
                         [&] {
                           watch.replace_if_stalled();
                           return figures(actor_result)["read_policy"] > 0 &&
                                  chunks_seen_of(8) > 0 &&
                                  testing::slurp(learner_log_path).find("of actor 8 ") !=
                                      std::string::npos;
                         }))
      << "the certified peer was not matched by the learner, the observer and a snapshot "
         "writer within 180 s: snapshots read "
      << figures(actor_result)["read_policy"] << ", chunks the observer saw " << chunks_seen_of(8)
      << ", learner log names actor 8: "
      << (testing::slurp(learner_log_path).find("of actor 8 ") != std::string::npos)
      << "; the certified peer authenticated "
      << figures(actor_result)["participants_authenticated"] << " participants, "
      << figures(actor_result)["handshakes_pending"] << " pending, "
      << figures(actor_result)["rejoins"] << " participant replacements; " << watch.replacements()
      << " observer participants replaced\n"
      << logs();
  const double certified_matched_s = testing::seconds_since(joined);
  // Both run as long, at least 10 s: what the outsider did not get, it would have got by then.
  if (certified_matched_s < 10.0) {
    std::this_thread::sleep_for(std::chrono::duration<double>(10.0 - certified_matched_s));
  }
  outsider.signal(SIGTERM);
  actor_certificate.signal(SIGTERM);
  EXPECT_EQ(outsider.wait(60s), 0) << logs();
  EXPECT_EQ(actor_certificate.wait(60s), 0) << logs();
  auto outsider_saw = figures(outsider_result);
  auto actor_saw = figures(actor_result);
  for (const char* topic :
       {"read_trajectory", "read_policy", "read_policy_announce", "read_snapshot_request",
        "read_allowance", "read_episode_result", "read_heartbeat"}) {
    EXPECT_EQ(outsider_saw[topic], 0) << topic;
  }
  EXPECT_GT(outsider_saw["chunks_written"], 0);  // it did try
  EXPECT_EQ(outsider_saw["trajectory_readers_matched"], 0);
  EXPECT_EQ(outsider_saw["policy_readers_matched"], 0);
  // The actor's permissions let it write chunks but not snapshots: the local access control
  // refuses the policy writer.
  EXPECT_EQ(actor_saw["policy_writer_refused"], 1);
  EXPECT_EQ(actor_saw["trajectory_writer_refused"], 0);
  EXPECT_GT(actor_saw["read_policy"], 0);  // an actor reads snapshots
  // No snapshot of the intruders' version reached anyone. The secure observer saw chunks of the
  // actor certificate (8), so it would have seen the outsider's (7) had they crossed.
  EXPECT_LT(watch.newest_snapshot(), 1000u);
  const int outsider_chunks = chunks_seen_of(7), certified_chunks = chunks_seen_of(8);
  EXPECT_EQ(outsider_chunks, 0);
  EXPECT_GT(certified_chunks, 0);

  remote.signal(SIGTERM);
  EXPECT_EQ(remote.wait(30s), 0) << logs();
  for (Child* child : service) child->signal(SIGTERM);
  for (Child* child : service) EXPECT_EQ(child->wait(60s), 0) << logs();
  const auto lines = metrics();
  ASSERT_FALSE(lines.empty());
  // Replay holds the two actors' chunks and nothing else. The learner heard the certified
  // peer's chunks (and dropped them for their shape), never the outsider's.
  EXPECT_EQ(lines.back().value("replay_actors", -1), 2) << lines.back().dump();
  const std::string learner_log = testing::slurp(learner_log_path);
  EXPECT_EQ(learner_log.find("of actor 7 "), std::string::npos) << logs();
  EXPECT_NE(learner_log.find("of actor 8 "), std::string::npos) << logs();
  EXPECT_EQ(lines.back().value("dropped_chunks", -1), lines.back().value("dropped_bad_shape", -2));
  std::printf(
      "[figures] DDS Security across the link: evaluator on B had snapshot v%llu (newest at its "
      "start v%llu) %.2f s after it started; outsider without certificate: %.0f chunks written, "
      "%.0f samples read of 7 topics, %.0f readers matched; actor certificate: policy writer "
      "refused %.0f, %.0f snapshots read, %d chunks seen by the observer, matched by all %.1f s "
      "after it started (%.0f participant replacements after a stalled handshake); learner: "
      "%lld chunks from %lld actors in replay, %lld dropped; participants the service replaced "
      "before hearing its learner: %d\n",
      static_cast<unsigned long long>(evaluated("evaluator-on-b").first),
      static_cast<unsigned long long>(newest_at_join), evaluator_s, outsider_saw["chunks_written"],
      outsider_saw["read_trajectory"] + outsider_saw["read_policy"] +
          outsider_saw["read_policy_announce"] + outsider_saw["read_snapshot_request"] +
          outsider_saw["read_allowance"] + outsider_saw["read_episode_result"] +
          outsider_saw["read_heartbeat"],
      outsider_saw["trajectory_readers_matched"] + outsider_saw["policy_readers_matched"],
      actor_saw["policy_writer_refused"], actor_saw["read_policy"], certified_chunks,
      certified_matched_s, actor_saw["rejoins"],
      static_cast<long long>(lines.back().value("chunks", 0)),
      static_cast<long long>(lines.back().value("replay_actors", 0)),
      static_cast<long long>(lines.back().value("dropped_chunks", 0)),
      count_lines(std::regex("recreating its DDS participant")));
}

// What DDS Security costs across the link: a publisher on A writes a 10 MB snapshot, then 1,000
// chunks once a receiver on B joins late; the same transfer runs without and with security
// (the publisher as a learner allowed to write chunks too, the receiver as an observer). Both
// must deliver everything; the figures are printed, not asserted (speed is a benchmark's job).
TEST_F(TwoHosts, WhatSecurityCostsAcrossTheLink) {
  make_hosts(/*multicast=*/true);
  if (IsSkipped()) return;
  const fs::path folder = dir_.path() / "security";
  testing::make_security_folder(folder);
  testing::allow_publishing(folder, "learner", "indrive/trajectory");
  std::map<std::string, std::map<std::string, double>> sent, received;
  for (const bool secure : {false, true}) {
    const std::string label = secure ? "secure" : "plain";
    security_ = secure ? folder : fs::path();
    const fs::path ready = dir_.path() / (label + "-ready");
    const fs::path sent_file = dir_.path() / (label + "-sent.txt");
    const fs::path received_file = dir_.path() / (label + "-received.txt");
    const std::string run_id = "cost-" + label;
    Child& publisher = start(hosts_->on_a(peer("publish",
                                               {"--run-id", run_id, "--ready", ready.string(),
                                                "--result", sent_file.string(), "--timeout", "60"},
                                               secure ? "learner" : "")),
                             label + "-publisher-on-a");
    ASSERT_TRUE(wait_until(30s, [&] { return fs::exists(ready); })) << logs();
    Child& receiver = start(
        hosts_->on_b(peer(
            "receive", {"--run-id", run_id, "--result", received_file.string(), "--timeout", "60"},
            secure ? "observer" : "")),
        label + "-receiver-on-b");
    EXPECT_EQ(receiver.wait(90s), 0) << logs();
    EXPECT_EQ(publisher.wait(30s), 0) << logs();
    sent[label] = figures(sent_file);
    received[label] = figures(received_file);
    EXPECT_EQ(received[label]["snapshot_ok"], 1) << label;
    EXPECT_EQ(received[label]["chunks_ok"], 1000) << label;
    EXPECT_EQ(sent[label]["acked"], 1) << label;
  }
  for (const char* label : {"plain", "secure"}) {
    auto& in = received[label];
    auto& out = sent[label];
    std::printf(
        "[figures] across the link, %s: 10 MB snapshot at the late receiver %.2f s after its "
        "start (participant %.2f s); %.1f MB of chunks received in %.2f s = %.0f MB/s; "
        "publisher sent and acknowledged at %.0f MB/s\n",
        label, in["snapshot_s"], in["participant_s"], out["wire_mb"], in["chunk_s"],
        out["wire_mb"] / std::max(in["chunk_s"], 1e-9), out["wire_mb_per_s"]);
  }
}

}  // namespace
}  // namespace indrive
