// A run's metrics.jsonl read into curves, as `indrive plot` and `indrive compare` do.
#include <cstdint>

#include "fuzz_support.h"
#include "indrive/basics/run_dir.h"
#include "indrive/deploy/plot.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  const fuzz::fs::path runs =
      fuzz::fs::path(INDRIVE_SOURCE_DIR) / "docs" / "results" / "method" / "runs";
  int made = 0;
  for (const auto& entry : fuzz::fs::recursive_directory_iterator(runs)) {
    if (entry.path().filename() != "metrics.jsonl" || made >= 3) continue;
    const std::string text = fuzz::read_text(entry.path());
    std::size_t end = 0;
    for (int line = 0; line < 4 && end != std::string::npos; ++line) end = text.find('\n', end + 1);
    fuzz::write_seed(dir, "metrics-" + std::to_string(made++), text.substr(0, end + 1));
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto& path = fuzz::as_file(data, size, ".jsonl");
  fuzz::accept<IoError>([&] {
    for (const auto& [key, column] : deploy::read_metric_columns(path)) {
      const auto& [x, y] = column;
      if (x.size() != y.size()) std::abort();
    }
  });
  return 0;
}
