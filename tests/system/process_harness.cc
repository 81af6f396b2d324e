#include "process_harness.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace indrive::testing {
namespace fs = std::filesystem;

bool wait_until(std::chrono::milliseconds timeout, const std::function<bool()>& condition) {
  const auto end = SteadyClock::now() + timeout;
  while (!condition()) {
    if (SteadyClock::now() >= end) return condition();
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return true;
}

std::vector<nlohmann::json> read_metrics(const fs::path& path) {
  std::vector<nlohmann::json> records;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    auto record = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!record.is_discarded()) records.push_back(std::move(record));
  }
  return records;
}

bool keeps_ratio(const nlohmann::json& line, double ratio, double steps_per_update,
                 double lead_steps) {
  const double env_steps = line.value("env_steps", 0.0);
  const double updates = line.value("updates", 0.0);
  const double due = std::floor(ratio * env_steps / steps_per_update);
  const double due_behind = std::floor(ratio * (env_steps - lead_steps) / steps_per_update);
  return updates <= due && updates >= due_behind;
}

namespace {

// A file under /proc/<pid>/ of a process that may end while it is read: reading then fails
// with ESRCH, which std::ifstream reports by throwing from underflow (a chaos-soak run once
// failed so). A process gone mid-read is reported as an empty file, i.e. as gone.
std::string read_proc(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return {};
  std::string text;
  char buffer[4096];
  for (;;) {
    const ssize_t got = ::read(fd, buffer, sizeof buffer);
    if (got == 0) break;
    if (got < 0) {
      if (errno == EINTR) continue;
      text.clear();
      break;
    }
    text.append(buffer, static_cast<std::size_t>(got));
  }
  ::close(fd);
  return text;
}

}  // namespace

double cpu_seconds(pid_t pid) {
  // /proc/<pid>/stat: the command is in parentheses and may hold spaces; fields 14 and 15
  // (utime, stime) follow, in clock ticks.
  const std::string stat = read_proc("/proc/" + std::to_string(pid) + "/stat");
  const auto close = stat.rfind(')');
  if (close == std::string::npos) return -1.0;
  std::istringstream fields(stat.substr(close + 2));
  std::string field;
  long long utime = 0, stime = 0;
  for (int index = 3; fields >> field; ++index) {
    if (index == 14) utime = std::stoll(field);
    if (index == 15) {
      stime = std::stoll(field);
      break;
    }
  }
  return static_cast<double>(utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

std::vector<pid_t> child_pids(pid_t parent, const std::vector<std::string>& words) {
  std::vector<pid_t> found;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator("/proc", error)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || !std::all_of(name.begin(), name.end(), ::isdigit)) continue;
    const std::string stat = read_proc(entry.path() / "stat");
    const auto close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream fields(stat.substr(close + 2));
    std::string state;
    pid_t ppid = 0;
    fields >> state >> ppid;
    if (ppid != parent || state == "Z") continue;
    // Arguments are separated by NUL bytes.
    const std::string cmdline = read_proc(entry.path() / "cmdline");
    if (cmdline.empty()) continue;  // ended since it was listed
    std::vector<std::string> args;
    std::string arg;
    for (char c : cmdline) {
      if (c == '\0') {
        args.push_back(arg);
        arg.clear();
      } else {
        arg += c;
      }
    }
    // `words` must appear as consecutive arguments.
    bool all = words.empty();
    for (std::size_t a = 0; !all && a + words.size() <= args.size(); ++a) {
      all = std::equal(words.begin(), words.end(), args.begin() + static_cast<std::ptrdiff_t>(a));
    }
    if (all) found.push_back(static_cast<pid_t>(std::stoi(name)));
  }
  return found;
}

ProcessWatch::ProcessWatch(int domain_id, const fs::path& profiles_file)
    : ProcessWatch(dds::ParticipantOptions{.domain_id = domain_id,
                                           .profiles_file = profiles_file.string()}) {}

ProcessWatch::ProcessWatch(const dds::ParticipantOptions& options) : options_(options) { open(); }

void ProcessWatch::open() {
  participant_ = std::make_unique<dds::Participant>(options_);
  chunk_reader_ =
      participant_->make_reader<msg::TrajectoryChunk>([this](const msg::TrajectoryChunk& chunk) {
        if (chunk.actor_id() >= 100) return;  // a test's own injected chunks
        SeenChunk seen{.actor_id = chunk.actor_id(),
                       .chunk_seq = chunk.chunk_seq(),
                       .num_steps = chunk.num_steps(),
                       .policy_version = chunk.policy_version(),
                       .ends_episode = !chunk.flags().empty() &&
                                       (chunk.flags().back() & msg::STEP_IS_LAST) != 0,
                       .time_s = now_s()};
        std::lock_guard<std::mutex> lock(mutex_);
        chunks_.push_back(seen);
      });
  snapshot_reader_ =
      participant_->make_reader<msg::PolicySnapshot>([this](const msg::PolicySnapshot& snapshot) {
        SeenSnapshot seen{.version = snapshot.version(),
                          .updates = snapshot.updates(),
                          .bytes = snapshot.params().size(),
                          .checksum = snapshot.checksum(),
                          .time_s = now_s()};
        std::lock_guard<std::mutex> lock(mutex_);
        snapshots_.push_back(seen);
      });
  heartbeat_reader_ = participant_->make_reader<msg::Heartbeat>([this](const msg::Heartbeat& beat) {
    SeenHeartbeat seen{.state = beat.state(),
                       .env_steps = beat.env_steps(),
                       .updates = beat.updates(),
                       .policy_version = beat.policy_version(),
                       .dropped_messages = beat.dropped_messages(),
                       .time_s = now_s()};
    std::lock_guard<std::mutex> lock(mutex_);
    heartbeats_[{static_cast<std::uint32_t>(beat.role()), beat.id()}] = seen;
  });
  opened_s_ = now_s();  // when it is ready: making a participant takes a while
}

ProcessWatch::~ProcessWatch() { close(); }

void ProcessWatch::close() {
  chunk_writer_.reset();
  chunk_reader_.reset();
  snapshot_reader_.reset();
  heartbeat_reader_.reset();
  participant_.reset();
}

void ProcessWatch::replace(const std::string& why) {
  close();
  open();
  ++replacements_;
  replaced_why_ += (replaced_why_.empty() ? "" : "; ") + why;
  std::fprintf(stderr, "[watch] replaced its participant: %s\n", why.c_str());
}

bool ProcessWatch::replace_if_stalled() {
  if (participant_->peers().stalled == 0) return false;
  replace("a DDS Security handshake stalled");
  return true;
}

bool ProcessWatch::replace_if_unheard(
    const std::vector<std::pair<std::uint32_t, std::uint32_t>>& processes, double silent_s) {
  const double now = now_s();
  if (now - opened_s_ < silent_s) return false;
  std::string why;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& key : processes) {
      const auto it = heartbeats_.find(key);
      if (it != heartbeats_.end() && now - it->second.time_s > silent_s) {
        std::ostringstream text;
        text.precision(2);
        text << std::fixed << "role " << key.first << " id " << key.second << " unheard for "
             << now - it->second.time_s << " s at " << now << " s";
        why = text.str();
        break;
      }
    }
  }
  if (why.empty()) return false;
  replace(why);
  return true;
}

std::vector<SeenChunk> ProcessWatch::chunks() {
  std::lock_guard<std::mutex> lock(mutex_);
  return chunks_;
}

std::vector<SeenSnapshot> ProcessWatch::snapshots() {
  std::lock_guard<std::mutex> lock(mutex_);
  return snapshots_;
}

std::uint64_t ProcessWatch::newest_snapshot() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t newest = 0;
  for (const auto& s : snapshots_) newest = std::max(newest, s.version);
  return newest;
}

bool ProcessWatch::heartbeat(std::uint32_t role, std::uint32_t id, SeenHeartbeat& out) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = heartbeats_.find({role, id});
  if (it == heartbeats_.end()) return false;
  out = it->second;
  return true;
}

std::uint64_t ProcessWatch::min_newest_chunk_version(const std::vector<std::uint32_t>& actors) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t low = UINT64_MAX;
  for (std::uint32_t actor : actors) {
    std::uint64_t newest = 0;
    bool any = false;
    for (auto it = chunks_.rbegin(); it != chunks_.rend(); ++it) {
      if (it->actor_id == actor) {
        newest = it->policy_version;
        any = true;
        break;
      }
    }
    if (!any) return 0;
    low = std::min(low, newest);
  }
  return actors.empty() ? 0 : low;
}

std::string ProcessWatch::describe() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::ostringstream text;
  text.precision(2);
  text << std::fixed << "watch at " << now_s() << " s";
  if (replacements_ > 0) {
    text << " (participant replaced " << replacements_ << " times: " << replaced_why_ << ")";
  }
  text << ": ";
  if (snapshots_.empty()) {
    text << "no snapshot";
  } else {
    const auto newest = std::max_element(
        snapshots_.begin(), snapshots_.end(),
        [](const SeenSnapshot& a, const SeenSnapshot& b) { return a.version < b.version; });
    text << snapshots_.size() << " snapshots, newest v" << newest->version << " at "
         << newest->time_s << " s";
  }
  std::map<std::uint32_t, const SeenChunk*> newest_chunk;
  for (const auto& chunk : chunks_) newest_chunk[chunk.actor_id] = &chunk;
  for (const auto& [actor, chunk] : newest_chunk) {
    text << "; actor " << actor << " chunk #" << chunk->chunk_seq << " v" << chunk->policy_version
         << " at " << chunk->time_s << " s";
  }
  static const char* const kRoles[] = {"learner", "actor", "evaluator", "launcher"};
  for (const auto& [key, beat] : heartbeats_) {
    text << "; heartbeat " << (key.first < std::size(kRoles) ? kRoles[key.first] : "role?") << " "
         << key.second << " '" << beat.state << "' v" << beat.policy_version << " steps "
         << beat.env_steps << " updates " << beat.updates << " at " << beat.time_s << " s";
  }
  return text.str();
}

std::string tiny_service_config() {
  return R"(preset: tiny
run:
  seed: 3
env:
  densities: [0]
  time_limit_steps: 150
actor:
  chunk_length: 16
  request_after_s: 1
  heartbeat_s: 0.2
agent:
  replay:
    prefill: 128
    capacity: 20000
learner:
  replay_ratio: 4
  snapshot_every: 2
  log_interval_s: 1
  announce_s: 0.5
  allowance_slack: 16
  dashboard_s: 0
)";
}

std::vector<std::string> service_args(const std::string& program, const fs::path& config,
                                      const fs::path& run_dir, int domain_id,
                                      const fs::path& profiles_file,
                                      const std::vector<std::string>& overrides) {
  std::vector<std::string> args = {std::string(INDRIVE_BIN_DIR) + "/" + program,
                                   "--config",
                                   config.string(),
                                   "--run-dir",
                                   run_dir.string(),
                                   "--domain",
                                   std::to_string(domain_id),
                                   "--dds-profile",
                                   profiles_file.string()};
  for (const auto& text : overrides) args.insert(args.end(), {"--set", text});
  return args;
}

}  // namespace indrive::testing
