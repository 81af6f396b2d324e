#include "indrive/agent/replay.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "indrive/basics/check.h"
#include "indrive/basics/checksum.h"
#include "indrive/basics/run_dir.h"

namespace indrive::agent {
namespace {

constexpr char kMagic[4] = {'I', 'R', 'P', 'L'};
constexpr std::uint32_t kVersion = 1;

template <typename T>
void put(std::string& out, const T& value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

// Reads fixed-size values from a byte range, throwing ReplayError past the end.
class Reader {
 public:
  Reader(std::span<const std::uint8_t> data, std::size_t end, const std::string& file)
      : data_(data), end_(end), file_(file) {}
  template <typename T>
  T get() {
    T value;
    bytes(&value, sizeof(T));
    return value;
  }
  void bytes(void* out, std::size_t n) {
    // Compared as a remainder: a damaged size near 2^64 would wrap pos_ + n.
    if (n > end_ - pos_) throw ReplayError("replay file " + file_ + " is truncated");
    std::memcpy(out, data_.data() + pos_, n);
    pos_ += n;
  }
  std::size_t pos() const { return pos_; }
  std::size_t left() const { return end_ - pos_; }

 private:
  std::span<const std::uint8_t> data_;
  std::size_t end_;
  std::string file_;
  std::size_t pos_ = 0;
};

}  // namespace

ReplayBuffer::ReplayBuffer(ReplayOptions options) : options_(options), rng_(options.seed) {
  if (options_.capacity < 1 || options_.height < 1 || options_.width < 1 ||
      options_.num_classes < 1 || options_.num_classes > 256 || options_.num_actions < 1) {
    throw ReplayError(
        "replay options need capacity, height, width, num_actions >= 1 and "
        "num_classes in [1, 256]");
  }
}

void ReplayBuffer::add(int stream, const ReplayStep& step) {
  const std::size_t pixels = static_cast<std::size_t>(options_.height) * options_.width;
  if (step.frame.size() != pixels) {
    throw ReplayError("replay frame has " + std::to_string(step.frame.size()) +
                      " pixels, expected " + std::to_string(options_.height) + "x" +
                      std::to_string(options_.width) + "; check the preset's image size");
  }
  for (std::uint8_t id : step.frame) {
    if (id >= options_.num_classes) {
      throw ReplayError("replay frame holds class id " + std::to_string(id) +
                        " >= " + std::to_string(options_.num_classes) + " classes");
    }
  }
  if (step.action < 0 || step.action >= options_.num_actions) {
    throw ReplayError("replay action " + std::to_string(step.action) + " outside [0, " +
                      std::to_string(options_.num_actions) + ")");
  }
  if (!options_.has_rewards && step.reward != 0.0f) {
    // A reward reaching a reward-free buffer means task data leaked into pretraining.
    throw ReplayError(
        "a nonzero reward was added to a reward-free replay buffer (pretrain "
        "phase); the actor must not send rewards in this phase");
  }
  if (size_ == options_.capacity) evict_oldest();
  streams_[stream].push_back({step, total_added_});
  ++size_;
  ++total_added_;
}

void ReplayBuffer::evict_oldest() {
  auto oldest = streams_.end();
  for (auto it = streams_.begin(); it != streams_.end(); ++it) {
    if (it->second.empty()) continue;
    if (oldest == streams_.end() || it->second.front().order < oldest->second.front().order) {
      oldest = it;
    }
  }
  INDRIVE_CHECK(oldest != streams_.end()) << "evicting from an empty replay buffer";
  oldest->second.pop_front();
  if (oldest->second.empty()) streams_.erase(oldest);
  --size_;
}

std::int64_t ReplayBuffer::num_windows(int length) const {
  std::int64_t total = 0;
  for (const auto& [id, steps] : streams_) {
    total += std::max<std::int64_t>(0, static_cast<std::int64_t>(steps.size()) - length + 1);
  }
  return total;
}

SequenceBatch ReplayBuffer::sample(int batch, int length) {
  INDRIVE_CHECK(batch >= 1 && length >= 1) << "batch " << batch << " length " << length;
  const std::int64_t windows = num_windows(length);
  INDRIVE_CHECK(windows > 0) << "replay holds no window of " << length
                             << " steps; wait for prefill";
  SequenceBatch out;
  out.batch = batch, out.length = length;
  out.height = options_.height, out.width = options_.width;
  const std::size_t pixels = static_cast<std::size_t>(options_.height) * options_.width;
  const std::size_t n = static_cast<std::size_t>(batch) * length;
  out.frames.resize(n * pixels);
  out.actions.resize(n);
  out.is_first.resize(n);
  out.is_last.resize(n);
  out.is_terminal.resize(n);
  if (options_.has_rewards) out.rewards.resize(n);
  std::uniform_int_distribution<std::int64_t> pick(0, windows - 1);
  for (int b = 0; b < batch; ++b) {
    // Map a uniform window index to (stream, offset), so every window is equally likely.
    std::int64_t index = pick(rng_);
    const std::deque<Stored>* steps = nullptr;
    for (const auto& [id, s] : streams_) {
      const std::int64_t count =
          std::max<std::int64_t>(0, static_cast<std::int64_t>(s.size()) - length + 1);
      if (index < count) {
        steps = &s;
        break;
      }
      index -= count;
    }
    INDRIVE_CHECK(steps != nullptr) << "window index out of range";
    for (int t = 0; t < length; ++t) {
      const ReplayStep& step = (*steps)[index + t].step;
      const std::size_t i = static_cast<std::size_t>(b) * length + t;
      std::memcpy(out.frames.data() + i * pixels, step.frame.data(), pixels);
      out.actions[i] = step.action;
      out.is_first[i] = (t == 0 || step.is_first) ? 1.0f : 0.0f;
      out.is_last[i] = step.is_last ? 1.0f : 0.0f;
      out.is_terminal[i] = step.is_terminal ? 1.0f : 0.0f;
      if (options_.has_rewards) out.rewards[i] = step.reward;
    }
  }
  return out;
}

std::vector<std::uint8_t> ReplayBuffer::to_bytes() const {
  std::string out;
  out.append(kMagic, 4);
  put(out, kVersion);
  put(out, static_cast<std::int32_t>(options_.height));
  put(out, static_cast<std::int32_t>(options_.width));
  put(out, static_cast<std::uint8_t>(options_.has_rewards));
  put(out, total_added_);
  std::ostringstream rng_text;
  rng_text << rng_;
  const std::string rng_state = rng_text.str();
  put(out, static_cast<std::uint64_t>(rng_state.size()));
  out += rng_state;
  put(out, static_cast<std::uint64_t>(streams_.size()));
  for (const auto& [id, steps] : streams_) {
    put(out, static_cast<std::int32_t>(id));
    put(out, static_cast<std::uint64_t>(steps.size()));
    for (const Stored& s : steps) {
      put(out, s.order);
      put(out, static_cast<std::int32_t>(s.step.action));
      const std::uint8_t flags =
          (s.step.is_first ? 1 : 0) | (s.step.is_last ? 2 : 0) | (s.step.is_terminal ? 4 : 0);
      put(out, flags);
      put(out, s.step.reward);
      out.append(reinterpret_cast<const char*>(s.step.frame.data()), s.step.frame.size());
    }
  }
  put(out, indrive::crc32(reinterpret_cast<const std::uint8_t*>(out.data()), out.size()));
  return {out.begin(), out.end()};
}

void ReplayBuffer::save(const std::filesystem::path& path) const {
  try {
    atomic_write(path, to_bytes());
  } catch (const IoError& error) {
    throw ReplayError(std::string("cannot write replay file: ") + error.what());
  }
}

void ReplayBuffer::load(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw ReplayError("cannot open replay file " + path.string());
  const std::vector<std::uint8_t> data((std::istreambuf_iterator<char>(file)),
                                       std::istreambuf_iterator<char>());
  load(data, path.string());
}

void ReplayBuffer::load(std::span<const std::uint8_t> data, const std::string& name) {
  if (data.size() < 8 || std::memcmp(data.data(), kMagic, 4) != 0) {
    throw ReplayError("file " + name + " is not a replay file");
  }
  std::uint32_t stored_crc;
  std::memcpy(&stored_crc, data.data() + data.size() - 4, 4);
  if (indrive::crc32(data.data(), data.size() - 4) != stored_crc) {
    throw ReplayError("replay file " + name + " is corrupt (checksum mismatch)");
  }
  Reader in(data, data.size() - 4, name);
  char magic[4];
  in.bytes(magic, 4);
  if (in.get<std::uint32_t>() != kVersion)
    throw ReplayError("replay file " + name + " has another version");
  const int height = in.get<std::int32_t>(), width = in.get<std::int32_t>();
  const bool has_rewards = in.get<std::uint8_t>() != 0;
  if (height != options_.height || width != options_.width || has_rewards != options_.has_rewards) {
    throw ReplayError(
        "replay file " + name + " holds " + std::to_string(height) + "x" + std::to_string(width) +
        " frames" + (has_rewards ? " with" : " without") + " rewards; this buffer expects " +
        std::to_string(options_.height) + "x" + std::to_string(options_.width) +
        (options_.has_rewards ? " with" : " without") + " rewards (another preset or phase?)");
  }
  const std::int64_t total_added = in.get<std::int64_t>();
  // A size the data cannot hold is refused before it is allocated.
  const std::uint64_t rng_size = in.get<std::uint64_t>();
  if (rng_size > in.left()) throw ReplayError("replay file " + name + " is truncated");
  std::string rng_state(rng_size, '\0');
  in.bytes(rng_state.data(), rng_state.size());
  std::map<int, std::deque<Stored>> streams;
  std::int64_t size = 0;
  const std::uint64_t num_streams = in.get<std::uint64_t>();
  const std::size_t pixels = static_cast<std::size_t>(height) * width;
  for (std::uint64_t s = 0; s < num_streams; ++s) {
    const int id = in.get<std::int32_t>();
    const std::uint64_t count = in.get<std::uint64_t>();
    std::deque<Stored>& steps = streams[id];
    for (std::uint64_t i = 0; i < count; ++i) {
      Stored stored;
      stored.order = in.get<std::int64_t>();
      stored.step.action = in.get<std::int32_t>();
      const std::uint8_t flags = in.get<std::uint8_t>();
      stored.step.is_first = flags & 1, stored.step.is_last = flags & 2,
      stored.step.is_terminal = flags & 4;
      stored.step.reward = in.get<float>();
      if (in.left() < pixels) throw ReplayError("replay file " + name + " is truncated");
      stored.step.frame.resize(pixels);
      in.bytes(stored.step.frame.data(), pixels);
      // What add() refuses may not enter by a file either: the sampler trusts these ranges.
      if (stored.step.action < 0 || stored.step.action >= options_.num_actions ||
          std::any_of(stored.step.frame.begin(), stored.step.frame.end(),
                      [&](std::uint8_t id) { return id >= options_.num_classes; })) {
        throw ReplayError("replay file " + name + " holds an action or class id out of range");
      }
      steps.push_back(std::move(stored));
      ++size;
    }
  }
  if (size > options_.capacity) {
    throw ReplayError("replay file " + name + " holds " + std::to_string(size) +
                      " steps, more than the capacity " + std::to_string(options_.capacity));
  }
  std::istringstream rng_text(rng_state);
  std::mt19937_64 rng;
  rng_text >> rng;
  if (!rng_text) throw ReplayError("replay file " + name + " has an unreadable RNG state");
  // Commit only after everything parsed, so a failed load leaves the buffer unchanged.
  streams_ = std::move(streams);
  size_ = size;
  total_added_ = total_added;
  rng_ = rng;
}

}  // namespace indrive::agent
