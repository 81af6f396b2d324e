#include "sim_test_net.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace indrive::testing {

std::filesystem::path make_t_junction_net(const std::filesystem::path& dir) {
  const auto nodes = dir / "t.nod.xml";
  const auto edges = dir / "t.edg.xml";
  const auto net = dir / "t.net.xml";
  std::ofstream(nodes) << R"(<nodes>
  <node id="W" x="0" y="0" type="priority"/>
  <node id="C" x="150" y="0" type="priority"/>
  <node id="E" x="300" y="0" type="priority"/>
  <node id="N" x="150" y="150" type="priority"/>
</nodes>
)";
  std::ofstream(edges) << R"(<edges>
  <edge id="we" from="W" to="C" numLanes="1" speed="13.9"/>
  <edge id="cw" from="C" to="W" numLanes="1" speed="13.9"/>
  <edge id="ce" from="C" to="E" numLanes="1" speed="13.9"/>
  <edge id="ec" from="E" to="C" numLanes="1" speed="13.9"/>
  <edge id="cn" from="C" to="N" numLanes="1" speed="13.9"/>
  <edge id="nc" from="N" to="C" numLanes="1" speed="13.9"/>
</edges>
)";
  const std::string command = std::string(INDRIVE_NETCONVERT_BINARY) + " --node-files " +
                              nodes.string() + " --edge-files " + edges.string() +
                              " --output-file " + net.string() +
                              " --default.lanewidth 3.5 --no-turnarounds true"
                              " --junctions.corner-detail 5 --offset.disable-normalization true"
                              " --xml-validation never --no-warnings true > " +
                              (dir / "netconvert.log").string() + " 2>&1";
  if (std::system(command.c_str()) != 0) {
    ADD_FAILURE() << "netconvert failed: " << command;
    return {};
  }
  return net;
}

}  // namespace indrive::testing
