// The QoS contract of docs/architecture.md, section 3, checked against one shipped XML profiles
// file (INDRIVE_PROFILES_FILE; one file per test binary, since a process can load only one).
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <gtest/gtest.h>

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <memory>
#include <vector>

#include "indrive/dds/participant.h"
#include "testing.h"

namespace indrive::dds {
namespace {

namespace fdds = eprosima::fastdds::dds;

const std::string kFile = INDRIVE_PROFILES_FILE;

struct Expected {
  fdds::ReliabilityQosPolicyKind reliability;
  fdds::DurabilityQosPolicyKind durability;
  fdds::HistoryQosPolicyKind history;
  int depth;  // for KEEP_LAST
};

class ProfilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    participant_ = std::make_unique<Participant>(
        ParticipantOptions{.domain_id = testing::unique_domain_id(),
                           .profiles_file = testing::source_path("deploy/dds/" + kFile).string()});
    publisher_ = participant_->native()->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
    subscriber_ = participant_->native()->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  }
  void TearDown() override {
    participant_->native()->delete_publisher(publisher_);
    participant_->native()->delete_subscriber(subscriber_);
  }

  // Checks the writer and reader profiles of topic T against `expected`.
  template <typename T>
  void expect_topic(const Expected& expected) {
    SCOPED_TRACE(TopicTraits<T>::kTopic);
    fdds::DataWriterQos writer;
    ASSERT_EQ(publisher_->get_datawriter_qos_from_profile(TopicTraits<T>::kWriterProfile, writer),
              eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
    fdds::DataReaderQos reader;
    ASSERT_EQ(subscriber_->get_datareader_qos_from_profile(TopicTraits<T>::kReaderProfile, reader),
              eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
    EXPECT_EQ(static_cast<int>(writer.reliability().kind), static_cast<int>(expected.reliability));
    EXPECT_EQ(static_cast<int>(reader.reliability().kind), static_cast<int>(expected.reliability));
    EXPECT_EQ(static_cast<int>(writer.durability().kind), static_cast<int>(expected.durability));
    EXPECT_EQ(static_cast<int>(reader.durability().kind), static_cast<int>(expected.durability));
    EXPECT_EQ(static_cast<int>(writer.history().kind), static_cast<int>(expected.history));
    EXPECT_EQ(static_cast<int>(reader.history().kind), static_cast<int>(expected.history));
    if (expected.history == fdds::KEEP_LAST_HISTORY_QOS) {
      EXPECT_EQ(writer.history().depth, expected.depth);
    } else {
      // KEEP_ALL must be bounded, so a slow reader pushes back instead of growing memory.
      EXPECT_GT(writer.resource_limits().max_samples, 0);
      EXPECT_GT(reader.resource_limits().max_samples, 0);
    }
    // Unbounded sequences (megabytes of params) need a history that reallocates.
    EXPECT_NE(writer.endpoint().history_memory_policy,
              eprosima::fastrtps::rtps::PREALLOCATED_MEMORY_MODE);
    EXPECT_NE(reader.endpoint().history_memory_policy,
              eprosima::fastrtps::rtps::PREALLOCATED_MEMORY_MODE);
  }

  std::unique_ptr<Participant> participant_;
  fdds::Publisher* publisher_ = nullptr;
  fdds::Subscriber* subscriber_ = nullptr;
};

TEST_F(ProfilesTest, TopicQosMatchesTheArchitecture) {
  using fdds::KEEP_ALL_HISTORY_QOS;
  using fdds::KEEP_LAST_HISTORY_QOS;
  constexpr auto kReliable = fdds::RELIABLE_RELIABILITY_QOS;
  constexpr auto kVolatile = fdds::VOLATILE_DURABILITY_QOS;
  constexpr auto kTransientLocal = fdds::TRANSIENT_LOCAL_DURABILITY_QOS;
  expect_topic<msg::TrajectoryChunk>({kReliable, kVolatile, KEEP_ALL_HISTORY_QOS, 0});
  expect_topic<msg::PolicySnapshot>({kReliable, kTransientLocal, KEEP_LAST_HISTORY_QOS, 1});
  expect_topic<msg::SnapshotAnnounce>({kReliable, kVolatile, KEEP_LAST_HISTORY_QOS, 1});
  expect_topic<msg::SnapshotRequest>({kReliable, kVolatile, KEEP_LAST_HISTORY_QOS, 8});
  expect_topic<msg::StepAllowance>({kReliable, kTransientLocal, KEEP_LAST_HISTORY_QOS, 1});
  expect_topic<msg::EpisodeResult>({kReliable, kVolatile, KEEP_ALL_HISTORY_QOS, 0});
  expect_topic<msg::Heartbeat>(
      {fdds::BEST_EFFORT_RELIABILITY_QOS, kVolatile, KEEP_LAST_HISTORY_QOS, 1});
}

TEST_F(ProfilesTest, TransportFitsTheFile) {
  fdds::DomainParticipantQos qos;
  ASSERT_EQ(fdds::DomainParticipantFactory::get_instance()->get_participant_qos_from_profile(
                "indrive_participant", qos),
            eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
  // Exactly one transport: Fast DDS fragments at the smallest message size of all of them.
  EXPECT_FALSE(qos.transport().use_builtin_transports);
  ASSERT_EQ(qos.transport().user_transports.size(), 1u);
  const auto& transport = qos.transport().user_transports.front();
  fdds::DataWriterQos policy_writer;
  ASSERT_EQ(publisher_->get_datawriter_qos_from_profile("policy_writer", policy_writer),
            eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
  if (kFile == "single_host.xml") {
    auto shm =
        std::dynamic_pointer_cast<eprosima::fastdds::rtps::SharedMemTransportDescriptor>(transport);
    ASSERT_NE(shm, nullptr) << "single_host.xml must use shared memory";
    // A 10 MB snapshot (plus headers) travels as one message, not 64 KB fragments.
    EXPECT_GE(shm->max_message_size(), 11u << 20);
    EXPECT_GE(shm->segment_size(), 2 * shm->max_message_size());
  } else {
    EXPECT_NE(
        std::dynamic_pointer_cast<eprosima::fastdds::rtps::UDPv4TransportDescriptor>(transport),
        nullptr)
        << kFile << " must use UDPv4";
    // Large samples over UDP go out asynchronously, paced by the writer's flow controller.
    EXPECT_EQ(static_cast<int>(policy_writer.publish_mode().kind),
              static_cast<int>(fdds::ASYNCHRONOUS_PUBLISH_MODE));
  }
  const auto& discovery = qos.wire_protocol().builtin.discovery_config;
  if (kFile == "discovery_server.xml") {
    EXPECT_EQ(discovery.discoveryProtocol, eprosima::fastrtps::rtps::DiscoveryProtocol_t::CLIENT);
    EXPECT_EQ(discovery.m_DiscoveryServers.size(), 1u);
  } else {
    EXPECT_EQ(discovery.discoveryProtocol, eprosima::fastrtps::rtps::DiscoveryProtocol_t::SIMPLE);
  }
}

// On one host (shared memory only) every participant of a process gets an id of its own, so
// one recreated after another was closed does not take its port; UDP files leave the id to
// Fast DDS.
TEST_F(ProfilesTest, ParticipantIdsFitTheTransport) {
  std::vector<int> ids = {participant_->participant_id()};
  for (int i = 0; i < 2; ++i) {
    Participant next(
        ParticipantOptions{.domain_id = participant_->domain_id(),
                           .profiles_file = testing::source_path("deploy/dds/" + kFile).string()});
    EXPECT_EQ(next.native()->get_qos().wire_protocol().participant_id, next.participant_id());
    ids.push_back(next.participant_id());
  }
  if (kFile == "single_host.xml") {
    for (std::size_t i = 0; i < ids.size(); ++i) {
      EXPECT_GE(ids[i], 0);
      for (std::size_t j = 0; j < i; ++j) EXPECT_NE(ids[i], ids[j]) << i << " and " << j;
    }
  } else {
    EXPECT_EQ(ids, (std::vector<int>{-1, -1, -1}));
  }
}

}  // namespace
}  // namespace indrive::dds
