# Tests of the envserver net area: road network, towns, routes, static scene, rewards.
indrive_test(envserver_net_test
  SOURCES net_parse_test.cc net_query_test.cc reward_test.cc
  LIBS indrive::envserver
  LABEL unit TIMEOUT 120)
