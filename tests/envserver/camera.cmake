# Tests of the envserver camera area.
indrive_test(camera_test SOURCES camera_test.cc LIBS indrive::envserver)
indrive_bench(camera_bench SOURCES camera_bench.cc LIBS indrive::envserver ARGS --frames 3000)
target_include_directories(camera_bench PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
