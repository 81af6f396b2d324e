// A small synthetic image environment for learning tests: a kDot x kDot "vehicle" on a road
// background that moves under the chosen action (steer -> x, throttle index -> y), with a
// rewarded goal region. Deterministic given its seed.
#pragma once

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "indrive/agent/replay.h"

namespace indrive::agent::synthetic {

class DotEnv {
 public:
  static constexpr int kDot = 12;  // side of the dot in pixels
  static constexpr int kMove = 3;  // pixels per step
  DotEnv(int size, std::uint64_t seed, int episode_length = 20)
      : size_(size), episode_length_(episode_length), rng_(seed) {}

  // Starts an episode at a random position and returns its first frame.
  std::vector<std::uint8_t> reset() {
    std::uniform_int_distribution<int> pos(0, size_ - kDot);
    x_ = pos(rng_), y_ = pos(rng_), t_ = 0;
    return frame();
  }
  // Moves the dot: action = 3 * steer + throttle, steer {-1, 0, +1} in x, throttle {0,1,2}
  // maps to y moves {-1, 0, +1}. Returns the reward of arriving at the new position.
  float step(int action) {
    const int dx = action / 3 - 1, dy = action % 3 - 1;
    x_ = std::clamp(x_ + kMove * dx, 0, size_ - kDot);
    y_ = std::clamp(y_ + kMove * dy, 0, size_ - kDot);
    ++t_;
    return reward();
  }
  // 1 when the dot is in the top-left goal quadrant.
  float reward() const { return (x_ < size_ / 4 && y_ < size_ / 4) ? 1.0f : 0.0f; }
  bool done() const { return t_ >= episode_length_; }
  std::vector<std::uint8_t> frame() const {
    std::vector<std::uint8_t> f(static_cast<std::size_t>(size_) * size_, 1);  // road
    for (int dy = 0; dy < kDot; ++dy)
      for (int dx = 0; dx < kDot; ++dx) f[(y_ + dy) * size_ + x_ + dx] = 4;  // vehicle
    return f;
  }
  int x() const { return x_; }
  int y() const { return y_; }

 private:
  int size_, episode_length_;
  std::mt19937_64 rng_;
  int x_ = 0, y_ = 0, t_ = 0;
};

// Fills a replay buffer with `steps` steps of random actions (one stream), recording the
// reward of arriving at each frame when the buffer keeps rewards. With `terminal_ends`, each
// episode's last step is terminal (as a task's failure or destination is), else a time limit.
inline void collect_random(DotEnv& env, ReplayBuffer& replay, int steps, std::uint64_t seed,
                           bool terminal_ends = false) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, 8);
  std::vector<std::uint8_t> frame = env.reset();
  bool first = true;
  float reward = 0.0f;
  for (int i = 0; i < steps; ++i) {
    ReplayStep s;
    s.frame = frame;
    s.action = pick(rng);
    s.is_first = first;
    s.reward = replay.options().has_rewards ? reward : 0.0f;
    reward = env.step(s.action);
    s.is_last = env.done();
    s.is_terminal = terminal_ends && s.is_last;
    replay.add(0, s);
    first = env.done();
    frame = first ? env.reset() : env.frame();
    if (first) reward = 0.0f;
  }
}

}  // namespace indrive::agent::synthetic
