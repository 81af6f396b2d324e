// Reading and writing route files (YAML: route name -> {loop, edges} or a point-to-point
// route's {kind, start, end}).
#include <yaml-cpp/yaml.h>

#include <array>
#include <cmath>
#include <fstream>
#include <tuple>

#include "indrive/envserver/routes.h"

namespace indrive::env {

namespace {

// A point written as [x, y] or [x, y, heading in degrees].
Eigen::Vector2d read_point(const YAML::Node& node, const std::string& key,
                           std::optional<double>& heading_rad) {
  if (!node) throw RouteError("needs '" + key + "' as well");
  if (!node.IsSequence() || (node.size() != 2 && node.size() != 3)) {
    throw RouteError("'" + key + "' must be a point [x, y] or [x, y, heading_deg]");
  }
  // Within a million kilometres: any map's coordinates, and no overflow in the lane index.
  std::array<double, 3> values{0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < node.size(); ++i) {
    values[i] = node[i].as<double>();
    if (!std::isfinite(values[i]) || std::abs(values[i]) > 1e9) {
      throw RouteError("'" + key + "' holds '" + node[i].as<std::string>() +
                       "'; give finite coordinates (metres) and a heading in degrees");
    }
  }
  if (node.size() == 3) heading_rad = values[2] * M_PI / 180.0;
  return {values[0], values[1]};
}

}  // namespace

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
      if (!body.IsMap()) throw RouteError("is not a map");
      const bool net_points = body["start"] || body["end"];
      const bool carla_points = body["carla_start"] || body["carla_end"];
      if (net_points && carla_points) {
        throw RouteError("gives both start/end and carla_start/carla_end; give one pair");
      }
      if (net_points || carla_points) {
        const std::string prefix = carla_points ? "carla_" : "";
        spec.start = read_point(body[prefix + "start"], prefix + "start", spec.start_heading_rad);
        spec.end = read_point(body[prefix + "end"], prefix + "end", spec.end_heading_rad);
        spec.frame = carla_points ? PointFrame::kCarla : PointFrame::kNetwork;
        if (body["loop"] && body["loop"].as<bool>()) {
          throw RouteError("is a loop with end points; a loop gives its edges");
        }
      } else if (!body["edges"] || !body["edges"].IsSequence()) {
        throw RouteError("needs an 'edges' list or end points");
      }
      spec.loop = body["loop"] ? body["loop"].as<bool>() : false;
      if (body["kind"]) spec.kind = body["kind"].as<std::string>();
      if (body["edges"]) {
        for (const auto& edge : body["edges"]) spec.edges.push_back(edge.as<std::string>());
        if (spec.edges.empty()) throw RouteError("has an empty 'edges' list");
      }
    } catch (const std::exception& error) {
      throw RouteError("route file '" + path.string() + "': route '" + spec.name + "' " +
                       error.what() +
                       " (expected {loop: bool, edges: [edge ids]} or {kind: label, "
                       "start: [x, y], end: [x, y]}, carla_start / carla_end for CARLA "
                       "coordinates)");
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
    if (!spec.kind.empty()) out << YAML::Key << "kind" << YAML::Value << spec.kind;
    if (spec.start && spec.end) {
      const std::string prefix = spec.frame == PointFrame::kCarla ? "carla_" : "";
      for (const auto& [key, point, heading] :
           {std::tuple{"start", *spec.start, spec.start_heading_rad},
            std::tuple{"end", *spec.end, spec.end_heading_rad}}) {
        out << YAML::Key << prefix + key << YAML::Value << YAML::Flow << YAML::BeginSeq << point.x()
            << point.y();
        if (heading) out << *heading * 180.0 / M_PI;
        out << YAML::EndSeq;
      }
    }
    if (!spec.edges.empty()) out << YAML::Key << "edges" << YAML::Value << YAML::Flow << spec.edges;
    out << YAML::EndMap;
  }
  out << YAML::EndMap;
  std::ofstream file(path);
  file << out.c_str() << "\n";
  if (!file) throw RouteError("cannot write route file '" + path.string() + "'");
}

}  // namespace indrive::env
