// The snapshot file format (snapshot_file.h): the learner writes it, the evaluators and tools
// read it.
#include "indrive/agent/snapshot_file.h"

#include <algorithm>
#include <charconv>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "indrive/agent/policy.h"
#include "indrive/basics/check.h"
#include "indrive/basics/checksum.h"
#include "indrive/basics/run_dir.h"
#include "indrive/nn/serialize.h"

namespace indrive::agent {
namespace {

// Snapshot file format 1 (see snapshot_file.h): magic, version, header length, header text,
// header CRC-32, then the blob.
constexpr char kFileMagic[8] = {'I', 'N', 'D', 'R', 'S', 'N', 'A', 'P'};
constexpr std::size_t kFilePrefix = sizeof(kFileMagic) + 4 + 4;  // magic, version, length
constexpr std::uint32_t kMaxHeaderBytes = 64 * 1024;
constexpr const char* kActorKey = "actor";

// The items separated by ", ".
std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& item : items) {
    if (!out.empty()) out += ", ";
    out += item;
  }
  return out;
}

}  // namespace

const char* acting_actor_group(Phase phase) {
  return phase == Phase::kPretrain ? "expl_actor" : "task_actor";
}

std::vector<std::string> snapshot_groups(std::span<const std::uint8_t> blob) {
  std::vector<nn::BlobGroup> contents;
  try {
    contents = nn::blob_contents(blob);
  } catch (const nn::SerializationError& error) {
    throw SnapshotFileError(std::string("snapshot: ") + error.what());
  }
  std::vector<std::string> names;
  names.reserve(contents.size());
  for (const nn::BlobGroup& group : contents) names.push_back(group.name);
  return names;
}

const std::vector<std::string>& snapshot_architecture_keys() {
  static const std::vector<std::string> keys = {
      "preset",
      "phase",
      kActorKey,
      "world_model.image",
      "world_model.channels",
      "world_model.cnn_depth",
      "world_model.deter",
      "world_model.units",
      "world_model.stoch",
      "world_model.classes",
      "world_model.head_layers",
      "behavior.units",
      "behavior.layers",
  };
  return keys;
}

bool is_snapshot_size_key(const std::string& key) {
  return key != "preset" && key != "phase" && key != kActorKey &&
         std::find(snapshot_architecture_keys().begin(), snapshot_architecture_keys().end(), key) !=
             snapshot_architecture_keys().end();
}

std::string SnapshotFile::value(const std::string& key) const {
  for (const auto& [name, text] : architecture) {
    if (name == key) return text;
  }
  return "";
}

namespace {

// A provenance key's number; nullopt when it is not a whole decimal number.
std::optional<std::uint64_t> parse_count(const std::string& text) {
  std::uint64_t value = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, error] = std::from_chars(text.data(), end, value);
  if (text.empty() || error != std::errc() || ptr != end) return std::nullopt;
  return value;
}

}  // namespace

std::optional<SnapshotProvenance> SnapshotFile::provenance() const {
  const std::string run_id = value("run_id");
  const auto version = parse_count(value("version"));
  const auto env_steps = parse_count(value("env_steps"));
  if (run_id.empty() || !version || !env_steps) return std::nullopt;
  return SnapshotProvenance{.run_id = run_id, .version = *version, .env_steps = *env_steps};
}

std::string snapshot_key_text(const AgentConfig& config, const std::string& key) {
  for (const auto& [name, text] : config_values(config)) {
    if (name == key) return text;
  }
  INDRIVE_CHECK(false) << "snapshot architecture key '" << key << "' is not an agent key";
  return "";
}

namespace {

// Parses and checks the header text of a format-1 file; throws SnapshotFileError (without the file
// name) when a line or a required key is missing or a value does not parse.
std::vector<std::pair<std::string, std::string>> parse_header(const std::string& text) {
  std::vector<std::pair<std::string, std::string>> pairs;
  std::size_t begin = 0;
  while (begin < text.size()) {
    const std::size_t end = text.find('\n', begin);
    if (end == std::string::npos) throw SnapshotFileError("header: its last line lacks a newline");
    const std::string line = text.substr(begin, end - begin);
    begin = end + 1;
    const std::size_t eq = line.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw SnapshotFileError("header: line '" + line + "' is not key=value");
    }
    pairs.emplace_back(line.substr(0, eq), line.substr(eq + 1));
  }
  AgentConfig scratch;
  for (const std::string& key : snapshot_architecture_keys()) {
    const auto it = std::find_if(pairs.begin(), pairs.end(),
                                 [&](const auto& pair) { return pair.first == key; });
    if (it == pairs.end()) throw SnapshotFileError("header: it lacks the key " + key);
    if (key == kActorKey || key == "preset") {
      if (it->second.empty()) throw SnapshotFileError("header: " + key + " is empty");
      continue;
    }
    try {
      set_config_value(scratch, key, it->second);
    } catch (const AgentConfigError& error) {
      throw SnapshotFileError(std::string("header: ") + error.what());
    }
    if (is_snapshot_size_key(key) && snapshot_key_text(scratch, key).starts_with("-")) {
      throw SnapshotFileError("header: " + key + "=" + it->second + " is negative");
    }
  }
  return pairs;
}

// The contents of a snapshot file's bytes (either format); throws SnapshotFileError without the
// name.
SnapshotFile parse_snapshot_file(std::vector<std::uint8_t> bytes) {
  SnapshotFile file;
  if (nn::starts_like_blob(bytes)) {  // format 0: the bare blob
    snapshot_groups(bytes);
    file.blob = std::move(bytes);
    return file;
  }
  if (bytes.size() < sizeof(kFileMagic) ||
      std::memcmp(bytes.data(), kFileMagic, sizeof(kFileMagic)) != 0) {
    throw SnapshotFileError(
        "not a snapshot file (it starts with neither the snapshot file magic "
        "INDRSNAP nor a parameter blob's)");
  }
  if (bytes.size() < kFilePrefix + 4) {
    throw SnapshotFileError("header is truncated (the file has " + std::to_string(bytes.size()) +
                            " bytes)");
  }
  std::uint32_t version = 0, length = 0;
  std::memcpy(&version, bytes.data() + sizeof(kFileMagic), 4);
  std::memcpy(&length, bytes.data() + sizeof(kFileMagic) + 4, 4);
  if (length > kMaxHeaderBytes || length > bytes.size() - kFilePrefix - 4) {
    throw SnapshotFileError("header is truncated or corrupt (its text claims " +
                            std::to_string(length) + " bytes where " +
                            std::to_string(bytes.size() - kFilePrefix - 4) + " are left)");
  }
  std::uint32_t stored = 0;
  std::memcpy(&stored, bytes.data() + kFilePrefix + length, 4);
  if (crc32(bytes.data(), kFilePrefix + length) != stored) {
    throw SnapshotFileError("header checksum mismatch: the file is corrupt");
  }
  if (version != kSnapshotFileFormat) {
    throw SnapshotFileError("file format version " + std::to_string(version) +
                            ", this build reads versions 0 and " +
                            std::to_string(kSnapshotFileFormat) +
                            "; evaluate it with the build that wrote it or a newer one");
  }
  file.format = version;
  file.architecture =
      parse_header(std::string(reinterpret_cast<const char*>(bytes.data() + kFilePrefix), length));
  file.blob.assign(bytes.begin() + static_cast<std::ptrdiff_t>(kFilePrefix + length + 4),
                   bytes.end());
  const std::vector<std::string> groups = snapshot_groups(file.blob);
  if (groups.empty() || groups.back() != file.value(kActorKey)) {
    throw SnapshotFileError("header names the actor " + file.value(kActorKey) +
                            " but the blob holds [" + join(groups) + "]");
  }
  return file;
}

}  // namespace

SnapshotFile read_snapshot_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!std::filesystem::is_regular_file(path) || !in) {
    throw SnapshotFileError(
        "snapshot file " + path.string() +
        " does not exist or cannot be read; name a run's final-snapshot.params (written by "
        "its learner) or a <run>/eval/snapshot-v<N>.params (written by an evaluator)");
  }
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
  if (bytes.empty()) throw SnapshotFileError("snapshot file " + path.string() + " is empty");
  try {
    return parse_snapshot_file(std::move(bytes));
  } catch (const SnapshotFileError& error) {
    throw SnapshotFileError("snapshot file " + path.string() + ": " + error.what());
  }
}

namespace {

// Writes format kSnapshotFileFormat: prefix, header text, header CRC, blob.
void write_file(const std::filesystem::path& path, const std::string& header,
                std::span<const std::uint8_t> blob) {
  std::vector<std::uint8_t> bytes(kFilePrefix);
  std::memcpy(bytes.data(), kFileMagic, sizeof(kFileMagic));
  const std::uint32_t length = static_cast<std::uint32_t>(header.size());
  std::memcpy(bytes.data() + sizeof(kFileMagic), &kSnapshotFileFormat, 4);
  std::memcpy(bytes.data() + sizeof(kFileMagic) + 4, &length, 4);
  bytes.insert(bytes.end(), header.begin(), header.end());
  const std::uint32_t checksum = crc32(bytes.data(), bytes.size());
  bytes.resize(bytes.size() + 4);
  std::memcpy(bytes.data() + bytes.size() - 4, &checksum, 4);
  bytes.insert(bytes.end(), blob.begin(), blob.end());
  atomic_write(path, bytes);
}

}  // namespace

void write_snapshot_file(const std::filesystem::path& path, std::span<const std::uint8_t> blob,
                         const AgentConfig& architecture,
                         const std::optional<SnapshotProvenance>& provenance) {
  const std::vector<std::string> groups = snapshot_groups(blob);
  const std::string actor = acting_actor_group(architecture.phase);
  if (groups.empty() || groups.back() != actor) {
    throw SnapshotFileError("snapshot for " + path.string() + " holds [" + join(groups) +
                            "], but its phase " + std::string(to_string(architecture.phase)) +
                            " acts with " + actor);
  }
  std::string header;
  for (const std::string& key : snapshot_architecture_keys()) {
    const std::string text = key == kActorKey ? actor : snapshot_key_text(architecture, key);
    INDRIVE_CHECK(text.find('\n') == std::string::npos) << key << " holds a newline";
    header += key + "=" + text + "\n";
  }
  if (provenance) {
    INDRIVE_CHECK(!provenance->run_id.empty() && provenance->run_id.find('\n') == std::string::npos)
        << "a snapshot's run id '" << provenance->run_id << "' cannot be a header value";
    header += "run_id=" + provenance->run_id + "\n";
    header += "version=" + std::to_string(provenance->version) + "\n";
    header += "env_steps=" + std::to_string(provenance->env_steps) + "\n";
  }
  write_file(path, header, blob);
}

std::string describe_snapshot_file(const SnapshotFile& file) {
  std::vector<nn::BlobGroup> groups;
  try {
    groups = nn::blob_contents(file.blob);
  } catch (const nn::SerializationError& error) {
    throw SnapshotFileError(std::string("snapshot: ") + error.what());
  }
  std::ostringstream out;
  out << "format " << file.format
      << (file.format == 0 ? " (a bare parameter blob: no architecture header)" : "") << "\n";
  for (const auto& [key, value] : file.architecture) out << "  " << key << " = " << value << "\n";
  std::size_t total_values = 0;
  for (const nn::BlobGroup& group : groups) {
    std::size_t values = 0, left_out = 0;
    for (const nn::BlobParam& param : group.params) {
      values += static_cast<std::size_t>(param.shape.numel());
      if (!snapshot_keeps(group.name, param.name)) ++left_out;
    }
    total_values += values;
    out << "group " << group.name << ": " << group.params.size() << " parameters, " << values
        << " values (" << values * sizeof(float) << " bytes)";
    if (group.name == "world_model") {
      out << (left_out == 0 ? "; what acting runs (encoder, RSSM)"
                            : "; the whole world model: " + std::to_string(left_out) +
                                  " parameters acting does not run (decoder, continuation "
                                  "head); `indrive snapshot FILE --acting-only OUT` leaves "
                                  "them out");
    }
    out << "\n";
  }
  out << "blob: " << file.blob.size() << " bytes, " << total_values << " values\n";
  return out.str();
}

void write_acting_snapshot_file(const std::filesystem::path& path, const SnapshotFile& file) {
  if (file.format == 0) {
    throw SnapshotFileError(
        "a format-0 snapshot (bare blob) has no architecture header to keep: evaluate it with "
        "--set preset=NAME, and the evaluator saves it again as a file of the current format");
  }
  std::string header;
  for (const auto& [key, value] : file.architecture) header += key + "=" + value + "\n";
  std::vector<std::uint8_t> blob;
  try {
    blob = nn::filter_blob(file.blob, snapshot_keeps);
  } catch (const nn::SerializationError& error) {
    throw SnapshotFileError(std::string("snapshot: ") + error.what());
  }
  write_file(path, header, blob);
}

}  // namespace indrive::agent
