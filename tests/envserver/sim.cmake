# Tests of the envserver sim area.
add_library(indrive_sim_test_net STATIC ${CMAKE_CURRENT_LIST_DIR}/sim_test_net.cc)
target_include_directories(indrive_sim_test_net PUBLIC ${CMAKE_CURRENT_LIST_DIR})
target_link_libraries(indrive_sim_test_net PUBLIC indrive_testing GTest::gtest)
target_compile_definitions(indrive_sim_test_net PRIVATE
  INDRIVE_NETCONVERT_BINARY="${NETCONVERT_BINARY}")

indrive_test(sumo_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/sumo_test.cc
  LIBS indrive::envserver indrive_sim_test_net)
indrive_test(ego_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/ego_test.cc LIBS indrive::envserver)
indrive_test(events_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/events_test.cc
  LIBS indrive::envserver indrive_sim_test_net)
indrive_test(env_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/env_test.cc LIBS indrive::envserver)
indrive_test(follower_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/follower_test.cc
  LIBS indrive::envserver LABEL smoke TIMEOUT 600)
indrive_bench(env_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/env_bench.cc LIBS indrive::envserver
  ARGS --town town01 --steps 3000)
indrive_test(traffic_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/traffic_test.cc
  LIBS indrive::envserver indrive_sim_test_net)

# Designated initializers name only the fields that matter ({.route = "straight"}); GCC's
# -Wextra would flag every field left at its default.
foreach(target sumo_test ego_test events_test env_test follower_test traffic_test env_bench)
  target_compile_options(${target} PRIVATE -Wno-missing-field-initializers)
endforeach()

indrive_test(route_check_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/route_check_test.cc
  LIBS indrive::envserver)
# Public maps from tests/data/maps: conversion, route checks, SUMO; about a minute.
indrive_test(maps_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/maps_test.cc LIBS indrive::envserver
  LABEL maps TIMEOUT 900)
foreach(target route_check_test maps_test)
  target_compile_options(${target} PRIVATE -Wno-missing-field-initializers)
endforeach()
