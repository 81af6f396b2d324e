# Sources of the envserver camera area (added to indrive_envserver): semantic camera, static
# scene cache, bird's-eye view, video writing.
target_sources(indrive_envserver PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/camera_colorize.cc
)
