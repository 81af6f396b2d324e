// Reading and writing route files (YAML: route name -> {loop, edges}).
#include <yaml-cpp/yaml.h>

#include <fstream>

#include "indrive/envserver/routes.h"

namespace indrive::env {

std::vector<RouteSpec> read_route_file(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw RouteError("route file '" + path.string() +
                     "' does not exist; built-in towns ship one under envserver/data/routes/");
  }
  YAML::Node root;
  try {
    root = YAML::LoadFile(path.string());
  } catch (const YAML::Exception& error) {
    throw RouteError("route file '" + path.string() + "' is not valid YAML: " + error.what());
  }
  if (!root.IsMap()) {
    throw RouteError("route file '" + path.string() +
                     "' must map route names to {loop: bool, edges: [edge ids]}");
  }
  std::vector<RouteSpec> specs;
  for (const auto& entry : root) {
    RouteSpec spec;
    // YAML allows lists and maps as keys ("? [a, b]: ..."); a route name is plain text.
    if (!entry.first.IsScalar()) {
      throw RouteError("route file '" + path.string() + "': line " +
                       std::to_string(entry.first.Mark().line + 1) +
                       ": a route name must be plain text (straight, right_loop, ...)");
    }
    spec.name = entry.first.as<std::string>();
    const YAML::Node& body = entry.second;
    try {
      if (!body.IsMap() || !body["edges"] || !body["edges"].IsSequence()) {
        throw RouteError("needs an 'edges' list");
      }
      spec.loop = body["loop"] ? body["loop"].as<bool>() : false;
      for (const auto& edge : body["edges"]) spec.edges.push_back(edge.as<std::string>());
      if (spec.edges.empty()) throw RouteError("has an empty 'edges' list");
    } catch (const std::exception& error) {
      throw RouteError("route file '" + path.string() + "': route '" + spec.name + "' " +
                       error.what() + " (expected {loop: bool, edges: [edge ids]})");
    }
    specs.push_back(std::move(spec));
  }
  return specs;
}

void write_route_file(const std::filesystem::path& path, const std::vector<RouteSpec>& specs) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  for (const RouteSpec& spec : specs) {
    out << YAML::Key << spec.name << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "loop" << YAML::Value << spec.loop;
    out << YAML::Key << "edges" << YAML::Value << YAML::Flow << spec.edges;
    out << YAML::EndMap;
  }
  out << YAML::EndMap;
  std::ofstream file(path);
  file << out.c_str() << "\n";
  if (!file) throw RouteError("cannot write route file '" + path.string() + "'");
}

}  // namespace indrive::env
