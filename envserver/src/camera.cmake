# Sources of the envserver camera area (added to indrive_envserver): semantic camera, static
# scene cache, bird's-eye view, video writing.
target_sources(indrive_envserver PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/bev.cc
  ${CMAKE_CURRENT_LIST_DIR}/camera_colorize.cc
  ${CMAKE_CURRENT_LIST_DIR}/camera_render.cc
  ${CMAKE_CURRENT_LIST_DIR}/camera_scene_cache.cc
  ${CMAKE_CURRENT_LIST_DIR}/video.cc
)
