// The ledger of a participant's peers: discovery, authentication, refusal, departure, and the
// one-time report of a handshake that has been pending too long, on a simulated clock.
#include "indrive/dds/peers.h"

#include <gtest/gtest.h>

namespace indrive::dds {
namespace {

using namespace std::chrono_literals;
using Clock = PeerLedger::Clock;

TEST(PeerLedger, CountsEachKindOfPeer) {
  PeerLedger peers;
  const Clock::time_point t0{};
  peers.discovered("a", /*offers_identity=*/true, t0);
  peers.discovered("b", true, t0);
  peers.discovered("c", true, t0);
  peers.discovered("plain", false, t0);
  EXPECT_DOUBLE_EQ(peers.authenticated("a", t0 + 1500ms), 1.5);
  EXPECT_TRUE(peers.refused("b"));
  // Fast DDS reports a participant without security as refused too: it stays unsecured.
  EXPECT_FALSE(peers.refused("plain"));
  const PeerLedger::Counts counts = peers.counts();
  EXPECT_EQ(counts.present, 3);  // a, c and plain; b was refused
  EXPECT_EQ(counts.authenticated, 1);
  EXPECT_EQ(counts.refused, 1);
  EXPECT_EQ(counts.pending, 1);  // c
  EXPECT_EQ(counts.unsecured, 1);
}

TEST(PeerLedger, AStalledHandshakeIsReportedOncePerDiscovery) {
  PeerLedger peers;
  const Clock::time_point t0{};
  peers.discovered("slow", true, t0);
  peers.discovered("quick", true, t0 + 5s);
  peers.discovered("plain", false, t0);
  EXPECT_TRUE(peers.newly_stalled(t0 + 29s, 30s).empty());
  auto stalled = peers.newly_stalled(t0 + 31s, 30s);
  ASSERT_EQ(stalled.size(), 1u);  // not "quick" (26 s), never "plain" (no handshake)
  EXPECT_EQ(stalled[0].guid, "slow");
  EXPECT_DOUBLE_EQ(stalled[0].pending_s, 31.0);
  peers.authenticated("quick", t0 + 32s);
  EXPECT_TRUE(peers.newly_stalled(t0 + 60s, 30s).empty()) << "reported once only";
  EXPECT_EQ(peers.counts().stalled, 1);
  EXPECT_EQ(peers.counts().pending, 1);

  // Gone and discovered again: a new handshake, a new chance to report it.
  peers.left("slow");
  EXPECT_EQ(peers.counts().pending, 0);
  EXPECT_EQ(peers.counts().stalled, 0);
  peers.discovered("slow", true, t0 + 100s);
  EXPECT_TRUE(peers.newly_stalled(t0 + 120s, 30s).empty());
  EXPECT_EQ(peers.newly_stalled(t0 + 131s, 30s).size(), 1u);
}

TEST(PeerLedger, RediscoveryKeepsAnAuthenticatedPeerAndItsClock) {
  PeerLedger peers;
  const Clock::time_point t0{};
  peers.discovered("a", true, t0);
  peers.authenticated("a", t0 + 1s);
  // Discovery also reports QoS changes of known participants.
  peers.discovered("a", true, t0 + 50s);
  EXPECT_EQ(peers.counts().pending, 0);
  EXPECT_TRUE(peers.newly_stalled(t0 + 100s, 30s).empty());
  // An authentication for a participant the ledger never saw discovered still counts.
  EXPECT_DOUBLE_EQ(peers.authenticated("unseen", t0 + 2s), 0.0);
  EXPECT_EQ(peers.counts().authenticated, 2);
  EXPECT_EQ(peers.counts().present, 2);
}

}  // namespace
}  // namespace indrive::dds
