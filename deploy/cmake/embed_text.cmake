# Writes OUTPUT, a C++ source defining `std::string_view indrive::deploy::NAME()` as the text
# of INPUT, so that `indrive dashboard` pages are self-contained and the program needs no file
# at run time: Chart.js from Debian's libjs-chart.js, and the page's own style and script
# (deploy/assets/). Run by the build (deploy/CMakeLists.txt).
file(READ "${INPUT}" content)
string(FIND "${content}" ")embedded\"" clash)
if(NOT clash EQUAL -1)
  message(FATAL_ERROR "${INPUT} contains the raw-string delimiter used to embed it")
endif()
file(WRITE "${OUTPUT}.tmp"
     "// Generated from ${INPUT} by deploy/cmake/embed_text.cmake; do not edit.\n"
     "#include <string_view>\n"
     "namespace indrive::deploy {\n"
     "std::string_view ${NAME}() {\n"
     "  static constexpr std::string_view kText = R\"embedded(${content})embedded\";\n"
     "  return kText;\n"
     "}\n"
     "}  // namespace indrive::deploy\n")
file(RENAME "${OUTPUT}.tmp" "${OUTPUT}")
