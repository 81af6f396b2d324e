# Tests of the envserver camera area.
indrive_test(camera_test SOURCES camera_test.cc LIBS indrive::envserver)
