// Replay buffer of sequences: class-id frames (1 byte per pixel), actions and episode flags,
// with the extrinsic reward only when the buffer is made for a task phase.
//
// Steps arrive per stream (one stream per actor) and stay in arrival order within a stream;
// a sampled window is `length` consecutive steps of one stream. Windows may cross an episode
// boundary: the step that starts the new episode carries is_first, which makes the world model
// restart from its initial state there, and the first step of every window is marked is_first
// because the model has no state from before it. Capacity is counted in steps over all
// streams; the oldest step is evicted first.
//
//   ReplayBuffer replay({.capacity = 100000, .height = 64, .width = 64, .has_rewards = false});
//   replay.add(/*stream=*/0, step);
//   SequenceBatch batch = replay.sample(16, 64);
#pragma once

#include <cstdint>
#include <deque>
#include <filesystem>
#include <map>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace indrive::agent {

// Data that cannot go into or come out of the replay buffer (wrong frame size, class id out of
// range, reward in a reward-free buffer, bad or foreign checkpoint file).
class ReplayError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One environment step as the actor recorded it.
struct ReplayStep {
  std::vector<std::uint8_t> frame;  // (H, W) semantic class ids, row-major
  int action = 0;                   // action taken after seeing the frame, in [0, num_actions)
  bool is_first = false;            // first step of an episode
  bool is_last = false;             // last step of an episode (terminal or time limit)
  bool is_terminal = false;         // the episode ended by a terminal event (no continuation)
  float reward = 0.0f;              // extrinsic reward, only read when the buffer has rewards
};

// A batch of B windows of T steps, row-major over (B, T).
struct SequenceBatch {
  int batch = 0, length = 0, height = 0, width = 0;
  std::vector<std::uint8_t> frames;  // (B, T, H, W) class ids
  std::vector<int> actions;          // (B, T)
  std::vector<float> is_first;       // (B, T) 1 or 0; [b, 0] is always 1
  std::vector<float> is_last;        // (B, T)
  std::vector<float> is_terminal;    // (B, T)
  std::vector<float> rewards;        // (B, T), empty when the buffer has no rewards
};

// Shape and mode of a replay buffer.
struct ReplayOptions {
  std::int64_t capacity = 100000;  // steps over all streams
  int height = 64;
  int width = 64;
  int num_classes = 8;  // class ids must be < num_classes
  int num_actions = 9;
  bool has_rewards = false;  // false in pretraining: no reward is stored or returned
  std::uint64_t seed = 0;
};

// Uniform replay of fixed-length windows. Not thread-safe.
class ReplayBuffer {
 public:
  // Creates an empty buffer; throws ReplayError when the options are unusable.
  explicit ReplayBuffer(ReplayOptions options);

  // Appends one step to a stream, evicting the oldest step when full. Throws ReplayError when
  // the frame has the wrong size or a class id is out of range, or the action is out of range.
  void add(int stream, const ReplayStep& step);
  // Number of stored steps.
  std::int64_t size() const { return size_; }
  // Total steps ever added.
  std::int64_t total_added() const { return total_added_; }
  // Number of distinct windows of `length` steps that sample() can return.
  std::int64_t num_windows(int length) const;
  // Draws `batch` windows of `length` steps uniformly over all valid windows (with
  // replacement). Checks that at least one window exists (callers wait for prefill).
  SequenceBatch sample(int batch, int length);
  const ReplayOptions& options() const { return options_; }

  // Writes every step, the counters and the RNG state to a file (atomically: a temporary file
  // renamed into place). Throws ReplayError when the file cannot be written.
  void save(const std::filesystem::path& path) const;
  // Replaces the contents with a file written by save(). Throws ReplayError when the file is
  // missing, corrupt (checksum), or was written with other frame sizes or reward mode.
  void load(const std::filesystem::path& path);
  // The bytes save() writes and load() reads, in memory (the learner packs them into its own
  // checkpoint file). `name` names where the bytes came from in error messages. A failed load
  // leaves the buffer unchanged.
  std::vector<std::uint8_t> to_bytes() const;
  void load(std::span<const std::uint8_t> bytes, const std::string& name);

 private:
  struct Stored {
    ReplayStep step;
    std::int64_t order = 0;  // global arrival index, for eviction of the oldest step
  };
  void evict_oldest();

  ReplayOptions options_;
  std::map<int, std::deque<Stored>> streams_;
  std::int64_t size_ = 0;
  std::int64_t total_added_ = 0;
  std::mt19937_64 rng_;
};

}  // namespace indrive::agent
