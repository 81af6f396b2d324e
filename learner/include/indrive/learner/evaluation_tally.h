// Evaluators' EpisodeResults in the learner's metrics.
//
// An evaluator (possibly on another host) publishes one EpisodeResult per protocol episode.
// The learner keeps, per policy version, the episodes, successes and route completion, overall
// and per town, and puts the newest version's tally on its next metrics line, so that
// metrics.jsonl shows evaluation SR over env steps wherever the evaluators ran:
//
//   eval_policy_version  the newest snapshot version that got a result since the last line
//   eval_episodes        episodes of that version so far (all evaluators together)
//   eval_success_rate    their success rate, eval_route_completion their mean route completion
//   eval_<town>_success_rate, eval_<town>_route_completion   the same per town
//   eval_results         every evaluator result received so far (on every line once one came)
//
// Only results that arrive while the learner runs are logged: a final evaluation after the
// learner has exited is in the evaluator's eval/*.csv alone. Thread-safe.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>

#include "indrive/dds/messages.h"

namespace indrive::learner {

class EvaluationTally {
 public:
  void add(const msg::EpisodeResult& result);
  // Adds the fields above to `record` when a result arrived since the previous call.
  void write_new(nlohmann::json& record);

  // A town as part of a metrics key: letters, digits and '_' only ("maps/x.xodr" -> "maps_x_xodr").
  static std::string key_of(const std::string& town);

 private:
  struct Tally {
    std::uint64_t episodes = 0, successes = 0;
    double completion_sum = 0.0;
    void add(bool success, double completion);
  };
  struct Version {
    Tally all;
    std::map<std::string, Tally> towns;
  };
  mutable std::mutex mutex_;
  std::map<std::uint64_t, Version> versions_;
  std::uint64_t results_ = 0;
  bool fresh_ = false;        // a result arrived since the last write_new
  std::uint64_t newest_ = 0;  // the newest version that got a result since then
};

}  // namespace indrive::learner
