// Road-network geometry parsed from a SUMO .net.xml, with a spatial index for fast queries.
//
// A RoadNetwork holds the lanes (normal and internal junction lanes) with their centre-line
// shapes and widths, the edges they belong to, the junction polygons and the lane-to-lane
// connections with their turn directions. Queries answer, for a point in SUMO's network frame
// (metres, x east, y north): which lane contains it, its arc-length position and signed
// lateral offset from that lane's centre line, the lane heading there, and whether the point
// is drivable at all (on a lane or inside a junction).
//
//   RoadNetwork net = RoadNetwork::load("town01.net.xml");      // throws MapError
//   if (auto at = net.locate({x, y}, yaw)) {
//     bool invaded = !net.lane(at->lane).internal &&
//                    std::abs(at->lateral_m) > 0.5 * net.lane(at->lane).width_m;
//     double heading_error = wrap_angle(yaw - at->heading_rad);
//   }
//   bool off_road = !net.is_drivable({x, y});
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "indrive/envserver/scene.h"

namespace indrive::env {

// A road network that cannot be used: missing or malformed file, failed conversion, a network
// without the parts a task needs. The message names the file and what to do.
class MapError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Turn direction of a connection, as SUMO's `dir` attribute gives it.
enum class TurnDirection { kStraight, kRight, kLeft, kPartialRight, kPartialLeft, kTurnaround };

// Parses SUMO's one-letter direction ("s", "r", "l", "R", "L", "t"); throws MapError otherwise.
TurnDirection parse_turn_direction(std::string_view dir);
// Returns the one-letter SUMO code of a direction.
char turn_direction_code(TurnDirection dir);
// True for right and partial right.
bool is_right_turn(TurnDirection dir);
// True for left and partial left.
bool is_left_turn(TurnDirection dir);

// Wraps an angle into [-pi, pi).
double wrap_angle(double angle_rad);

// One lane: a centre line in driving direction with a constant width.
struct Lane {
  std::string id;
  int edge = -1;          // index into RoadNetwork::edges()
  int index = 0;          // 0 = rightmost lane of its edge
  bool internal = false;  // a lane inside a junction (connects two normal lanes)
  double width_m = 3.2;
  double speed_mps = 13.89;
  double length_m = 0.0;  // arc length of the shape (SUMO's `length` attribute is ignored)
  std::vector<Eigen::Vector2d> shape;  // centre line, at least 2 points
  std::vector<double> arc_m;           // arc length at each shape point; arc_m[0] = 0
};

// One edge: a bundle of parallel lanes from one junction to another (or an internal edge).
struct Edge {
  std::string id;
  std::string from_junction;  // empty for internal edges
  std::string to_junction;    // empty for internal edges
  bool internal = false;
  std::vector<int> lanes;  // indices into RoadNetwork::lanes(), ordered by lane index
};

// One junction with its outline polygon (may be empty or degenerate for dead ends).
struct Junction {
  std::string id;
  std::string type;  // SUMO's junction type, e.g. "priority", "dead_end"
  Eigen::Vector2d position{0.0, 0.0};
  std::vector<Eigen::Vector2d> shape;
};

// A permitted move from the end of one normal lane to the start of another. `via` is the first
// internal lane crossing the junction (-1 when the network has no internal lanes); a crossing
// may consist of several internal lanes chained by internal connections.
struct Connection {
  int from_lane = -1;
  int to_lane = -1;
  int via_lane = -1;
  TurnDirection direction = TurnDirection::kStraight;
};

// Where a point lies relative to one lane's centre line.
struct LanePosition {
  int lane = -1;
  double s_m = 0.0;          // arc length of the closest centre-line point, in [0, length_m]
  double lateral_m = 0.0;    // signed offset from the centre line, positive to the left
  double heading_rad = 0.0;  // direction of travel of the lane at s_m
};

// The parsed network and its spatial index. Immutable after loading; cheap queries are const
// and thread-safe.
class RoadNetwork {
 public:
  // Parses a .net.xml file; throws MapError when it is missing, unreadable or malformed.
  static RoadNetwork load(const std::filesystem::path& net_xml);
  // Parses .net.xml text; `source_name` only labels error messages. Throws MapError.
  static RoadNetwork parse(std::string_view xml_text, std::string_view source_name);

  RoadNetwork(RoadNetwork&&) noexcept;
  RoadNetwork& operator=(RoadNetwork&&) noexcept;
  ~RoadNetwork();

  // All lanes, normal and internal; Lane::edge indexes edges().
  const std::vector<Lane>& lanes() const { return lanes_; }
  // All edges, normal and internal.
  const std::vector<Edge>& edges() const { return edges_; }
  // All junctions except SUMO's internal junctions (waiting positions inside a junction).
  const std::vector<Junction>& junctions() const { return junctions_; }
  // All connections between normal lanes.
  const std::vector<Connection>& connections() const { return connections_; }
  // Returns lane `index`, checking the range.
  const Lane& lane(int index) const;
  // Returns edge `index`, checking the range.
  const Edge& edge(int index) const;
  // Returns the index of the lane with this id, or -1.
  int find_lane(std::string_view id) const;
  // Returns the index of the edge with this id, or -1.
  int find_edge(std::string_view id) const;
  // Returns the indices into connections() of the moves leaving normal lane `lane`.
  const std::vector<int>& connections_from(int lane) const;
  // Returns the lane that follows internal lane `lane` (the next internal piece of the same
  // crossing, or the normal lane it ends on); -1 when there is none.
  int internal_successor(int lane) const;
  // Returns the chain of internal lanes of a connection, in driving order (empty when none).
  std::vector<int> crossing_lanes(const Connection& connection) const;

  // Returns the pose on lane `lane` at arc length `s_m` (clamped to the lane).
  Pose2 lane_pose(int lane, double s_m) const;
  // Projects a point onto lane `lane`'s centre line, however far it is.
  LanePosition project(int lane, const Eigen::Vector2d& point) const;
  // Returns every lane whose surface contains the point (|lateral| <= width / 2 + margin_m, with
  // margin_m in [0, 2]), sorted by lane index.
  std::vector<LanePosition> lanes_at(const Eigen::Vector2d& point, double margin_m = 0.0) const;
  // Returns the lane containing the point that fits best: the smallest |lateral| relative to
  // the lane width, a normal lane winning ties over an internal one; nullopt when off all lanes.
  std::optional<LanePosition> locate(const Eigen::Vector2d& point) const;
  // As locate(point), but prefers lanes whose direction lies within 60 degrees of `yaw_rad`,
  // then within 90, so that at junctions, on two-way roads and where two roads cross without
  // a junction (a bridge) the lane the vehicle drives on wins.
  std::optional<LanePosition> locate(const Eigen::Vector2d& point, double yaw_rad) const;
  // True when the point lies inside any junction polygon.
  bool in_junction(const Eigen::Vector2d& point) const;
  // True when the point lies on any lane surface or inside any junction polygon.
  bool is_drivable(const Eigen::Vector2d& point) const;
  // Bounding box of all lane surfaces and junction polygons.
  Eigen::Vector2d min_corner() const { return min_corner_; }
  Eigen::Vector2d max_corner() const { return max_corner_; }
  // What the conversion added to the source's coordinates (SUMO's location netOffset; zero
  // when the file has none).
  const Eigen::Vector2d& offset() const { return offset_; }
  // Path the network was loaded from (empty when parsed from text).
  const std::filesystem::path& source() const { return source_; }

 private:
  RoadNetwork();
  void build_index();

  struct Index;
  std::vector<Lane> lanes_;
  std::vector<Edge> edges_;
  std::vector<Junction> junctions_;
  std::vector<Connection> connections_;
  std::vector<std::vector<int>> connections_from_;  // per lane
  std::vector<int> internal_successor_;             // per lane
  std::unordered_map<std::string, int> lane_by_id_;
  std::unordered_map<std::string, int> edge_by_id_;
  Eigen::Vector2d min_corner_{0.0, 0.0};
  Eigen::Vector2d max_corner_{0.0, 0.0};
  Eigen::Vector2d offset_{0.0, 0.0};
  std::filesystem::path source_;
  std::unique_ptr<Index> index_;
};

}  // namespace indrive::env
