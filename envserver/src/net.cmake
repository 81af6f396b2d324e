# Sources of the envserver net area (added to indrive_envserver): road network, towns, routes,
# static scene, rewards.
find_package(pugixml REQUIRED)
target_sources(indrive_envserver PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/reward.cc
)
target_link_libraries(indrive_envserver PRIVATE pugixml::pugixml)
