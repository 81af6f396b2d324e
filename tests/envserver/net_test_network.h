// A small hand-written SUMO network whose geometry the net tests compute by hand.
//
//   y
//   ^            ba_0 (westbound, y = +1.75)        junction b: square x 100..110, y -3.5..3.5
//   |  a  <--------------------------------  b  ----- bd_0 (eastbound, 110..150, y = -1.75)
//   |     -------------------------------->     :b_0_0 (internal, 100..110, y = -1.75)
//   |            ab_0 (eastbound, y = -1.75)
//   +-----------------------------------------------------> x
// plus an L-shaped lane ce_0 of width 4: (200,0) -> (200,50) -> (250,50).
#pragma once

namespace indrive::env::testing {

inline constexpr const char* kHandNetwork = R"(<?xml version="1.0" encoding="UTF-8"?>
<net version="1.9">
  <edge id=":b_0" function="internal">
    <lane id=":b_0_0" index="0" speed="10" length="10" width="3.5" shape="100,-1.75 110,-1.75"/>
  </edge>
  <edge id="ab" from="a" to="b" priority="-1">
    <lane id="ab_0" index="0" speed="10" length="100" width="3.5" shape="0,-1.75 100,-1.75"/>
  </edge>
  <edge id="ba" from="b" to="a" priority="-1">
    <lane id="ba_0" index="0" speed="10" length="100" width="3.5" shape="100,1.75 0,1.75"/>
  </edge>
  <edge id="bd" from="b" to="d" priority="-1">
    <lane id="bd_0" index="0" speed="10" length="40" width="3.5" shape="110,-1.75 150,-1.75"/>
  </edge>
  <edge id="ce" from="c" to="e" priority="-1">
    <lane id="ce_0" index="0" speed="10" length="100" width="4" shape="200,0 200,50 250,50"/>
  </edge>
  <edge id="sw" from="a" to="b">
    <lane id="sw_0" index="0" allow="pedestrian" width="2" shape="0,-5 100,-5"/>
  </edge>
  <junction id="b" type="priority" x="105" y="0" shape="100,-3.5 110,-3.5 110,3.5 100,3.5"/>
  <junction id=":b_x" type="internal" x="105" y="0"/>
  <connection from="ab" to="bd" fromLane="0" toLane="0" via=":b_0_0" dir="s" state="M"/>
  <connection from=":b_0" to="bd" fromLane="0" toLane="0" dir="s" state="M"/>
</net>
)";

}  // namespace indrive::env::testing
