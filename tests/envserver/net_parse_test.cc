// A missing or malformed network gives a MapError that names the problem.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>

#include "indrive/envserver/net.h"
#include "net_test_network.h"
#include "testing.h"

namespace indrive::env {
namespace {

using ::testing::HasSubstr;

// Returns the message of the MapError that parsing `xml` throws (fails the test otherwise).
std::string parse_error(const std::string& xml) {
  try {
    RoadNetwork::parse(xml, "bad.net.xml");
  } catch (const MapError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no MapError for:\n" << xml;
  return {};
}

TEST(NetParseTest, MissingFileNamesThePath) {
  try {
    RoadNetwork::load("/nonexistent/dir/town99.net.xml");
    FAIL() << "expected MapError";
  } catch (const MapError& error) {
    EXPECT_THAT(error.what(), HasSubstr("town99.net.xml"));
    EXPECT_THAT(error.what(), HasSubstr("does not exist"));
  }
}

TEST(NetParseTest, MalformedInputs) {
  EXPECT_THAT(parse_error("<net><edge id='x'>"), HasSubstr("not well-formed XML"));
  EXPECT_THAT(parse_error("<routes/>"), HasSubstr("no <net> root"));
  EXPECT_THAT(parse_error("<net/>"), HasSubstr("no drivable lanes"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 1,abc'/></edge></net>"),
              HasSubstr("bad number 'abc'"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 10'/></edge></net>"),
              HasSubstr("malformed shape point '10'"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0'/></edge></net>"),
              HasSubstr("lane 'x_0' has no shape"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 5,0'/></edge>"
                          "<edge id='x'><lane id='x_1' shape='0,0 5,0'/></edge></net>"),
              HasSubstr("duplicate edge id 'x'"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 5,0'/></edge>"
                          "<connection from='x' to='x' fromLane='0' toLane='0' dir='q'/></net>"),
              HasSubstr("unknown connection direction 'q'"));
  // Coordinates that would size the spatial index beyond reason (found by tests/fuzz, target
  // net: 1e28 m overflowed the cell count), or that are no finite numbers.
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 1e28,0'/></edge></net>"),
              HasSubstr("at most about 32 x 32 km"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 40000,40000'/></edge>"
                          "</net>"),
              HasSubstr("crop the map"));
  EXPECT_THAT(parse_error("<net><edge id='x'><lane id='x_0' shape='0,0 inf,0'/></edge></net>"),
              HasSubstr("bad number 'inf'"));
}

TEST(NetParseTest, LoadsFromFileAndRemembersTheSource) {
  indrive::testing::TempDir dir;
  const auto path = dir.path() / "hand.net.xml";
  std::ofstream(path) << testing::kHandNetwork;
  const RoadNetwork net = RoadNetwork::load(path);
  EXPECT_EQ(net.source(), path);
  EXPECT_EQ(net.lanes().size(), 5u);
  // A truncated copy of the same file is rejected.
  std::ofstream(path) << std::string(testing::kHandNetwork).substr(0, 300);
  EXPECT_THROW(RoadNetwork::load(path), MapError);
}

TEST(NetParseTest, TurnDirectionCodesRoundTrip) {
  for (const char* code : {"s", "r", "l", "R", "L", "t"}) {
    EXPECT_EQ(turn_direction_code(parse_turn_direction(code)), code[0]);
  }
  EXPECT_TRUE(is_right_turn(TurnDirection::kPartialRight));
  EXPECT_FALSE(is_right_turn(TurnDirection::kLeft));
  EXPECT_TRUE(is_left_turn(TurnDirection::kPartialLeft));
  EXPECT_THROW(parse_turn_direction("x"), MapError);
}

}  // namespace
}  // namespace indrive::env
