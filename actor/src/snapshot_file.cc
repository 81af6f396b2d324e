#include "indrive/actor/snapshot_file.h"

#include <algorithm>
#include <filesystem>

#include "indrive/basics/run_dir.h"
#include "text.h"

namespace indrive::actor {

PolicyHead resolve_head(const std::string& head, const std::string& eval_kind) {
  if (head == "exploration") return PolicyHead::kExploration;
  if (head == "task") return PolicyHead::kTask;
  if (head == "auto") {
    if (eval_kind == "zero_shot") return PolicyHead::kExploration;
    if (eval_kind == "few_shot") return PolicyHead::kTask;
    throw EvalError("evaluation kind '" + eval_kind +
                    "' does not choose a head; use zero_shot or few_shot, or set eval.head");
  }
  throw EvalError("unknown policy head '" + head + "'; use exploration, task or auto");
}

const char* head_group(PolicyHead head) {
  return agent::acting_actor_group(head == PolicyHead::kExploration ? agent::Phase::kPretrain
                                                                    : agent::Phase::kFinetune);
}

std::filesystem::path snapshot_file_path(const std::filesystem::path& given) {
  std::error_code error;
  if (!std::filesystem::is_directory(given, error)) return given;
  const std::filesystem::path final_snapshot = final_snapshot_path(given);
  if (std::filesystem::is_regular_file(final_snapshot, error)) return final_snapshot;
  throw EvalError("--snapshot " + given.string() +
                  " is a directory without a final-snapshot.params (a run's learner writes it "
                  "when the run ends); name a snapshot file: a run's final-snapshot.params, or "
                  "<run>/eval/snapshot-v<N>.params written by an evaluator");
}

void check_snapshot_head(std::span<const std::uint8_t> blob, PolicyHead head,
                         const std::string& source) {
  std::vector<std::string> groups;
  try {
    groups = agent::snapshot_groups(blob);
  } catch (const agent::SnapshotFileError& error) {
    throw EvalError(source + ": " + error.what());
  }
  const std::string wanted = head_group(head);
  if (std::find(groups.begin(), groups.end(), wanted) != groups.end()) return;
  const bool few_shot = head == PolicyHead::kTask;
  throw EvalError(
      source + " holds the groups [" + join(groups) + "] but not " + wanted + ", the " +
      (few_shot ? "task" : "exploration") + " policy head that " +
      (few_shot ? "few-shot" : "zero-shot") + " evaluation runs; " +
      (few_shot ? "evaluate a finetune (or dreamer) snapshot, or use eval.kind=zero_shot / "
                  "eval.head=exploration"
                : "evaluate a pretraining snapshot, or use eval.kind=few_shot / eval.head=task"));
}

std::string adopt_snapshot_architecture(agent::AgentConfig& config, const agent::SnapshotFile& file,
                                        const std::map<std::string, std::string>& chosen,
                                        const std::string& source) {
  if (file.format == 0) return "";
  const auto preset_choice = chosen.find("preset");
  std::vector<std::string> conflicts;
  std::vector<std::string> undo;  // where the conflicting sizes were chosen, each once
  std::vector<std::string> taken;
  std::string file_sizes;
  for (const std::string& key : agent::snapshot_architecture_keys()) {
    if (!agent::is_snapshot_size_key(key)) continue;
    const std::string wanted = file.value(key);
    file_sizes += (file_sizes.empty() ? "" : " ") + key + "=" + wanted;
    const auto choice = chosen.find(key);
    const std::string have = agent::snapshot_key_text(config, key);
    if (choice == chosen.end() && preset_choice == chosen.end()) {
      if (have != wanted) agent::set_config_value(config, key, wanted);
      taken.push_back(key + "=" + wanted);
      continue;
    }
    if (have == wanted) continue;
    // A size the preset set is undone by not choosing the preset.
    std::string where = choice != chosen.end() ? choice->second : "preset " + config.preset;
    std::string culprit = where;
    if (preset_choice != chosen.end() &&
        (choice == chosen.end() || where.starts_with("preset '"))) {
      culprit = preset_choice->second;
      if (choice == chosen.end()) where = "preset " + config.preset + " from " + culprit;
    }
    conflicts.push_back(key + "=" + have + " (" + where + ") where the file has " + wanted);
    if (!culprit.starts_with("--set")) culprit = "the setting at " + culprit;
    if (std::find(undo.begin(), undo.end(), culprit) == undo.end()) undo.push_back(culprit);
  }
  const std::string file_preset = file.value("preset");
  if (!conflicts.empty()) {
    throw EvalError(source + " was trained with preset " + file_preset + " (" + file_sizes +
                    "), but the configuration sets " + join(conflicts, "; ") +
                    "; the file decides the model's shapes: drop " + join(undo, " and ") +
                    " to take the sizes from the file, or set them to the file's values");
  }
  std::string note = source + ": architecture from the file's header";
  if (preset_choice == chosen.end()) {
    config.preset = file_preset;
    note += ", preset " + file_preset;
  } else {
    note += ", preset " + config.preset + " as configured";
    if (config.preset != file_preset) note += " (the file's is " + file_preset + ")";
  }
  if (!chosen.contains("phase")) {
    config.phase = agent::parse_phase(file.value("phase"));
    note += ", phase " + file.value("phase");
  }
  note += taken.empty() ? ", every size as configured"
                        : ", sizes taken from the file: " + join(taken, " ");
  return note;
}
}  // namespace indrive::actor
