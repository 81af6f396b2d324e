# Sources of common/agent (added to indrive_common).
target_sources(indrive_common PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/agent.cc
  ${CMAKE_CURRENT_LIST_DIR}/behavior.cc
  ${CMAKE_CURRENT_LIST_DIR}/config.cc
  ${CMAKE_CURRENT_LIST_DIR}/intrinsic.cc
  ${CMAKE_CURRENT_LIST_DIR}/local_trainer.cc
  ${CMAKE_CURRENT_LIST_DIR}/observation.cc
  ${CMAKE_CURRENT_LIST_DIR}/policy.cc
  ${CMAKE_CURRENT_LIST_DIR}/replay.cc
  ${CMAKE_CURRENT_LIST_DIR}/returns.cc
  ${CMAKE_CURRENT_LIST_DIR}/world_model.cc
)
