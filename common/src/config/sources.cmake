# Sources of common/config (added to indrive_common).
target_sources(indrive_common PRIVATE ${CMAKE_CURRENT_LIST_DIR}/config.cc)
