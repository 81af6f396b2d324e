# Sources of common/dds (added to indrive_common). The helpers wrap the generated wire types,
# so indrive::common exposes indrive::idl to its users.
target_sources(indrive_common PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/dds_messages.cc
  ${CMAKE_CURRENT_LIST_DIR}/dds.cc)
target_link_libraries(indrive_common PUBLIC indrive::idl)

# DDS Security (dds_security.cc): certificate and signature checks with OpenSSL's own API, so a
# wrong file is named before Fast DDS refuses it with a bare log line; pugixml reads the grants.
find_package(OpenSSL REQUIRED COMPONENTS Crypto)
find_package(pugixml REQUIRED)
target_sources(indrive_common PRIVATE ${CMAKE_CURRENT_LIST_DIR}/dds_security.cc)
target_link_libraries(indrive_common PRIVATE OpenSSL::Crypto pugixml::pugixml)
