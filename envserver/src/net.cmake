# Sources of the envserver net area (added to indrive_envserver): road network, towns, routes,
# static scene, rewards. Town sources and route files live in envserver/data/.
find_package(pugixml REQUIRED)
find_program(NETGENERATE_BINARY netgenerate)
if(NOT NETGENERATE_BINARY)
  set(NETGENERATE_BINARY netgenerate)  # procedural towns then fail with a clear message
endif()
target_sources(indrive_envserver PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/net_geometry.cc
  ${CMAKE_CURRENT_LIST_DIR}/net_parse.cc
  ${CMAKE_CURRENT_LIST_DIR}/net_query.cc
  ${CMAKE_CURRENT_LIST_DIR}/net_town.cc
  ${CMAKE_CURRENT_LIST_DIR}/net_draw.cc
  ${CMAKE_CURRENT_LIST_DIR}/routes_route.cc
  ${CMAKE_CURRENT_LIST_DIR}/routes_file.cc
  ${CMAKE_CURRENT_LIST_DIR}/routes_points.cc
  ${CMAKE_CURRENT_LIST_DIR}/routes_derive.cc
  ${CMAKE_CURRENT_LIST_DIR}/routes_conflicts.cc
  ${CMAKE_CURRENT_LIST_DIR}/scene_build.cc
  ${CMAKE_CURRENT_LIST_DIR}/reward.cc
)
target_link_libraries(indrive_envserver PRIVATE pugixml::pugixml)
target_compile_definitions(indrive_envserver PRIVATE
  INDRIVE_NETGENERATE_BINARY="${NETGENERATE_BINARY}")
