# Tests of the envserver net area: road network, towns, routes, static scene, rewards.
indrive_test(envserver_net_test
  SOURCES net_parse_test.cc net_query_test.cc net_town_test.cc reward_test.cc
          routes_route_test.cc routes_derive_test.cc routes_file_test.cc
          routes_conflicts_test.cc scene_build_test.cc net_draw_test.cc routes_feasibility_test.cc
          routes_points_test.cc
  LIBS indrive::envserver
  LABEL unit TIMEOUT 120)
target_compile_definitions(envserver_net_test PRIVATE
  INDRIVE_NETCONVERT_FOR_TESTS="${NETCONVERT_BINARY}")
indrive_bench(envserver_net_bench SOURCES net_query_bench.cc LIBS indrive::envserver ARGS town01)
