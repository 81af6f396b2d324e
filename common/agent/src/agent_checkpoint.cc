// The agent's checkpoint file: everything an update depends on (parameters, optimiser states,
// normalisers, the RNG and the counters), so a resumed agent continues bitwise; the learner's
// checkpoint holds it as one part (docs/formats.md, "Learner checkpoints"). Layout: magic
// "IAGT", format version (u32), then sections of u64 length + bytes (architecture, parameters,
// one per optimiser, normalisers, RNG, counters, the continuation head's optimiser), and the
// CRC-32 of all before it.
#include <cstring>
#include <fstream>
#include <type_traits>

#include "indrive/agent/agent.h"
#include "indrive/basics/checksum.h"
#include "indrive/basics/run_dir.h"

namespace indrive::agent {
namespace {

constexpr char kMagic[4] = {'I', 'A', 'G', 'T'};
constexpr std::uint32_t kVersion = 1;

// Section writer/reader of the checkpoint: u64 length + bytes per section.
void put_section(std::vector<std::uint8_t>& out, std::span<const std::uint8_t> bytes) {
  const std::uint64_t size = bytes.size();
  const auto* p = reinterpret_cast<const std::uint8_t*>(&size);
  out.insert(out.end(), p, p + sizeof(size));
  out.insert(out.end(), bytes.begin(), bytes.end());
}

template <typename T>
std::vector<std::uint8_t> bytes_of(const std::vector<T>& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  const auto* p = reinterpret_cast<const std::uint8_t*>(v.data());
  return {p, p + v.size() * sizeof(T)};
}

template <typename T>
std::vector<T> values_of(std::span<const std::uint8_t> bytes) {
  std::vector<T> v(bytes.size() / sizeof(T));
  std::memcpy(v.data(), bytes.data(), v.size() * sizeof(T));
  return v;
}

class SectionReader {
 public:
  SectionReader(std::span<const std::uint8_t> data, std::string file)
      : data_(data), file_(std::move(file)) {}
  std::span<const std::uint8_t> next() {
    std::uint64_t size = 0;
    if (pos_ + sizeof(size) > data_.size())
      throw AgentError("checkpoint " + file_ + " is truncated");
    std::memcpy(&size, data_.data() + pos_, sizeof(size));
    pos_ += sizeof(size);
    // Compared as a remainder: a damaged size near 2^64 would wrap pos_ + size.
    if (size > data_.size() - pos_) throw AgentError("checkpoint " + file_ + " is truncated");
    auto out = data_.subspan(pos_, size);
    pos_ += size;
    return out;
  }
  bool done() const { return pos_ == data_.size(); }

 private:
  std::span<const std::uint8_t> data_;
  std::string file_;
  std::size_t pos_ = 0;
};

// Architecture descriptor: the sizes that must match between checkpoint and agent.
std::vector<std::int64_t> architecture(const AgentConfig& c) {
  const WorldModelConfig& w = c.world_model;
  return {w.image,
          w.channels,
          w.cnn_depth,
          w.deter,
          w.units,
          w.stoch,
          w.classes,
          w.head_layers,
          static_cast<std::int64_t>(c.intrinsic.method),
          c.intrinsic.ensemble,
          c.intrinsic.units,
          c.intrinsic.layers,
          c.intrinsic.rnd_embed,
          c.behavior.units,
          c.behavior.layers};
}

}  // namespace

std::vector<std::uint8_t> Agent::checkpoint_bytes() const {
  std::vector<std::uint8_t> out(kMagic, kMagic + 4);
  out.resize(8);
  std::memcpy(out.data() + 4, &kVersion, 4);
  put_section(out, bytes_of(architecture(config_)));
  const std::vector<const nn::ParamGroup*> g = groups();
  put_section(out, nn::save_params(std::span<const nn::ParamGroup* const>(g)));
  for (const nn::Adam* opt : optimizers()) put_section(out, opt->save_state());
  std::vector<float> norms = intrinsic_->normalizer_state();
  norms.push_back(static_cast<float>(norms.size()));
  for (ActorCritic* ac : {expl_.get(), task_.get()}) {
    for (float x : ac->return_normalizer().state()) norms.push_back(x);
  }
  put_section(out, bytes_of(norms));
  // Counters and the RNG: the generator is a plain state of four words.
  static_assert(std::is_trivially_copyable_v<nn::Rng>);
  std::vector<std::uint8_t> rng_bytes(sizeof(nn::Rng));
  std::memcpy(rng_bytes.data(), &rng_, sizeof(nn::Rng));
  put_section(out, rng_bytes);
  put_section(out,
              bytes_of(std::vector<std::int64_t>{train_steps_, task_actor_initialised_ ? 1 : 0}));
  // Added after the first checkpoints were written: loading one without it leaves the
  // continuation head's optimiser fresh.
  put_section(out, cont_opt_->save_state());
  const std::uint32_t crc = indrive::crc32(out.data(), out.size());
  const auto* c = reinterpret_cast<const std::uint8_t*>(&crc);
  out.insert(out.end(), c, c + 4);
  return out;
}

void Agent::save_checkpoint(const std::filesystem::path& path) const {
  try {
    atomic_write(path, checkpoint_bytes());
  } catch (const IoError& error) {
    throw AgentError(std::string("cannot write checkpoint: ") + error.what());
  }
}

void Agent::load_checkpoint(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::ifstream file(path, std::ios::binary);
  if (!file) throw AgentError("cannot open checkpoint " + name + ": check the path");
  const std::vector<std::uint8_t> data((std::istreambuf_iterator<char>(file)),
                                       std::istreambuf_iterator<char>());
  load_checkpoint(data, name);
}

void Agent::load_checkpoint(std::span<const std::uint8_t> data, const std::string& name) {
  if (data.size() < 12 || std::memcmp(data.data(), kMagic, 4) != 0) {
    throw AgentError("file " + name + " is not an agent checkpoint");
  }
  std::uint32_t crc;
  std::memcpy(&crc, data.data() + data.size() - 4, 4);
  if (indrive::crc32(data.data(), data.size() - 4) != crc) {
    throw AgentError("checkpoint " + name + " is corrupt (checksum mismatch)");
  }
  std::uint32_t version;
  std::memcpy(&version, data.data() + 4, 4);
  if (version != kVersion) throw AgentError("checkpoint " + name + " has another format version");
  const std::span<const std::uint8_t> body(data.data() + 8, data.size() - 12);
  SectionReader in(body, name);
  if (values_of<std::int64_t>(in.next()) != architecture(config_)) {
    throw AgentError("checkpoint " + name +
                     " was written by a model of other sizes or another "
                     "intrinsic method; use the same preset and intrinsic.* settings");
  }
  const std::span<const std::uint8_t> params = in.next();
  std::vector<std::span<const std::uint8_t>> opt_states;
  for (std::size_t i = 0; i < optimizers().size(); ++i) opt_states.push_back(in.next());
  const std::vector<float> norms = values_of<float>(in.next());
  const std::span<const std::uint8_t> rng_bytes = in.next();
  const std::vector<std::int64_t> counters = values_of<std::int64_t>(in.next());
  // Absent from checkpoints written before the continuation head had an optimiser of its own.
  const std::span<const std::uint8_t> cont_state =
      in.done() ? std::span<const std::uint8_t>{} : in.next();
  if (!in.done()) throw AgentError("checkpoint " + name + " has trailing sections");
  if (rng_bytes.size() != sizeof(nn::Rng) || counters.size() != 2 || norms.empty()) {
    throw AgentError("checkpoint " + name + " has malformed state sections");
  }
  try {
    std::vector<nn::ParamGroup*> g = groups();
    nn::load_params(params, std::span<nn::ParamGroup* const>(g));
    for (std::size_t i = 0; i < opt_states.size(); ++i) optimizers()[i]->load_state(opt_states[i]);
    if (!cont_state.empty()) cont_opt_->load_state(cont_state);
  } catch (const nn::SerializationError& e) {
    throw AgentError("checkpoint " + name + " does not fit this agent: " + e.what());
  }
  const std::size_t intrinsic_size = intrinsic_->normalizer_state().size();
  if (norms.size() != intrinsic_size + 1 + 4) {
    throw AgentError("checkpoint " + name + " has normaliser state of another size");
  }
  if (intrinsic_size > 0)
    intrinsic_->set_normalizer_state(std::span(norms).subspan(0, intrinsic_size));
  expl_->return_normalizer().set_state(std::span(norms).subspan(intrinsic_size + 1, 2));
  task_->return_normalizer().set_state(std::span(norms).subspan(intrinsic_size + 3, 2));
  std::memcpy(&rng_, rng_bytes.data(), sizeof(nn::Rng));
  train_steps_ = counters[0];
  task_actor_initialised_ = counters[1] != 0;
  // Loading a pretraining checkpoint into a finetune agent starts the task actor from the
  // pretrained exploration actor.
  if (config_.phase == Phase::kFinetune && !task_actor_initialised_) set_phase(Phase::kFinetune);
}

}  // namespace indrive::agent
