#include "indrive/basics/episode_csv.h"

#include <algorithm>
#include <charconv>
#include <iterator>
#include <sstream>

namespace indrive {
namespace {

constexpr int kColumnsV1 = 17;
constexpr int kColumns = 19;

// Quotes a field if it holds a comma or a quote (RFC 4180). A line break is refused: the files
// are read line by line, and a writer reopening one counts and cuts rows at line ends.
std::string quote(const std::string& field) {
  if (field.find_first_of("\r\n") != std::string::npos)
    throw CsvError("a results field may not hold a line break: '" + field + "'");
  if (field.find_first_of(",\"") == std::string::npos) return field;
  std::string out = "\"";
  for (const char c : field) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

std::vector<std::string> split_row(const std::string& line) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        fields.back() += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        fields.back() += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      fields.emplace_back();
    } else if (c != '\r') {
      fields.back() += c;
    }
  }
  return fields;
}

template <typename T>
T parse_number(const std::string& text, const std::string& where) {
  T value{};
  const auto* end = text.data() + text.size();
  const auto [ptr, error] = std::from_chars(text.data(), end, value);
  if (error != std::errc() || ptr != end)
    throw CsvError(where + ": '" + text + "' is not a number");
  return value;
}

}  // namespace

const std::string& episode_csv_header_v1() {
  static const std::string header =
      "run_id,method,eval_kind,task,train_seed,policy_version,town,route,density,traffic_seed,"
      "spawn_seed,episode,success,failure_reason,steps,route_completion,return";
  return header;
}

const std::string& episode_csv_header() {
  static const std::string header = episode_csv_header_v1() + ",protocol,lane_invasions";
  return header;
}

EpisodeCsvWriter::EpisodeCsvWriter(const std::filesystem::path& path) : path_(path) {
  std::error_code error;
  bool fresh =
      !std::filesystem::exists(path, error) || std::filesystem::file_size(path, error) == 0;
  if (!fresh) {
    std::ifstream in(path, std::ios::binary);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in.eof() && in.fail()) throw CsvError("cannot read " + path.string());
    const std::size_t complete = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
    if (complete < text.size()) {  // a row cut by a crash: drop it
      std::filesystem::resize_file(path, complete, error);
      if (error) throw CsvError("cannot cut the partial last row of " + path.string());
    }
    // A file of an older build (a resumed run's): its rows stay in its columns.
    v1_ = text.compare(0, episode_csv_header_v1().size() + 1, episode_csv_header_v1() + "\n") == 0;
    const auto lines = std::count(text.begin(), text.begin() + static_cast<long>(complete), '\n');
    rows_ = std::max<long long>(0, lines - 1);  // less the header
    fresh = complete == 0;
  }
  out_.open(path, std::ios::app);
  if (!out_) throw CsvError("cannot open " + path.string() + " for appending");
  if (fresh) out_ << episode_csv_header() << '\n' << std::flush;
}

void EpisodeCsvWriter::write(const EpisodeRecord& r) {
  if (v1_ && r.protocol != "strict") {
    throw CsvError(path_.string() + " was written before results had a protocol column, and a " +
                   r.protocol + " row cannot be told apart there; move it aside (it stays " +
                   "readable by indrive report) and evaluate into a new file");
  }
  std::ostringstream row;
  row.precision(6);
  row << quote(r.run_id) << ',' << quote(r.method) << ',' << quote(r.eval_kind) << ','
      << quote(r.task) << ',' << r.train_seed << ',' << r.policy_version << ',' << quote(r.town)
      << ',' << quote(r.route) << ',' << r.density << ',' << r.traffic_seed << ',' << r.spawn_seed
      << ',' << r.episode << ',' << (r.success ? 1 : 0) << ',' << quote(r.failure_reason) << ','
      << r.steps << ',' << r.route_completion << ',' << r.episode_return;
  if (!v1_) row << ',' << quote(r.protocol) << ',' << r.lane_invasions;
  out_ << row.str() << '\n' << std::flush;
  if (!out_) throw CsvError("cannot append to " + path_.string() + " (disk full?)");
  ++rows_;
}

std::vector<EpisodeRecord> read_episode_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw CsvError("cannot open results file " + path.string());
  std::string line;
  if (!std::getline(in, line)) throw CsvError(path.string() + " is empty (no header line)");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  const bool v1 = line == episode_csv_header_v1();
  if (line != episode_csv_header() && !v1) {
    throw CsvError(path.string() + ": the header is not an episode results header; expected '" +
                   episode_csv_header() + "'");
  }
  const int columns = v1 ? kColumnsV1 : kColumns;
  std::vector<EpisodeRecord> records;
  for (int number = 2; std::getline(in, line); ++number) {
    if (line.empty() || line == "\r") continue;
    const std::string where = path.string() + ":" + std::to_string(number);
    const auto f = split_row(line);
    if (static_cast<int>(f.size()) != columns) {
      throw CsvError(where + ": " + std::to_string(f.size()) + " fields, expected " +
                     std::to_string(columns) + " (a partially written row?)");
    }
    EpisodeRecord r;
    r.run_id = f[0];
    r.method = f[1];
    r.eval_kind = f[2];
    r.task = f[3];
    r.train_seed = parse_number<int>(f[4], where + " train_seed");
    r.policy_version = parse_number<long long>(f[5], where + " policy_version");
    r.town = f[6];
    r.route = f[7];
    r.density = parse_number<int>(f[8], where + " density");
    r.traffic_seed = parse_number<int>(f[9], where + " traffic_seed");
    r.spawn_seed = parse_number<int>(f[10], where + " spawn_seed");
    r.episode = parse_number<int>(f[11], where + " episode");
    const int success = parse_number<int>(f[12], where + " success");
    if (success != 0 && success != 1) throw CsvError(where + ": success must be 0 or 1");
    r.success = success == 1;
    r.failure_reason = f[13];
    r.steps = parse_number<int>(f[14], where + " steps");
    r.route_completion = parse_number<double>(f[15], where + " route_completion");
    r.episode_return = parse_number<double>(f[16], where + " return");
    if (v1) {
      r.protocol = "strict";
      r.lane_invasions = r.failure_reason.find("lane_invasion") != std::string::npos ? 1 : 0;
    } else {
      r.protocol = f[17];
      if (r.protocol != "strict" && r.protocol != "indrive_code") {
        throw CsvError(where + ": protocol '" + r.protocol +
                       "' is neither strict nor indrive_code");
      }
      r.lane_invasions = parse_number<int>(f[18], where + " lane_invasions");
    }
    records.push_back(std::move(r));
  }
  return records;
}

}  // namespace indrive
