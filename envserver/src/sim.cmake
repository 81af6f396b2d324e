# Sources of the envserver sim area (added to indrive_envserver): SUMO connection, ego,
# traffic, events, the environment loop; and the indrive-env tool.
target_sources(indrive_envserver PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/ego.cc
  ${CMAKE_CURRENT_LIST_DIR}/env.cc
  ${CMAKE_CURRENT_LIST_DIR}/events.cc
  ${CMAKE_CURRENT_LIST_DIR}/follower.cc
  ${CMAKE_CURRENT_LIST_DIR}/route_check.cc
  ${CMAKE_CURRENT_LIST_DIR}/sumo_connection.cc
  ${CMAKE_CURRENT_LIST_DIR}/sumo_libsumo.cc
  ${CMAKE_CURRENT_LIST_DIR}/sumo_libtraci.cc
  ${CMAKE_CURRENT_LIST_DIR}/traffic.cc
)

add_executable(indrive-env ${CMAKE_CURRENT_LIST_DIR}/tools/indrive_env_main.cc)
target_link_libraries(indrive-env PRIVATE indrive::envserver)

# Designated initializers name only the fields that matter; GCC's -Wextra would flag every
# field left at its default.
set_source_files_properties(
  ${CMAKE_CURRENT_LIST_DIR}/env.cc ${CMAKE_CURRENT_LIST_DIR}/route_check.cc
  ${CMAKE_CURRENT_LIST_DIR}/tools/indrive_env_main.cc
  PROPERTIES COMPILE_OPTIONS -Wno-missing-field-initializers)
