// An EpisodeResult CSV (episode_csv.h) read and turned into the paper's tables, as
// `indrive report` does with the evaluators' files.
#include <cstdint>

#include "fuzz_support.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/deploy/report.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  const fuzz::fs::path results = fuzz::fs::path(INDRIVE_SOURCE_DIR) / "docs" / "results";
  int made = 0;
  for (const auto& entry : fuzz::fs::recursive_directory_iterator(results)) {
    if (entry.path().extension() != ".csv" || made >= 4) continue;
    const std::string text = fuzz::read_text(entry.path());
    // Files of either header (episode_csv_header() extends the first).
    if (!text.starts_with(episode_csv_header_v1())) continue;
    // The header and a few rows: enough for every column, small enough to mutate fast.
    std::size_t end = 0;
    for (int line = 0; line < 6 && end != std::string::npos; ++line) end = text.find('\n', end + 1);
    fuzz::write_seed(dir, "results-" + std::to_string(made++), text.substr(0, end));
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto& path = fuzz::as_file(data, size, ".csv");
  fuzz::accept<CsvError>([&] {
    const auto records = read_episode_csv(path);
    if (records.empty()) return;
    const auto report = deploy::aggregate(records);
    deploy::render_markdown(report, "town01", "town02");
    deploy::render_latex(report);
    deploy::render_csv(report);
  });
  return 0;
}
