// A replay file (replay.h, ReplayBuffer::save / load), as a resuming learner restores its
// replay from the checkpoint. What loads must be what replay promises its sampler: frames of
// the buffer's size, class ids and actions in range, no more steps than the capacity.
// Input: one flag byte, then the file; flag bit 0 rewrites the CRC-32 trailer to match.
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "fuzz_support.h"
#include "indrive/agent/replay.h"
#include "indrive/basics/checksum.h"
#include "indrive/basics/run_dir.h"

namespace {

using namespace indrive;

agent::ReplayOptions options(bool rewards) {
  return {.capacity = 64, .height = 8, .width = 8, .has_rewards = rewards, .seed = 3};
}

void make_seeds(const fuzz::fs::path& dir) {
  for (const bool rewards : {false, true}) {
    agent::ReplayBuffer replay(options(rewards));
    for (int stream = 0; stream < 2; ++stream) {
      for (int t = 0; t < 12; ++t) {
        agent::ReplayStep step;
        step.frame.assign(64, static_cast<std::uint8_t>((t + stream) % 8));
        step.action = t % 9;
        step.is_first = t == 0;
        step.is_last = step.is_terminal = t == 11;
        step.reward = rewards ? 0.25f * t : 0.0f;
        replay.add(stream, step);
      }
    }
    const auto path = dir / "replay.tmp";
    replay.save(path);
    auto bytes = read_file(path);
    fuzz::fs::remove(path);
    bytes.insert(bytes.begin(), static_cast<std::uint8_t>(rewards ? 2 : 0));
    fuzz::write_seed(dir, rewards ? "with-rewards" : "without-rewards", bytes);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::vector<std::uint8_t> file = fuzz::file_with_flags(data, size);
  agent::ReplayBuffer replay(options((data[0] & 2) != 0));
  const auto& path = fuzz::as_file(file.data(), file.size(), ".replay");
  bool loaded = false;
  fuzz::accept<agent::ReplayError>([&] {
    replay.load(path);
    loaded = true;
  });
  if (!loaded) return 0;
  if (replay.size() > replay.options().capacity) std::abort();
  if (replay.num_windows(2) > 0) {
    const agent::SequenceBatch batch = replay.sample(4, 2);
    for (const int action : batch.actions) {
      if (action < 0 || action >= replay.options().num_actions) std::abort();
    }
    for (const std::uint8_t id : batch.frames) {
      if (id >= replay.options().num_classes) std::abort();
    }
  }
  return 0;
}
