# Tests and benchmark of the envserver camera area (camera, scene cache, bird's-eye view, video).
indrive_test(camera_test SOURCES camera_test.cc LIBS indrive::envserver)
indrive_test(camera_scene_cache_test SOURCES camera_scene_cache_test.cc LIBS indrive::envserver)
indrive_test(bev_test SOURCES bev_test.cc LIBS indrive::envserver)
indrive_test(video_test SOURCES video_test.cc LIBS indrive::envserver)
indrive_bench(camera_bench SOURCES camera_bench.cc LIBS indrive::envserver ARGS --frames 3000)
