# Writes OUTPUT, a C++ source defining indrive::deploy::chartjs_source() as the text of INPUT
# (Chart.js from Debian's libjs-chart.js), so that `indrive dashboard` pages are self-contained
# and the program needs no file at run time. Run by the build (deploy/CMakeLists.txt).
file(READ "${INPUT}" content)
string(FIND "${content}" ")chartjs\"" clash)
if(NOT clash EQUAL -1)
  message(FATAL_ERROR "${INPUT} contains the raw-string delimiter used to embed it")
endif()
file(WRITE "${OUTPUT}.tmp"
     "// Generated from ${INPUT} by deploy/cmake/embed_chartjs.cmake; do not edit.\n"
     "#include <string_view>\n"
     "namespace indrive::deploy {\n"
     "std::string_view chartjs_source() {\n"
     "  static constexpr std::string_view kSource = R\"chartjs(${content})chartjs\";\n"
     "  return kSource;\n"
     "}\n"
     "}  // namespace indrive::deploy\n")
file(RENAME "${OUTPUT}.tmp" "${OUTPUT}")
