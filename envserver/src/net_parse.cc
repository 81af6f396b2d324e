// Parsing of SUMO .net.xml files into a RoadNetwork.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <pugixml.hpp>
#include <sstream>
#include <string>

#include "indrive/basics/check.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/net_geometry.h"

namespace indrive::env {

namespace {

[[noreturn]] void fail(std::string_view source, const std::string& what) {
  throw MapError("road network '" + std::string(source) + "': " + what);
}

double parse_double(std::string_view text, std::string_view source, std::string_view what) {
  double value = 0.0;
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(begin, end, value);
  if (ec != std::errc() || ptr != end || !std::isfinite(value)) {
    fail(source, "bad number '" + std::string(text) + "' in " + std::string(what) +
                     "; regenerate the file with netconvert");
  }
  return value;
}

// Parses "x,y[,z] x,y[,z] ..." (z ignored).
std::vector<Eigen::Vector2d> parse_shape(std::string_view text, std::string_view source,
                                         std::string_view what) {
  std::vector<Eigen::Vector2d> points;
  size_t pos = 0;
  while (pos < text.size()) {
    while (pos < text.size() && text[pos] == ' ') ++pos;
    if (pos >= text.size()) break;
    size_t end = text.find(' ', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view token = text.substr(pos, end - pos);
    const size_t comma = token.find(',');
    if (comma == std::string_view::npos) {
      fail(source, "malformed shape point '" + std::string(token) + "' in " + std::string(what));
    }
    std::string_view ys = token.substr(comma + 1);
    const size_t comma2 = ys.find(',');
    if (comma2 != std::string_view::npos) ys = ys.substr(0, comma2);
    points.emplace_back(parse_double(token.substr(0, comma), source, what),
                        parse_double(ys, source, what));
    pos = end;
  }
  return points;
}

// Lanes that cars may not use (sidewalks, bike lanes, rails) are left out of the network.
bool allows_cars(const pugi::xml_node& lane) {
  auto contains = [](std::string_view list, std::string_view word) {
    std::istringstream words{std::string(list)};
    std::string token;
    while (words >> token) {
      if (token == word) return true;
    }
    return false;
  };
  if (auto allow = lane.attribute("allow")) {
    const std::string_view list = allow.value();
    if (!contains(list, "passenger") && !contains(list, "all")) return false;
  }
  if (auto disallow = lane.attribute("disallow")) {
    const std::string_view list = disallow.value();
    if (contains(list, "passenger") || contains(list, "all")) return false;
  }
  return true;
}

}  // namespace

TurnDirection parse_turn_direction(std::string_view dir) {
  if (dir == "s") return TurnDirection::kStraight;
  if (dir == "r") return TurnDirection::kRight;
  if (dir == "l") return TurnDirection::kLeft;
  if (dir == "R") return TurnDirection::kPartialRight;
  if (dir == "L") return TurnDirection::kPartialLeft;
  if (dir == "t") return TurnDirection::kTurnaround;
  throw MapError("unknown connection direction '" + std::string(dir) +
                 "' (expected one of s r l R L t)");
}

char turn_direction_code(TurnDirection dir) {
  switch (dir) {
    case TurnDirection::kStraight:
      return 's';
    case TurnDirection::kRight:
      return 'r';
    case TurnDirection::kLeft:
      return 'l';
    case TurnDirection::kPartialRight:
      return 'R';
    case TurnDirection::kPartialLeft:
      return 'L';
    case TurnDirection::kTurnaround:
      return 't';
  }
  return '?';
}

bool is_right_turn(TurnDirection dir) {
  return dir == TurnDirection::kRight || dir == TurnDirection::kPartialRight;
}

bool is_left_turn(TurnDirection dir) {
  return dir == TurnDirection::kLeft || dir == TurnDirection::kPartialLeft;
}

double wrap_angle(double angle_rad) {
  double wrapped = std::fmod(angle_rad + M_PI, 2.0 * M_PI);
  if (wrapped < 0.0) wrapped += 2.0 * M_PI;
  return wrapped - M_PI;
}

RoadNetwork RoadNetwork::load(const std::filesystem::path& net_xml) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(net_xml, ec)) {
    throw MapError("road network file '" + net_xml.string() +
                   "' does not exist; give a .net.xml path, an .xodr path or a built-in town "
                   "name (town01, town02)");
  }
  std::ifstream in(net_xml, std::ios::binary);
  if (!in) throw MapError("road network file '" + net_xml.string() + "' cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  RoadNetwork net = parse(text.str(), net_xml.string());
  net.source_ = net_xml;
  return net;
}

RoadNetwork RoadNetwork::parse(std::string_view xml_text, std::string_view source) {
  pugi::xml_document doc;
  const pugi::xml_parse_result parsed = doc.load_buffer(xml_text.data(), xml_text.size());
  if (!parsed) {
    fail(source, std::string("not well-formed XML (") + parsed.description() + " at byte " +
                     std::to_string(parsed.offset) + "); is it a complete SUMO .net.xml?");
  }
  const pugi::xml_node root = doc.child("net");
  if (!root) fail(source, "no <net> root element; this is not a SUMO .net.xml file");

  RoadNetwork net;
  // <location netOffset="x,y">: what netconvert added to the source's coordinates.
  if (const pugi::xml_attribute offset = root.child("location").attribute("netOffset")) {
    const auto points = parse_shape(offset.value(), source, "location netOffset");
    if (points.size() != 1) fail(source, "location netOffset must be one point \"x,y\"");
    net.offset_ = points.front();
  }
  // Edges and their lanes.
  for (const pugi::xml_node& edge_node : root.children("edge")) {
    const std::string function = edge_node.attribute("function").as_string("normal");
    if (function != "normal" && function != "internal") continue;  // crossings, walking areas
    Edge edge;
    edge.id = edge_node.attribute("id").as_string();
    if (edge.id.empty()) fail(source, "an <edge> has no id");
    edge.internal = function == "internal";
    edge.from_junction = edge_node.attribute("from").as_string();
    edge.to_junction = edge_node.attribute("to").as_string();
    const int edge_index = static_cast<int>(net.edges_.size());
    for (const pugi::xml_node& lane_node : edge_node.children("lane")) {
      if (!allows_cars(lane_node)) continue;
      Lane lane;
      lane.id = lane_node.attribute("id").as_string();
      if (lane.id.empty()) fail(source, "a <lane> of edge '" + edge.id + "' has no id");
      lane.edge = edge_index;
      lane.internal = edge.internal;
      lane.index = lane_node.attribute("index").as_int(0);
      lane.speed_mps = lane_node.attribute("speed").as_double(13.89);
      lane.width_m = lane_node.attribute("width").as_double(3.2);  // SUMO's default width
      const pugi::xml_attribute shape = lane_node.attribute("shape");
      if (!shape) fail(source, "lane '" + lane.id + "' has no shape");
      lane.shape = geometry::dedupe(parse_shape(shape.value(), source, "lane " + lane.id));
      // Zero-length internal lanes occur at some junctions; they carry no surface.
      if (lane.shape.size() < 2) continue;
      lane.arc_m = geometry::arc_lengths(lane.shape);
      lane.length_m = lane.arc_m.back();
      if (!(lane.width_m > 0.0)) fail(source, "lane '" + lane.id + "' has a non-positive width");
      const int lane_index = static_cast<int>(net.lanes_.size());
      if (!net.lane_by_id_.emplace(lane.id, lane_index).second) {
        fail(source, "duplicate lane id '" + lane.id + "'");
      }
      edge.lanes.push_back(lane_index);
      net.lanes_.push_back(std::move(lane));
    }
    std::sort(edge.lanes.begin(), edge.lanes.end(),
              [&](int a, int b) { return net.lanes_[a].index < net.lanes_[b].index; });
    if (!net.edge_by_id_.emplace(edge.id, edge_index).second) {
      fail(source, "duplicate edge id '" + edge.id + "'");
    }
    net.edges_.push_back(std::move(edge));
  }
  if (net.lanes_.empty()) fail(source, "no drivable lanes; the network is empty");

  // Junctions (SUMO's internal junctions are waiting positions, not areas).
  for (const pugi::xml_node& junction_node : root.children("junction")) {
    Junction junction;
    junction.type = junction_node.attribute("type").as_string();
    if (junction.type == "internal") continue;
    junction.id = junction_node.attribute("id").as_string();
    junction.position = {junction_node.attribute("x").as_double(),
                         junction_node.attribute("y").as_double()};
    if (const auto shape = junction_node.attribute("shape")) {
      junction.shape =
          geometry::dedupe(parse_shape(shape.value(), source, "junction " + junction.id));
      if (junction.shape.size() > 1 &&
          (junction.shape.front() - junction.shape.back()).norm() < 1e-6) {
        junction.shape.pop_back();
      }
    }
    net.junctions_.push_back(std::move(junction));
  }

  // Connections: normal lane -> normal lane, and the chains of internal lanes between them.
  net.connections_from_.assign(net.lanes_.size(), {});
  net.internal_successor_.assign(net.lanes_.size(), -1);
  for (const pugi::xml_node& node : root.children("connection")) {
    const std::string from = node.attribute("from").as_string();
    const std::string to = node.attribute("to").as_string();
    const int from_edge = net.find_edge(from);
    const int to_edge = net.find_edge(to);
    if (from_edge < 0 || to_edge < 0) continue;  // pedestrian parts that were left out
    const int from_lane = net.find_lane(from + "_" + node.attribute("fromLane").as_string());
    const int to_lane = net.find_lane(to + "_" + node.attribute("toLane").as_string());
    if (from_lane < 0 || to_lane < 0) continue;
    const int via_lane = net.find_lane(node.attribute("via").as_string());
    const char* dir_text = node.attribute("dir").as_string("s");
    TurnDirection direction;
    try {
      direction = parse_turn_direction(dir_text);
    } catch (const MapError& error) {
      fail(source, std::string(error.what()) + " in connection " + from + " -> " + to);
    }
    if (net.edges_[from_edge].internal) {
      net.internal_successor_[from_lane] = via_lane >= 0 ? via_lane : to_lane;
      continue;
    }
    if (net.edges_[to_edge].internal) continue;
    net.connections_from_[from_lane].push_back(static_cast<int>(net.connections_.size()));
    net.connections_.push_back(Connection{from_lane, to_lane, via_lane, direction});
  }

  net.build_index();
  return net;
}

}  // namespace indrive::env
