// Adam with global-norm clipping and warm-up, and EMA copies of parameter groups.
#include "indrive/nn/optim.h"

#include <cmath>
#include <span>
#include <utility>

#include "bytes.h"
#include "indrive/basics/check.h"
#include "indrive/nn/serialize.h"
#include "ops_internal.h"

namespace indrive::nn {

namespace {
// The squared L2 norm of a parameter's gradient, in double, as a vector reduction (Eigen keeps
// several accumulators; a plain loop is one serial chain of adds).
double squared_grad_norm(const Parameter& p) {
  const std::span<const float> g = p.grad();
  return detail::ConstArray(g.data(), static_cast<std::int64_t>(g.size()))
      .cast<double>()
      .square()
      .sum();
}
}  // namespace

float grad_norm(const ParamGroup& group) {
  double total = 0.0;
  for (const auto& p : group.params()) total += squared_grad_norm(*p);
  return static_cast<float>(std::sqrt(total));
}

Adam::Adam(ParamGroup& group, AdamConfig config, std::string_view prefix)
    : group_(group), group_size_(group.params().size()), config_(config) {
  for (const auto& p : group.params()) {
    if (!p->name().starts_with(prefix)) continue;
    params_.push_back(p.get());
    m_.emplace_back(static_cast<std::size_t>(p->numel()), 0.0f);
    v_.emplace_back(static_cast<std::size_t>(p->numel()), 0.0f);
  }
  INDRIVE_CHECK(!params_.empty() || group.params().empty())
      << "no parameter of group '" << group.name() << "' starts with '" << prefix << "'";
}

StepStats Adam::step() {
  INDRIVE_CHECK_EQ(group_size_, group_.params().size()) << "group changed after Adam was created";
  StepStats stats;
  double squared = 0.0;
  for (const Parameter* p : params_) squared += squared_grad_norm(*p);
  stats.grad_norm = static_cast<float>(std::sqrt(squared));
  if (!std::isfinite(stats.grad_norm)) {
    // A numerical fault is counted and skipped, not applied.
    ++skipped_;
    stats.skipped = true;
    for (Parameter* p : params_) p->zero_grad();
    return stats;
  }
  const float clip_scale =
      (config_.clip > 0 && stats.grad_norm > config_.clip) ? config_.clip / stats.grad_norm : 1.0f;
  ++steps_;
  float lr = config_.lr;
  if (config_.warmup > 0)
    lr *= std::min(1.0f, static_cast<float>(steps_) / static_cast<float>(config_.warmup));
  stats.lr = lr;
  const float b1 = config_.beta1, b2 = config_.beta2;
  const float c1 = 1.0f - static_cast<float>(std::pow(b1, static_cast<double>(steps_)));
  const float c2 = 1.0f - static_cast<float>(std::pow(b2, static_cast<double>(steps_)));
  const float step_size = lr / c1;
  const float inv_sqrt_c2 = 1.0f / std::sqrt(c2);
  const float decay = 1.0f - lr * config_.weight_decay;
  for (std::size_t i = 0; i < m_.size(); ++i) {
    Parameter& p = *params_[i];
    float* w = p.value().data();
    float* g = p.grad().data();
    float* m = m_[i].data();
    float* v = v_[i].data();
    // Elementwise, so large parameters are split over the threads (fixed chunks: the result
    // does not depend on the thread count). Written as Eigen array expressions because a plain
    // loop stays scalar: std::sqrt may set errno, so the compiler keeps it out of vector code.
    detail::parallel_for(p.numel(), [&](std::int64_t s, std::int64_t e) {
      const std::int64_t len = e - s;
      detail::Array gs(g + s, len), ms(m + s, len), vs(v + s, len), ws(w + s, len);
      ms = b1 * ms + ((1.0f - b1) * clip_scale) * gs;
      vs = b2 * vs + ((1.0f - b2) * clip_scale * clip_scale) * gs.square();
      ws = ws * decay - step_size * ms / (vs.sqrt() * inv_sqrt_c2 + config_.eps);
      gs.setZero();
    });
  }
  return stats;
}

namespace {
constexpr std::uint32_t kAdamMagic = 0x414e4e49;  // "INNA"
}

std::vector<std::uint8_t> Adam::save_state() const {
  detail::ByteWriter w;
  w.u32(kAdamMagic);
  w.str(group_.name());
  w.i64(steps_);
  w.i64(skipped_);
  w.u32(static_cast<std::uint32_t>(m_.size()));
  for (std::size_t i = 0; i < m_.size(); ++i) {
    w.str(params_[i]->name());
    w.i64(static_cast<std::int64_t>(m_[i].size()));
    w.floats(m_[i]);
    w.floats(v_[i]);
  }
  return w.finish();
}

void Adam::load_state(std::span<const std::uint8_t> blob) {
  detail::ByteReader r(blob, "Adam state of group '" + group_.name() + "'");
  if (r.u32() != kAdamMagic) throw SerializationError(r.what() + ": not an optimiser state");
  const std::string gname = r.str();
  if (gname != group_.name())
    throw SerializationError(r.what() + ": state belongs to group '" + gname + "'");
  const std::int64_t steps = r.i64();
  const std::int64_t skipped = r.i64();
  const std::uint32_t n = r.u32();
  if (n != m_.size())
    throw SerializationError(r.what() + ": " + std::to_string(n) + " parameters, expected " +
                             std::to_string(m_.size()));
  std::vector<std::vector<float>> m(n), v(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::string pname = r.str();
    const Parameter& p = *params_[i];
    if (pname != p.name())
      throw SerializationError(r.what() + ": parameter '" + pname + "' where '" + p.name() +
                               "' was expected");
    const std::int64_t size = r.i64();
    if (size != p.numel())
      throw SerializationError(r.what() + ": '" + pname + "' has " + std::to_string(size) +
                               " values, expected " + std::to_string(p.numel()));
    m[i].resize(size);
    v[i].resize(size);
    r.floats(m[i]);
    r.floats(v[i]);
  }
  if (!r.done()) throw SerializationError(r.what() + ": trailing bytes");
  m_ = std::move(m);
  v_ = std::move(v);
  steps_ = steps;
  skipped_ = skipped;
}

// ---- EMA ----

Ema::Ema(const ParamGroup& source, ParamGroup& target, float rate)
    : source_(source), target_(target), rate_(rate) {
  INDRIVE_CHECK(rate > 0.0f && rate <= 1.0f) << "EMA rate " << rate;
  if (source.params().size() != target.params().size())
    throw SerializationError("EMA: group '" + source.name() + "' has " +
                             std::to_string(source.params().size()) + " parameters, '" +
                             target.name() + "' has " + std::to_string(target.params().size()));
  for (std::size_t i = 0; i < source.params().size(); ++i) {
    const Parameter& s = *source.params()[i];
    const Parameter& t = *target.params()[i];
    if (s.name() != t.name() || s.shape() != t.shape())
      throw SerializationError("EMA: parameter " + std::to_string(i) + " is '" + s.name() + "' " +
                               s.shape().str() + " in '" + source.name() + "' but '" + t.name() +
                               "' " + t.shape().str() + " in '" + target.name() + "'");
  }
}

void Ema::update() {
  for (std::size_t i = 0; i < source_.params().size(); ++i) {
    const auto src = source_.params()[i]->value();
    auto dst = target_.params()[i]->value();
    for (std::size_t j = 0; j < src.size(); ++j) dst[j] += rate_ * (src[j] - dst[j]);
  }
}

void Ema::copy() {
  for (std::size_t i = 0; i < source_.params().size(); ++i) {
    const auto src = source_.params()[i]->value();
    auto dst = target_.params()[i]->value();
    std::copy(src.begin(), src.end(), dst.begin());
  }
}

}  // namespace indrive::nn
