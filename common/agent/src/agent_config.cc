#include "indrive/agent/agent_config.h"

#include <charconv>
#include <functional>
#include <sstream>

namespace indrive::agent {
namespace {

// One settable key: how to read it as text and how to set it from text.
struct Key {
  std::string name;
  std::function<std::string(const AgentConfig&)> get;
  std::function<void(AgentConfig&, std::string_view)> set;
};

template <typename T>
T parse_number(std::string_view key, std::string_view text) {
  T value{};
  // from_chars for floats is available in GCC 11+; trailing garbage is an error.
  auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size()) {
    throw AgentConfigError("config key '" + std::string(key) + "': cannot parse '" +
                           std::string(text) + "' as a number");
  }
  return value;
}

bool parse_bool(std::string_view key, std::string_view text) {
  if (text == "true" || text == "1") return true;
  if (text == "false" || text == "0") return false;
  throw AgentConfigError("config key '" + std::string(key) + "': expected true or false, got '" +
                         std::string(text) + "'");
}

template <typename T>
std::string number_text(T value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

#define INDRIVE_NUMBER_KEY(name, member)                                      \
  Key {                                                                       \
    name, [](const AgentConfig& c) { return number_text(c.member); },         \
        [](AgentConfig& c, std::string_view v) {                              \
          c.member = parse_number<std::decay_t<decltype(c.member)>>(name, v); \
        }                                                                     \
  }

const std::vector<Key>& keys() {
  static const std::vector<Key> table = {
      Key{"preset", [](const AgentConfig& c) { return c.preset; },
          [](AgentConfig& c, std::string_view v) { c.preset = std::string(v); }},
      Key{"phase", [](const AgentConfig& c) { return std::string(to_string(c.phase)); },
          [](AgentConfig& c, std::string_view v) { c.phase = parse_phase(v); }},
      Key{"task", [](const AgentConfig& c) { return c.task; },
          [](AgentConfig& c, std::string_view v) { c.task = std::string(v); }},
      Key{"eval_sample",
          [](const AgentConfig& c) { return std::string(c.eval_sample ? "true" : "false"); },
          [](AgentConfig& c, std::string_view v) { c.eval_sample = parse_bool("eval_sample", v); }},
      Key{"precision", [](const AgentConfig& c) { return c.precision; },
          [](AgentConfig& c, std::string_view v) { c.precision = std::string(v); }},
      Key{"backward_parts",
          [](const AgentConfig& c) { return std::string(c.backward_parts ? "true" : "false"); },
          [](AgentConfig& c, std::string_view v) {
            c.backward_parts = parse_bool("backward_parts", v);
          }},
      Key{"finetune_cont",
          [](const AgentConfig& c) { return std::string(c.finetune_cont ? "true" : "false"); },
          [](AgentConfig& c, std::string_view v) {
            c.finetune_cont = parse_bool("finetune_cont", v);
          }},
      Key{"finetune_world_model",
          [](const AgentConfig& c) {
            return std::string(c.finetune_world_model ? "true" : "false");
          },
          [](AgentConfig& c, std::string_view v) {
            c.finetune_world_model = parse_bool("finetune_world_model", v);
          }},
      INDRIVE_NUMBER_KEY("seed", seed),
      INDRIVE_NUMBER_KEY("world_model.image", world_model.image),
      INDRIVE_NUMBER_KEY("world_model.channels", world_model.channels),
      INDRIVE_NUMBER_KEY("world_model.cnn_depth", world_model.cnn_depth),
      INDRIVE_NUMBER_KEY("world_model.deter", world_model.deter),
      INDRIVE_NUMBER_KEY("world_model.units", world_model.units),
      INDRIVE_NUMBER_KEY("world_model.stoch", world_model.stoch),
      INDRIVE_NUMBER_KEY("world_model.classes", world_model.classes),
      INDRIVE_NUMBER_KEY("world_model.head_layers", world_model.head_layers),
      INDRIVE_NUMBER_KEY("world_model.unimix", world_model.unimix),
      INDRIVE_NUMBER_KEY("world_model.kl_dyn", world_model.kl_dyn),
      INDRIVE_NUMBER_KEY("world_model.kl_rep", world_model.kl_rep),
      INDRIVE_NUMBER_KEY("world_model.free_nats", world_model.free_nats),
      INDRIVE_NUMBER_KEY("world_model.recon_scale", world_model.recon_scale),
      INDRIVE_NUMBER_KEY("world_model.cont_scale", world_model.cont_scale),
      INDRIVE_NUMBER_KEY("world_model.reward_scale", world_model.reward_scale),
      INDRIVE_NUMBER_KEY("world_model.lr", world_model.lr),
      INDRIVE_NUMBER_KEY("world_model.eps", world_model.eps),
      INDRIVE_NUMBER_KEY("world_model.clip", world_model.clip),
      Key{"intrinsic.method",
          [](const AgentConfig& c) { return std::string(to_string(c.intrinsic.method)); },
          [](AgentConfig& c, std::string_view v) { c.intrinsic.method = parse_method(v); }},
      INDRIVE_NUMBER_KEY("intrinsic.ensemble", intrinsic.ensemble),
      Key{"intrinsic.disag_reward",
          [](const AgentConfig& c) { return std::string(to_string(c.intrinsic.disag_reward)); },
          [](AgentConfig& c, std::string_view v) {
            if (v == "variance") {
              c.intrinsic.disag_reward = DisagReward::kVariance;
            } else if (v == "std") {
              c.intrinsic.disag_reward = DisagReward::kStd;
            } else {
              throw AgentConfigError(
                  "config key 'intrinsic.disag_reward': expected variance or std, got '" +
                  std::string(v) + "'");
            }
          }},
      INDRIVE_NUMBER_KEY("intrinsic.units", intrinsic.units),
      INDRIVE_NUMBER_KEY("intrinsic.layers", intrinsic.layers),
      INDRIVE_NUMBER_KEY("intrinsic.rnd_embed", intrinsic.rnd_embed),
      INDRIVE_NUMBER_KEY("intrinsic.disag_scale", intrinsic.disag_scale),
      INDRIVE_NUMBER_KEY("intrinsic.icm_scale", intrinsic.icm_scale),
      INDRIVE_NUMBER_KEY("intrinsic.rnd_scale", intrinsic.rnd_scale),
      INDRIVE_NUMBER_KEY("intrinsic.icm_eta", intrinsic.icm_eta),
      INDRIVE_NUMBER_KEY("intrinsic.icm_inverse_scale", intrinsic.icm_inverse_scale),
      INDRIVE_NUMBER_KEY("intrinsic.norm_rate", intrinsic.norm_rate),
      INDRIVE_NUMBER_KEY("intrinsic.norm_eps", intrinsic.norm_eps),
      INDRIVE_NUMBER_KEY("intrinsic.lr", intrinsic.lr),
      INDRIVE_NUMBER_KEY("intrinsic.eps", intrinsic.eps),
      INDRIVE_NUMBER_KEY("intrinsic.clip", intrinsic.clip),
      INDRIVE_NUMBER_KEY("behavior.horizon", behavior.horizon),
      INDRIVE_NUMBER_KEY("behavior.gamma", behavior.gamma),
      INDRIVE_NUMBER_KEY("behavior.lambda", behavior.lambda),
      INDRIVE_NUMBER_KEY("behavior.units", behavior.units),
      INDRIVE_NUMBER_KEY("behavior.layers", behavior.layers),
      INDRIVE_NUMBER_KEY("behavior.actor_unimix", behavior.actor_unimix),
      INDRIVE_NUMBER_KEY("behavior.entropy", behavior.entropy),
      INDRIVE_NUMBER_KEY("behavior.slow_critic_rate", behavior.slow_critic_rate),
      INDRIVE_NUMBER_KEY("behavior.slow_critic_reg", behavior.slow_critic_reg),
      INDRIVE_NUMBER_KEY("behavior.return_low", behavior.return_low),
      INDRIVE_NUMBER_KEY("behavior.return_high", behavior.return_high),
      INDRIVE_NUMBER_KEY("behavior.return_decay", behavior.return_decay),
      INDRIVE_NUMBER_KEY("behavior.return_floor", behavior.return_floor),
      INDRIVE_NUMBER_KEY("behavior.actor_lr", behavior.actor_lr),
      INDRIVE_NUMBER_KEY("behavior.critic_lr", behavior.critic_lr),
      INDRIVE_NUMBER_KEY("behavior.eps", behavior.eps),
      INDRIVE_NUMBER_KEY("behavior.clip", behavior.clip),
      INDRIVE_NUMBER_KEY("replay.capacity", replay.capacity),
      INDRIVE_NUMBER_KEY("replay.batch", replay.batch),
      INDRIVE_NUMBER_KEY("replay.length", replay.length),
      INDRIVE_NUMBER_KEY("replay.prefill", replay.prefill),
      INDRIVE_NUMBER_KEY("replay.seed", replay.seed),
  };
  return table;
}

#undef INDRIVE_NUMBER_KEY

void require(bool ok, const std::string& message) {
  if (!ok) throw AgentConfigError("invalid agent config: " + message);
}

bool in_unit_interval(float x) { return x > 0.0f && x <= 1.0f; }

}  // namespace

AgentConfig preset(std::string_view name) {
  AgentConfig config;
  config.preset = std::string(name);
  WorldModelConfig& wm = config.world_model;
  int units = 0;
  if (name == "tiny") {
    wm.image = 32, wm.cnn_depth = 8, wm.deter = 128, units = 128, wm.stoch = 16, wm.classes = 16;
    config.replay.batch = 8, config.replay.length = 16;
    config.backward_parts = true;
  } else if (name == "cpu") {
    wm.image = 64, wm.cnn_depth = 16, wm.deter = 256, units = 256, wm.stoch = 32, wm.classes = 32;
    config.replay.batch = 16, config.replay.length = 64;
  } else if (name == "small") {
    wm.image = 128, wm.cnn_depth = 32, wm.deter = 512, units = 512, wm.stoch = 32, wm.classes = 32;
    config.replay.batch = 16, config.replay.length = 64;
  } else {
    throw AgentConfigError("unknown agent preset '" + std::string(name) +
                           "': use one of tiny, cpu, small");
  }
  wm.units = units;
  config.intrinsic.units = units;
  config.intrinsic.rnd_embed = units;
  config.behavior.units = units;
  return config;
}

void set_config_value(AgentConfig& config, std::string_view key, std::string_view value) {
  for (const Key& entry : keys()) {
    if (entry.name == key) {
      entry.set(config, value);
      return;
    }
  }
  throw AgentConfigError("unknown agent config key '" + std::string(key) +
                         "'; see config_values() for the list of keys");
}

std::vector<std::pair<std::string, std::string>> config_values(const AgentConfig& config) {
  std::vector<std::pair<std::string, std::string>> out;
  for (const Key& entry : keys()) out.emplace_back(entry.name, entry.get(config));
  return out;
}

void validate(const AgentConfig& config) {
  require(config.precision == "auto" || config.precision == "fp32" || config.precision == "bf16",
          "precision must be auto, fp32 or bf16, got '" + config.precision + "'");
  const WorldModelConfig& wm = config.world_model;
  require(wm.image >= 8 && (wm.image & (wm.image - 1)) == 0,
          "world_model.image must be a power of two >= 8, got " + std::to_string(wm.image));
  require(wm.channels > 0 && wm.cnn_depth > 0 && wm.deter > 0 && wm.units > 0 && wm.stoch > 0 &&
              wm.classes > 1 && wm.head_layers >= 0,
          "world_model sizes must be positive (classes >= 2)");
  require(wm.unimix >= 0.0f && wm.unimix < 1.0f, "world_model.unimix must be in [0, 1)");
  require(wm.free_nats >= 0.0f, "world_model.free_nats must be >= 0");
  const IntrinsicConfig& in = config.intrinsic;
  require(in.ensemble >= 2, "intrinsic.ensemble must be >= 2 to measure disagreement");
  require(in.units > 0 && in.layers >= 0 && in.rnd_embed > 0, "intrinsic sizes must be positive");
  require(in.method != Method::kDisag || in.layers >= 1,
          "intrinsic.layers must be >= 1 for disag: the ensemble members share their first "
          "hidden layer's product");
  require(in_unit_interval(in.norm_rate), "intrinsic.norm_rate must be in (0, 1]");
  require(in.norm_eps > 0.0f, "intrinsic.norm_eps must be > 0");
  require(in.disag_scale > 0.0f && in.icm_scale > 0.0f && in.rnd_scale > 0.0f,
          "intrinsic.disag_scale, icm_scale and rnd_scale must be > 0");
  const BehaviorConfig& b = config.behavior;
  require(b.horizon >= 1, "behavior.horizon must be >= 1");
  require(in_unit_interval(b.gamma) && b.lambda >= 0.0f && b.lambda <= 1.0f,
          "behavior.gamma must be in (0, 1] and behavior.lambda in [0, 1]");
  require(b.return_low >= 0.0f && b.return_low < b.return_high && b.return_high <= 1.0f,
          "behavior.return_low < behavior.return_high, both in [0, 1]");
  require(in_unit_interval(b.slow_critic_rate), "behavior.slow_critic_rate must be in (0, 1]");
  require(!(config.finetune_cont && config.finetune_world_model),
          "finetune_world_model already trains the continuation head with the rest of the world "
          "model: set finetune_cont to false");
  const ReplayConfig& r = config.replay;
  require(r.batch >= 1, "replay.batch must be >= 1, got " + std::to_string(r.batch));
  require(r.length >= 2, "replay.length must be >= 2, got " + std::to_string(r.length));
  require(r.capacity >= r.length, "replay.capacity must hold at least one sequence");
}

std::string_view to_string(Phase phase) {
  switch (phase) {
    case Phase::kPretrain:
      return "pretrain";
    case Phase::kFinetune:
      return "finetune";
    case Phase::kDreamer:
      return "dreamer";
  }
  return "?";
}

std::string method_label(const AgentConfig& config) {
  return config.phase == Phase::kDreamer ? "dreamer"
                                         : std::string(to_string(config.intrinsic.method));
}

std::string task_label(const AgentConfig& config) {
  return config.phase == Phase::kPretrain ? "exploration" : config.task;
}

std::string_view to_string(Method method) {
  switch (method) {
    case Method::kDisag:
      return "disag";
    case Method::kIcm:
      return "icm";
    case Method::kRnd:
      return "rnd";
  }
  return "?";
}

std::string_view to_string(DisagReward reward) {
  return reward == DisagReward::kVariance ? "variance" : "std";
}

Phase parse_phase(std::string_view text) {
  if (text == "pretrain") return Phase::kPretrain;
  if (text == "finetune") return Phase::kFinetune;
  if (text == "dreamer") return Phase::kDreamer;
  throw AgentConfigError("unknown phase '" + std::string(text) +
                         "': use pretrain, finetune or dreamer");
}

Method parse_method(std::string_view text) {
  if (text == "disag") return Method::kDisag;
  if (text == "icm") return Method::kIcm;
  if (text == "rnd") return Method::kRnd;
  throw AgentConfigError("unknown intrinsic method '" + std::string(text) +
                         "': use disag, icm or rnd");
}

}  // namespace indrive::agent
