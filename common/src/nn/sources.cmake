# Sources of common/nn (added to indrive_common).
target_sources(indrive_common PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/tensor.cc
  ${CMAKE_CURRENT_LIST_DIR}/ops_elementwise.cc
  ${CMAKE_CURRENT_LIST_DIR}/ops_linear.cc
  ${CMAKE_CURRENT_LIST_DIR}/ops_shape.cc
  ${CMAKE_CURRENT_LIST_DIR}/ops_norm.cc
  ${CMAKE_CURRENT_LIST_DIR}/ops_conv.cc
  ${CMAKE_CURRENT_LIST_DIR}/ops_dist.cc
  ${CMAKE_CURRENT_LIST_DIR}/layers.cc
  ${CMAKE_CURRENT_LIST_DIR}/optim.cc
  ${CMAKE_CURRENT_LIST_DIR}/serialize.cc
)
