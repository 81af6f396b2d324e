// CDR bytes of the wire types, decoded by the type the project registers for each topic
// (dds/messages.h, GuardedPubSubType over the generated one): the message targets decode fuzz
// input exactly as a subscriber does before any project code runs.
#pragma once

#include <fastdds/rtps/common/SerializedPayload.h>

#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "indrive/dds/messages.h"

namespace indrive::fuzz {

template <typename T>
std::vector<std::uint8_t> to_cdr(const T& message) {
  typename dds::TopicTraits<T>::PubSubType type;
  T copy = message;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(&copy)());
  if (!type.serialize(&copy, &payload)) return {};
  return {payload.data, payload.data + payload.length};
}

// False when the bytes are not a T in CDR (the subscriber drops such a sample before the
// application sees it).
template <typename T>
bool from_cdr(std::span<const std::uint8_t> bytes, T& message) {
  typename dds::TopicTraits<T>::PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<std::uint32_t>(bytes.size()));
  if (!bytes.empty()) std::memcpy(payload.data, bytes.data(), bytes.size());
  payload.length = static_cast<std::uint32_t>(bytes.size());
  return type.deserialize(&payload, &message);
}

}  // namespace indrive::fuzz
