// Hyperparameters of the agent: world model, intrinsic modules, actor-critic, replay, phases.
//
// Every default is the value of the InDRiVE paper (or DreamerV3 v1 where the paper is silent);
// the presets `tiny`, `cpu` and `small` only change sizes (ARCHITECTURE.md section 6).
//
//   AgentConfig config = preset("cpu");
//   set_config_value(config, "intrinsic.method", "icm");
//   set_config_value(config, "behavior.horizon", "15");
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace indrive::agent {

// A configuration that cannot be used: unknown preset or key, unparsable or out-of-range value.
class AgentConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Number of discrete actions: steer {-0.3, 0, +0.3} x throttle {0.0, 0.2, 0.3}.
inline constexpr int kNumActions = 9;

// The training phase decides which parts train and which data the learner keeps.
enum class Phase {
  kPretrain,  // reward-free: world model + intrinsic module + exploration actor-critic
  kFinetune,  // world model, intrinsic module, exploration policy frozen; reward head + task AC
  kDreamer,   // from scratch on the task reward: world model + reward head + task AC
};

// The intrinsic reward of the pretraining phase.
enum class Method {
  kDisag,  // latent ensemble disagreement (InDRiVE)
  kIcm,    // intrinsic curiosity module
  kRnd,    // random network distillation
};

// How the ensemble's disagreement becomes a reward.
enum class DisagReward {
  kVariance,  // mean over latent dims of the variance across members (the paper's formula)
  kStd,       // mean of the standard deviation (the public code)
};

// World model (DreamerV3 v1 layout).
struct WorldModelConfig {
  int image = 64;          // square image side in pixels
  int channels = 3;        // RGB
  int cnn_depth = 16;      // channels of the first encoder conv, doubled per halving
  int deter = 256;         // GRU state size
  int units = 256;         // hidden units of the RSSM MLPs and the heads
  int stoch = 32;          // number of categorical latents
  int classes = 32;        // classes per categorical latent
  int head_layers = 2;     // hidden layers of the continuation and reward heads
  float unimix = 0.01f;    // uniform mix of the latent categoricals
  float kl_dyn = 0.5f;     // weight of KL(sg(post) || prior)
  float kl_rep = 0.1f;     // weight of KL(post || sg(prior))
  float free_nats = 1.0f;  // free bits, on the KL summed over the latents
  float recon_scale = 1.0f;
  float cont_scale = 1.0f;
  float reward_scale = 1.0f;
  float lr = 1e-4f;
  float eps = 1e-8f;
  float clip = 1000.0f;

  // Size of the stochastic state, stoch * classes.
  int stoch_dim() const { return stoch * classes; }
  // Size of u_t = [h_t; s_t].
  int feat_dim() const { return deter + stoch * classes; }
};

// Intrinsic modules (all trained on u_t with stop-gradient into the world model).
struct IntrinsicConfig {
  Method method = Method::kDisag;
  int ensemble = 8;  // K predictors of the LD ensemble
  DisagReward disag_reward = DisagReward::kVariance;
  int units = 256;      // hidden units of every intrinsic MLP
  int layers = 2;       // hidden layers of every intrinsic MLP
  int rnd_embed = 256;  // output size of the RND target/predictor
  // Scale of each module's raw signal before anything else is applied to it (LD: the reward
  // is disag_scale * mean variance; ICM and RND: Norm(scale * error)). One rule sets all three
  // (docs/decisions.md "Intrinsic reward scale"): the raw signal must reach the actor-critic
  // at order 1, above the return normaliser's floor and wider than a two-hot bin. LD's 1e4 is
  // Plan2Explore's intrinsic_reward_scale; ICM's and RND's come from the same rule, measured.
  float disag_scale = 1e4f;
  float icm_scale = 10.0f;
  float rnd_scale = 10.0f;
  float icm_eta = 1.0f;            // ICM reward scale
  float icm_inverse_scale = 1.0f;  // weight of the ICM inverse loss
  float norm_rate = 0.01f;         // rho of the EMA mean/variance normaliser
  float norm_eps = 1.0f;           // eps of Norm(g) = (g - mu) / (sigma + eps)
  float lr = 1e-4f;
  float eps = 1e-6f;
  float clip = 100.0f;
};

// Actor-critic in imagination.
struct BehaviorConfig {
  int horizon = 15;
  float gamma = 0.99f;
  float lambda = 0.95f;
  int units = 256;
  int layers = 2;
  float actor_unimix = 0.01f;
  float entropy = 3e-4f;
  float slow_critic_rate = 0.02f;  // EMA rate of the slow critic
  float slow_critic_reg = 1.0f;    // weight of the regulariser towards the slow critic
  float return_low = 0.05f;        // percentiles of the return normaliser
  float return_high = 0.95f;
  float return_decay = 0.99f;
  float return_floor = 1.0f;  // the scale is max(floor, high - low)
  float actor_lr = 3e-5f;
  float critic_lr = 3e-5f;
  float eps = 1e-5f;
  float clip = 100.0f;
};

// Replay and batching.
struct ReplayConfig {
  std::int64_t capacity = 100000;  // steps
  int batch = 16;
  int length = 64;
  std::int64_t prefill = 1000;  // random steps before training
  std::uint64_t seed = 0;
};

// Everything the learner and the acting policy need.
struct AgentConfig {
  std::string preset = "cpu";
  Phase phase = Phase::kPretrain;
  std::string task = "lane_following";
  WorldModelConfig world_model;
  IntrinsicConfig intrinsic;
  BehaviorConfig behavior;
  ReplayConfig replay;
  // Evaluation samples from the actor, as DreamerV3 evaluates (its policy in eval mode samples
  // the task actor); false takes the most likely action.
  bool eval_sample = true;
  // Operands of the matrix products: "auto" (bf16 where the CPU multiplies it natively, AMX or
  // AVX512_BF16, and the agent's update measures faster in it; else fp32; precision_choice.h),
  // "fp32" or "bf16". Parameters, optimiser state and every other op
  // stay fp32 (nn/kernels.h). Process-wide: an Agent applies it when it is made.
  std::string precision = "auto";
  // The backward pass of an update runs its independent parts (world model, intrinsic module,
  // actor-critic) side by side, one thread each (true), or one after another with each op split
  // over the threads (false). Gradients are bitwise the same either way with one thread; which
  // is faster depends on the sizes, measured per preset (docs/performance.md): true
  // for tiny, false for cpu and small.
  bool backward_parts = false;
  // Few-shot (finetune) also trains the world model's continuation head, on stop-gradient
  // features like the reward head, so that imagination learns where the task's episodes end
  // (leaving the route, reaching the destination: events pretraining never has). The paper
  // and the project's contract keep the whole world model frozen (false); an ablation
  // (docs/decisions.md).
  bool finetune_cont = false;
  // Few-shot also trains the whole world model (representation, dynamics, decoder and heads)
  // on the task's replay, as DreamerV3 from scratch does, from the pretrained weights; the paper
  // and the project's contract keep it frozen (false). An ablation of whether the frozen
  // model's pretraining coverage limits few-shot (docs/decisions.md). Includes the
  // continuation head, so it excludes finetune_cont.
  bool finetune_world_model = false;
  std::uint64_t seed = 0;
};

// The paper's defaults with the sizes of a preset ("tiny", "cpu" or "small"); throws
// AgentConfigError for any other name.
AgentConfig preset(std::string_view name);

// Sets one key such as "world_model.deter" or "phase" from its text form; throws
// AgentConfigError naming the key when the key is unknown or the value does not parse.
void set_config_value(AgentConfig& config, std::string_view key, std::string_view value);

// Every settable key with its current value as text, in a stable order (for the resolved
// config that a run saves).
std::vector<std::pair<std::string, std::string>> config_values(const AgentConfig& config);

// Checks sizes and ranges (image a power of two >= 8, positive sizes, rates in (0, 1]); throws
// AgentConfigError with the first problem.
void validate(const AgentConfig& config);

// Text names of the enums, as used in config files.
std::string_view to_string(Phase phase);
std::string_view to_string(Method method);
std::string_view to_string(DisagReward reward);
// The method a run trains, as results files name it: "dreamer" in the DreamerV3 phase (no
// intrinsic module), else the intrinsic module's name (disag, icm, rnd).
std::string method_label(const AgentConfig& config);
// The task a run's policy serves, as results files name it: "exploration" in pretraining, else
// the task (lane_following, collision_avoidance).
std::string task_label(const AgentConfig& config);
// Parses the text names; throw AgentConfigError listing the valid names.
Phase parse_phase(std::string_view text);
Method parse_method(std::string_view text);

}  // namespace indrive::agent
