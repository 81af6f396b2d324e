// TrajectoryChunk as the learner ingests it: CDR -> wire checks -> decode into replay steps.
// Input: one flag byte, then the CDR sample. Flag bit 0 re-seals the chunk (a valid checksum
// over whatever the rest says, as a hostile sender could compute), so the checks behind the
// checksum get explored too; bit 1 decodes as a task phase (rewards required).
#include <cstdint>
#include <cstdlib>

#include "fuzz_cdr.h"
#include "fuzz_support.h"
#include "indrive/actor/chunk_builder.h"
#include "indrive/learner/ingest.h"

namespace {

using namespace indrive;
constexpr int kSide = 16;

learner::IngestOptions options(bool task) {
  return {.run_id = "fuzz",
          .height = kSide,
          .width = kSide,
          .phase = task ? msg::PHASE_FINETUNE : msg::PHASE_PRETRAIN,
          .with_rewards = task};
}

void make_seeds(const fuzz::fs::path& dir) {
  for (const bool task : {false, true}) {
    actor::ChunkBuilder builder({.run_id = "fuzz",
                                 .actor_id = 3,
                                 .height = kSide,
                                 .width = kSide,
                                 .chunk_length = 6,
                                 .phase = task ? msg::PHASE_FINETUNE : msg::PHASE_PRETRAIN,
                                 .with_rewards = task});
    std::vector<std::uint8_t> frame(kSide * kSide);
    int made = 0;
    for (int t = 0; t < 10; ++t) {
      for (std::size_t i = 0; i < frame.size(); ++i) frame[i] = (i / kSide + t) % 8;
      const bool last = t == 9;
      const bool complete =
          builder.add({.frame = frame,
                       .action = last ? 0 : t % 9,
                       .is_first = t == 0,
                       .is_last = last,
                       .is_terminal = last,
                       .events = last ? 1u : 0u,
                       .reward = task ? std::optional<float>(0.5f * t) : std::nullopt,
                       .episode_id = 1,
                       .episode_step = static_cast<std::uint64_t>(t)});
      if (!complete) continue;
      std::vector<std::uint8_t> input = {static_cast<std::uint8_t>(task ? 2 : 0)};
      const auto cdr = fuzz::to_cdr(builder.take());
      input.insert(input.end(), cdr.begin(), cdr.end());
      fuzz::write_seed(dir, std::string(task ? "task" : "pretrain") + "-" + std::to_string(made++),
                       input);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  msg::TrajectoryChunk chunk;
  if (!fuzz::from_cdr(std::span(data + 1, size - 1), chunk)) return 0;
  if (data[0] & 1) dds::seal(chunk);
  learner::DecodedChunk decoded;
  const auto reason = learner::decode_chunk(chunk, options((data[0] & 2) != 0), decoded);
  if (reason == dds::DropReason::kOk) {
    // What replay receives: whole steps of this model's frame size and in-range ids.
    if (decoded.steps.size() != chunk.num_steps()) std::abort();
    for (const auto& step : decoded.steps) {
      if (step.frame.size() != static_cast<std::size_t>(kSide * kSide)) std::abort();
      if (step.action < 0 || step.action >= 9) std::abort();
    }
  }
  return 0;
}
