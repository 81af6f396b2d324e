# Sources of common/nn (added to indrive_common).
target_sources(indrive_common PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/tensor.cc
  ${CMAKE_CURRENT_LIST_DIR}/kernels.cc
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

# The kernel layer's oneDNN matmul (kernels.cc); without it every product runs on Eigen.
if(INDRIVE_ONEDNN)
  target_link_libraries(indrive_common PRIVATE DNNL::dnnl)
  target_compile_definitions(indrive_common PRIVATE INDRIVE_WITH_ONEDNN=1)
else()
  target_compile_definitions(indrive_common PRIVATE INDRIVE_WITH_ONEDNN=0)
endif()
