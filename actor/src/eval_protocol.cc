#include "indrive/actor/eval_protocol.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <set>
#include <stdexcept>

namespace indrive::actor {
namespace {

template <typename T>
void require_unique(const std::vector<T>& values, const std::string& what) {
  if (values.empty()) throw std::invalid_argument("evaluation " + what + " list is empty");
  if (std::set<T>(values.begin(), values.end()).size() != values.size()) {
    throw std::invalid_argument("evaluation " + what + " list has a duplicate");
  }
}

}  // namespace

const char* protocol_name(EvalProtocol protocol) {
  return protocol == EvalProtocol::kIndriveCode ? "indrive_code" : "strict";
}

EvalProtocol parse_protocol(const std::string& name) {
  if (name == "strict") return EvalProtocol::kStrict;
  if (name == "indrive_code") return EvalProtocol::kIndriveCode;
  throw EvalError("unknown evaluation protocol '" + name +
                  "'; give strict (ours) or indrive_code (the public InDRiVE code's rules)");
}

const std::vector<std::string>& ProtocolGrid::routes_of(const std::string& town) const {
  const auto it = town_routes.find(town);
  return it != town_routes.end() ? it->second : routes;
}

void ProtocolGrid::validate() const {
  require_unique(towns, "towns");
  require_unique(routes, "routes");
  for (const auto& [town, names] : town_routes) require_unique(names, town + " routes");
  require_unique(densities, "densities");
  for (const int density : densities) {
    if (density != 5 && density != 10 && density != 20) {
      throw std::invalid_argument("evaluation density " + std::to_string(density) +
                                  " is not allowed; use 5, 10 or 20 vehicles within 150 m");
    }
  }
  if (episodes_per_cell < 1) {
    throw std::invalid_argument("evaluation episodes per cell must be at least 1, got " +
                                std::to_string(episodes_per_cell));
  }
}

int ProtocolGrid::size() const {
  std::size_t cells = 0;
  for (const auto& town : towns) cells += routes_of(town).size() * densities.size();
  return static_cast<int>(cells) * episodes_per_cell;
}

std::vector<EpisodeSpec> ProtocolGrid::all_episodes() const {
  validate();
  std::vector<EpisodeSpec> episodes;
  episodes.reserve(static_cast<std::size_t>(size()));
  for (const auto& town : towns) {
    for (const auto& route : routes_of(town)) {
      for (const int density : densities) {
        for (int i = 0; i < episodes_per_cell; ++i) {
          episodes.push_back({.town = town,
                              .route = route,
                              .density = density,
                              .episode = i,
                              .traffic_seed = kTrafficSeeds[i % kTrafficSeeds.size()],
                              .spawn_seed = kSpawnSeeds[i % kSpawnSeeds.size()],
                              .policy_seed = static_cast<std::uint64_t>(i),
                              .global_index = static_cast<int>(episodes.size())});
        }
      }
    }
  }
  return episodes;
}

std::vector<EpisodeSpec> ProtocolGrid::episodes_for(int index, int count) const {
  if (count < 1 || index < 0 || index >= count) {
    throw std::invalid_argument("evaluator " + std::to_string(index) + " of " +
                                std::to_string(count) + " does not exist; use 0 <= id < count");
  }
  std::vector<EpisodeSpec> mine;
  for (auto& episode : all_episodes()) {
    if (episode.global_index % count == index) mine.push_back(std::move(episode));
  }
  return mine;
}

std::string town_file_label(const std::string& town) {
  std::string label = std::filesystem::path(town).stem().string();
  if (label.empty()) label = town;
  for (char& c : label) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-') c = '_';
  }
  return label.empty() ? "town" : label;
}

}  // namespace indrive::actor
