# Tests of the envserver coverage area: lane pieces, visit windows, coverage files and map.
indrive_test(envserver_coverage_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/coverage_test.cc
  LIBS indrive::envserver LABEL unit TIMEOUT 120)
