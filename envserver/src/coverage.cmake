# Sources of the envserver coverage area (added to indrive_envserver): lane pieces, visit
# counting and the coverage map.
target_sources(indrive_envserver PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/coverage.cc
)
