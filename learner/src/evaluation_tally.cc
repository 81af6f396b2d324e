#include "indrive/learner/evaluation_tally.h"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace indrive::learner {
namespace {

// Versions kept: a continuous evaluator reports a few versions at a time, and an old version's
// late results must not grow memory without bound over a run of days.
constexpr std::size_t kVersionsKept = 64;

void write_tally(nlohmann::json& record, const std::string& prefix, std::uint64_t episodes,
                 std::uint64_t successes, double completion_sum) {
  const double n = static_cast<double>(episodes);
  record[prefix + "success_rate"] = static_cast<double>(successes) / n;
  record[prefix + "route_completion"] = completion_sum / n;
}

}  // namespace

void EvaluationTally::Tally::add(bool success, double completion) {
  ++episodes;
  successes += success ? 1 : 0;
  completion_sum += completion;
}

std::string EvaluationTally::key_of(const std::string& town) {
  std::string key = town;
  for (char& c : key) {
    if (std::isalnum(static_cast<unsigned char>(c)) == 0) c = '_';
  }
  return key.empty() ? "unnamed" : key;
}

void EvaluationTally::add(const msg::EpisodeResult& result) {
  if (result.failure_reason() == "env_fault") return;  // SUMO failed: nothing of the policy
  const double raw = result.route_completion();
  const double completion = std::isfinite(raw) ? std::clamp(raw, 0.0, 1.0) : 0.0;
  std::lock_guard<std::mutex> lock(mutex_);
  Version& version = versions_[result.policy_version()];
  version.all.add(result.success(), completion);
  version.towns[key_of(result.town())].add(result.success(), completion);
  ++results_;
  newest_ = fresh_ ? std::max(newest_, result.policy_version()) : result.policy_version();
  fresh_ = true;
  while (versions_.size() > kVersionsKept) versions_.erase(versions_.begin());
}

void EvaluationTally::write_new(nlohmann::json& record) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (results_ == 0) return;  // no evaluator took part: no eval_ fields at all
  record["eval_results"] = results_;
  if (!fresh_) return;
  fresh_ = false;
  const auto found = versions_.find(newest_);
  if (found == versions_.end()) return;  // only when > kVersionsKept newer versions exist
  const Version& version = found->second;
  record["eval_policy_version"] = newest_;
  record["eval_episodes"] = version.all.episodes;
  write_tally(record, "eval_", version.all.episodes, version.all.successes,
              version.all.completion_sum);
  for (const auto& [town, tally] : version.towns) {
    write_tally(record, "eval_" + town + "_", tally.episodes, tally.successes,
                tally.completion_sum);
  }
}

}  // namespace indrive::learner
