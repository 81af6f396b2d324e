# Sources of common/dds (added to indrive_common). The helpers wrap the generated wire types,
# so indrive::common exposes indrive::idl to its users.
target_sources(indrive_common PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/dds_messages.cc
  ${CMAKE_CURRENT_LIST_DIR}/dds.cc)
target_link_libraries(indrive_common PUBLIC indrive::idl)
