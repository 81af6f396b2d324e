#include "indrive/learner/checkpoint.h"

#include <zstd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>
#include <sstream>

#include "indrive/basics/check.h"
#include "indrive/basics/checksum.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"

namespace indrive::learner {
namespace fs = std::filesystem;
namespace {

// A damaged checkpoint that a resume skipped is renamed to <name> + this, out of the rotation:
// its counter sorts after the checkpoints the resumed learner writes next, so left in place it
// would stay "newest" and the retention of learner.checkpoint_keep would delete intact ones.
constexpr std::string_view kDamagedSuffix = ".damaged";

// Version 1 holds counters and agent bytes; version 2 adds the sizes of its sections and the
// zstd-compressed replay file; version 3 adds a trailer with a CRC-32 of every byte before it,
// so that damage to the counters line (which has no checksum of its own) is noticed too.
constexpr std::string_view kCheckpointMagicPrefix = "INDRIVE-LEARNER-CHECKPOINT ";
constexpr int kCheckpointVersion = 3;
// "CRC32 " + 8 lowercase hex digits + "\n": fixed-size, so it is found from the end of the file.
constexpr std::string_view kTrailerTag = "CRC32 ";
constexpr std::size_t kTrailerSize = kTrailerTag.size() + 8 + 1;
// Replay holds class-id frames: a fast level already shrinks them many times over.
constexpr int kReplayZstdLevel = 1;

std::string checkpoint_trailer(std::uint32_t crc) {
  char text[16];
  std::snprintf(text, sizeof text, "%08x", crc);
  return std::string(kTrailerTag) + text + "\n";
}

// Checks the trailer of a version 3 checkpoint against every byte before it.
void check_trailer(std::span<const std::uint8_t> bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const std::string_view trailer = text.substr(text.size() - kTrailerSize);
  const std::string_view digits = trailer.substr(kTrailerTag.size(), 8);
  const bool well_formed =
      trailer.starts_with(kTrailerTag) && trailer.back() == '\n' &&
      std::all_of(digits.begin(), digits.end(), [](char c) { return std::isxdigit(c) != 0; });
  if (!well_formed) {
    throw CheckpointError(
        "learner checkpoint does not end with its checksum trailer 'CRC32 <8 hex digits>' "
        "(truncated or damaged file)");
  }
  const auto stored =
      static_cast<std::uint32_t>(std::stoul(std::string(digits), nullptr, /*base=*/16));
  const std::uint32_t actual = crc32(bytes.first(bytes.size() - kTrailerSize));
  if (stored != actual) {
    char numbers[64];
    std::snprintf(numbers, sizeof numbers, "CRC-32 of its content is %08x, its trailer says %08x",
                  actual, stored);
    throw CheckpointError(std::string("learner checkpoint is damaged: the ") + numbers);
  }
}

// Decompresses the replay section into `out`. The sizes come from a file that may be damaged,
// so nothing is allocated up front: the output grows only by what the frame actually produces
// and the decompression stops as soon as it would exceed the size the counters line declares.
void decompress_replay(std::span<const std::uint8_t> frame, std::uint64_t declared,
                       std::vector<std::uint8_t>& out) {
  const auto fail = [](const std::string& what) {
    return CheckpointError("the replay section of the learner checkpoint " + what +
                           " (damaged file)");
  };
  const unsigned long long content = ZSTD_getFrameContentSize(frame.data(), frame.size());
  if (content == ZSTD_CONTENTSIZE_ERROR) throw fail("does not start with a zstd frame header");
  if (content != ZSTD_CONTENTSIZE_UNKNOWN && content != declared) {
    throw fail("holds " + std::to_string(content) + " bytes, its counters line declares " +
               std::to_string(declared));
  }
  std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> context(ZSTD_createDCtx(), ZSTD_freeDCtx);
  INDRIVE_CHECK(context != nullptr) << "zstd could not make a decompression context";
  std::vector<std::uint8_t> block(ZSTD_DStreamOutSize());
  ZSTD_inBuffer in{frame.data(), frame.size(), 0};
  out.clear();
  while (true) {
    ZSTD_outBuffer piece{block.data(), block.size(), 0};
    const std::size_t status = ZSTD_decompressStream(context.get(), &piece, &in);
    if (ZSTD_isError(status)) {
      throw fail(std::string("does not decompress (") + ZSTD_getErrorName(status) + ")");
    }
    if (piece.pos > declared - out.size()) {
      throw fail("decompresses to more than the " + std::to_string(declared) +
                 " bytes its counters line declares");
    }
    out.insert(out.end(), block.data(), block.data() + piece.pos);
    if (status == 0) break;  // the frame is complete and its content checksum matched
    if (in.pos == in.size && piece.pos < piece.size) throw fail("ends inside its zstd frame");
  }
  if (in.pos != in.size) {
    throw fail("has " + std::to_string(in.size - in.pos) + " bytes after its zstd frame");
  }
  if (out.size() != declared) {
    throw fail("decompresses to " + std::to_string(out.size()) +
               " bytes, its counters line declares " + std::to_string(declared));
  }
}

// What one checkpoint file restores, into fresh objects.
RestoredRun restore(const fs::path& file, const agent::AgentConfig& config,
                    const agent::ReplayOptions& replay_options) {
  std::vector<std::uint8_t> agent_bytes, replay_bytes;
  RestoredRun restored;
  restored.file = file;
  restored.counters = unpack_checkpoint(read_file(file), agent_bytes, &replay_bytes);
  restored.agent = std::make_unique<agent::Agent>(config);
  restored.agent->load_checkpoint(agent_bytes, file.string() + " (agent section)");
  restored.replay.emplace(replay_options);
  if (!replay_bytes.empty()) restored.replay->load(replay_bytes, file.string() + " (replay)");
  return restored;
}

// True when `bytes` begin like a learner checkpoint (its magic prefix), whole or damaged.
bool looks_like_learner_checkpoint(std::span<const std::uint8_t> bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  return text.starts_with(kCheckpointMagicPrefix);
}

// Moves a damaged checkpoint out of the rotation, keeping its bytes for a look.
void set_aside(const fs::path& file) {
  const fs::path target = file.string() + std::string(kDamagedSuffix);
  std::error_code error;
  fs::rename(file, target, error);
  if (error) {
    INDRIVE_LOG(kWarn, "learner") << "could not rename damaged checkpoint " << file.string()
                                  << " to " << target.filename().string() << ": " << error.message()
                                  << "; move it away by hand";
  } else {
    INDRIVE_LOG(kWarn, "learner") << "damaged checkpoint " << file.string() << " set aside as "
                                  << target.filename().string()
                                  << "; delete it once it is no longer needed";
  }
}

}  // namespace

std::vector<std::uint8_t> pack_checkpoint(const LearnerCounters& counters,
                                          std::span<const std::uint8_t> agent_bytes,
                                          std::span<const std::uint8_t> replay_bytes) {
  std::vector<std::uint8_t> replay_zstd;
  if (!replay_bytes.empty()) {
    // The frame carries a checksum of its content, so a damaged section is noticed.
    std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
    ZSTD_CCtx_setParameter(context.get(), ZSTD_c_compressionLevel, kReplayZstdLevel);
    ZSTD_CCtx_setParameter(context.get(), ZSTD_c_checksumFlag, 1);
    replay_zstd.resize(ZSTD_compressBound(replay_bytes.size()));
    const std::size_t size = ZSTD_compress2(context.get(), replay_zstd.data(), replay_zstd.size(),
                                            replay_bytes.data(), replay_bytes.size());
    INDRIVE_CHECK(!ZSTD_isError(size)) << "zstd failed on the replay: " << ZSTD_getErrorName(size);
    replay_zstd.resize(size);
  }
  const nlohmann::json meta = {
      {"env_steps", counters.env_steps},           {"updates", counters.updates},
      {"policy_version", counters.policy_version}, {"learner_epoch", counters.learner_epoch},
      {"agent_bytes", agent_bytes.size()},         {"replay_bytes", replay_bytes.size()},
      {"replay_zstd_bytes", replay_zstd.size()}};
  const std::string head = std::string(kCheckpointMagicPrefix) +
                           std::to_string(kCheckpointVersion) + "\n" + meta.dump() + "\n";
  std::vector<std::uint8_t> bytes;
  bytes.reserve(head.size() + agent_bytes.size() + replay_zstd.size() + kTrailerSize);
  bytes.insert(bytes.end(), head.begin(), head.end());
  bytes.insert(bytes.end(), agent_bytes.begin(), agent_bytes.end());
  bytes.insert(bytes.end(), replay_zstd.begin(), replay_zstd.end());
  const std::string trailer = checkpoint_trailer(crc32(bytes));
  bytes.insert(bytes.end(), trailer.begin(), trailer.end());
  return bytes;
}

LearnerCounters unpack_checkpoint(std::span<const std::uint8_t> bytes,
                                  std::vector<std::uint8_t>& agent_bytes,
                                  std::vector<std::uint8_t>* replay_bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const std::string expected_line =
      std::string(kCheckpointMagicPrefix) + std::to_string(kCheckpointVersion);
  // "INDRIVE-LEARNER-CHECKPOINT <one digit>\n"
  const std::size_t magic_size = kCheckpointMagicPrefix.size() + 2;
  const bool has_magic = text.size() >= magic_size && text.starts_with(kCheckpointMagicPrefix) &&
                         std::isdigit(static_cast<unsigned char>(text[magic_size - 2])) &&
                         text[magic_size - 1] == '\n';
  if (!has_magic) {
    const std::size_t compared = std::min(text.size(), kCheckpointMagicPrefix.size());
    if (text.size() < magic_size &&
        text.substr(0, compared) == kCheckpointMagicPrefix.substr(0, compared)) {
      throw CheckpointError("learner checkpoint of " + std::to_string(bytes.size()) +
                            " bytes is truncated inside its first line");
    }
    throw CheckpointError("not a learner checkpoint (its first line is not '" + expected_line +
                          "')");
  }
  const int version = text[magic_size - 2] - '0';
  if (version < 1 || version > kCheckpointVersion) {
    throw CheckpointError("learner checkpoint has format version " + std::to_string(version) +
                          "; this program reads versions 1 to " +
                          std::to_string(kCheckpointVersion) + " (written by a newer learner?)");
  }
  std::size_t body_size = bytes.size();
  if (version >= 3) {
    if (bytes.size() < magic_size + kTrailerSize) {
      throw CheckpointError("learner checkpoint of " + std::to_string(bytes.size()) +
                            " bytes is too short to hold its checksum trailer (truncated file)");
    }
    // Before anything is parsed: a damaged counters line could otherwise parse as other numbers.
    check_trailer(bytes);
    body_size -= kTrailerSize;
  }
  const std::size_t meta_end = text.substr(0, body_size).find('\n', magic_size);
  if (meta_end == std::string_view::npos) {
    throw CheckpointError("learner checkpoint is truncated inside its counters line");
  }
  const std::size_t agent_begin = meta_end + 1;
  const std::uint64_t after_counters = body_size - agent_begin;
  LearnerCounters counters;
  std::uint64_t agent_size = after_counters;
  std::uint64_t replay_size = 0, replay_zstd_size = 0;
  try {
    const auto meta = nlohmann::json::parse(text.substr(magic_size, meta_end - magic_size));
    counters.env_steps = meta.at("env_steps").get<std::int64_t>();
    counters.updates = meta.at("updates").get<std::int64_t>();
    counters.policy_version = meta.at("policy_version").get<std::uint64_t>();
    counters.learner_epoch = meta.at("learner_epoch").get<std::uint64_t>();
    if (version >= 2) {
      agent_size = meta.at("agent_bytes").get<std::uint64_t>();
      replay_size = meta.at("replay_bytes").get<std::uint64_t>();
      replay_zstd_size = meta.at("replay_zstd_bytes").get<std::uint64_t>();
    }
  } catch (const nlohmann::json::exception& error) {
    throw CheckpointError(std::string("learner checkpoint counters are unreadable: ") +
                          error.what());
  }
  // Compared without adding the sizes: damaged ones near 2^64 would wrap around.
  if (agent_size > after_counters || replay_zstd_size != after_counters - agent_size) {
    throw CheckpointError("learner checkpoint has " + std::to_string(after_counters) +
                          " bytes after its counters, its header says " +
                          std::to_string(agent_size) + " + " + std::to_string(replay_zstd_size) +
                          " (truncated or damaged file)");
  }
  if (replay_zstd_size == 0 && replay_size != 0) {
    throw CheckpointError("learner checkpoint declares " + std::to_string(replay_size) +
                          " replay bytes but holds no replay section (damaged file)");
  }
  const auto agent_section = bytes.subspan(agent_begin, agent_size);
  agent_bytes.assign(agent_section.begin(), agent_section.end());
  if (replay_bytes != nullptr) {
    replay_bytes->clear();
    if (replay_zstd_size > 0) {
      decompress_replay(bytes.subspan(agent_begin + agent_size, replay_zstd_size), replay_size,
                        *replay_bytes);
    }
  }
  return counters;
}

RestoredRun restore_newest(const std::vector<fs::path>& files, const agent::AgentConfig& config,
                           const agent::ReplayOptions& replay_options, const std::string& run_id) {
  std::vector<std::pair<fs::path, std::string>> damaged;
  for (auto file = files.rbegin(); file != files.rend(); ++file) {
    RestoredRun restored;
    try {
      restored = restore(*file, config, replay_options);
    } catch (const std::exception& error) {
      // Whatever the loaders throw: CheckpointError, agent::AgentError, agent::ReplayError,
      // IoError when the file cannot be read, std::bad_alloc for sizes no memory holds.
      damaged.emplace_back(*file, error.what());
      INDRIVE_LOG(kWarn, "learner") << "checkpoint " << file->string()
                                    << " cannot be restored and is skipped: " << error.what();
      continue;
    }
    restored.skipped = damaged.size();
    for (const auto& [path, reason] : damaged) set_aside(path);
    INDRIVE_LOG(kInfo, "learner") << "resumed from " << file->string() << " with "
                                  << restored.replay->size() << " replay steps (skipped "
                                  << damaged.size() << " damaged newer checkpoint"
                                  << (damaged.size() == 1 ? "" : "s") << ")";
    return restored;
  }
  std::string message = "no checkpoint of run '" + run_id + "' can be restored (" +
                        std::to_string(damaged.size()) + " tried):";
  for (const auto& [path, reason] : damaged) message += "\n  " + path.string() + ": " + reason;
  message +=
      "\nThe learner does not start the run again from nothing on its own: restore an "
      "intact copy, or move these files out of " +
      (files.empty() ? std::string("the checkpoints folder")
                     : files.front().parent_path().string()) +
      " to start the run afresh.";
  throw CheckpointError(message);
}

RestoredRun load_agent_checkpoint(const fs::path& file, const agent::AgentConfig& config) {
  if (!fs::exists(file)) throw CheckpointError("checkpoint " + file.string() + " does not exist");
  const std::vector<std::uint8_t> bytes = read_file(file);
  RestoredRun loaded;
  loaded.file = file;
  std::vector<std::uint8_t> agent_bytes;
  if (looks_like_learner_checkpoint(bytes)) {
    try {
      loaded.counters = unpack_checkpoint(bytes, agent_bytes);
    } catch (const CheckpointError& error) {
      throw CheckpointError(file.string() + ": " + error.what());
    }
  }
  loaded.agent = std::make_unique<agent::Agent>(config);
  loaded.agent->load_checkpoint(agent_bytes.empty() ? bytes : agent_bytes, file.string());
  return loaded;
}

RestoredRun load_newest_agent(const std::vector<fs::path>& files,
                              const agent::AgentConfig& config) {
  std::string faults;
  std::uint64_t skipped = 0;
  for (auto file = files.rbegin(); file != files.rend(); ++file) {
    try {
      RestoredRun loaded = load_agent_checkpoint(*file, config);
      loaded.skipped = skipped;
      return loaded;
    } catch (const std::exception& error) {  // CheckpointError, agent::AgentError, IoError
      ++skipped;
      faults += "\n  " + file->string() + ": " + error.what();
      INDRIVE_LOG(kWarn, "learner")
          << "checkpoint " << file->string() << " does not load and is skipped: " << error.what();
    }
  }
  throw CheckpointError(files.empty() ? std::string("no checkpoint to load")
                                      : "no checkpoint loads (" + std::to_string(skipped) +
                                            " tried):" + faults);
}

RunStart start_run(const std::vector<fs::path>& files, const std::string& init_checkpoint,
                   const agent::AgentConfig& config, const agent::ReplayOptions& replay_options,
                   const std::string& run_id) {
  RunStart start;
  if (!files.empty()) {
    start.from = StartedFrom::kCheckpoint;
    start.restored = restore_newest(files, config, replay_options, run_id);
  } else if (!init_checkpoint.empty()) {
    if (!fs::exists(init_checkpoint)) {
      throw CheckpointError("learner.init_checkpoint '" + init_checkpoint +
                            "' does not exist: point it at a pretraining run's checkpoint "
                            "(runs/<run>/checkpoints/ckpt-*.bin)");
    }
    start.from = StartedFrom::kInitCheckpoint;
    start.restored = load_agent_checkpoint(init_checkpoint, config);
    start.restored.counters = {};  // a finetune counts its own steps from zero
    INDRIVE_LOG(kInfo, "learner") << "initialised from " << init_checkpoint;
  }
  ++start.restored.counters.learner_epoch;
  return start;
}

CheckpointWriter::CheckpointWriter(fs::path folder, int keep, std::string channel, double every_s)
    : files_(std::move(folder), keep), channel_(std::move(channel)), every_s_(every_s) {}

double CheckpointWriter::seconds_since_save() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - last_try_).count();
}

bool CheckpointWriter::save(const LearnerCounters& counters,
                            std::span<const std::uint8_t> agent_bytes,
                            std::span<const std::uint8_t> replay_bytes, std::int64_t replay_steps,
                            bool final) {
  const auto start = std::chrono::steady_clock::now();
  // Replay goes into the same file, so counters, model and data always match.
  const std::vector<std::uint8_t> packed = pack_checkpoint(counters, agent_bytes, replay_bytes);
  const auto counter = static_cast<std::uint64_t>(counters.updates);
  fs::path path;
  try {
    path = files_.save(counter, packed);
  } catch (const IoError& error) {
    last_try_ = std::chrono::steady_clock::now();
    ++failures_;
    std::ostringstream next;
    if (!final) next << "; the next try is in " << every_s_ << " s (free space on that disk)";
    INDRIVE_LOG(kError, channel_) << (final ? "final " : "") << "checkpoint "
                                  << files_.path(counter).filename().string() << " ("
                                  << packed.size() << " bytes) was not written: " << error.what()
                                  << "; "
                                  << (latest_.empty() ? "this run has no earlier checkpoint"
                                                      : "the previous checkpoint " +
                                                            latest_.string() + " is intact")
                                  << "; " << failures_ << " failed in this run" << next.str();
    return false;
  }
  last_try_ = std::chrono::steady_clock::now();
  latest_ = path;
  ++written_;
  INDRIVE_LOG(kInfo, channel_) << "checkpoint " << path.filename().string() << " (" << packed.size()
                               << " bytes: agent " << agent_bytes.size() << ", replay of "
                               << replay_steps << " steps " << replay_bytes.size() << " -> "
                               << packed.size() - agent_bytes.size() << " compressed; "
                               << std::chrono::duration<double>(last_try_ - start).count() << " s)";
  return true;
}

}  // namespace indrive::learner
