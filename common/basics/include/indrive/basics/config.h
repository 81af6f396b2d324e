// Declarative configuration: each component declares its keys next to its code; a run's
// Config is resolved from, in order, the schema defaults, a preset (a named bundle of
// overrides), a YAML file and `--set key=value` overrides. The resolved config is written to
// runs/<id>/config.yaml and reads back identically.
//
//   indrive::config::Schema schema;
//   schema.add_int("replay.capacity", 100000, "steps kept in replay", 1, 100000000)
//         .add_choice("method", "disag", {"disag", "icm", "rnd"}, "intrinsic module");
//   schema.add_preset("tiny", {{"replay.capacity", "1000"}}, "unit tests, CI smoke");
//   auto config = indrive::config::Config::resolve(
//       schema, {.preset = "tiny", .file = "run.yaml", .overrides = {"method=icm"}});
//   int capacity = config.get<int>("replay.capacity");
//
// Every mistake in a file, preset or override throws ConfigError naming the key, where it came
// from and what is allowed (unknown keys come with the closest known key).
#pragma once

#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace indrive::config {

// A configuration file, preset or override is wrong; the message says what is allowed.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class Type { kInt, kFloat, kBool, kString, kChoice, kNumberList };

// Name of a type as used in messages, e.g. "integer".
std::string_view type_name(Type type);

// One resolved value: int64 for kInt, double for kFloat, bool, string for kString and
// kChoice, a vector of doubles for kNumberList.
using Value = std::variant<std::int64_t, double, bool, std::string, std::vector<double>>;

// Declaration of one key.
struct KeySpec {
  std::string key;  // dotted, e.g. "replay.capacity"
  Type type = Type::kInt;
  Value default_value;
  double min = -std::numeric_limits<double>::infinity();  // for numbers and list elements
  double max = std::numeric_limits<double>::infinity();
  std::vector<std::string> choices{};  // for kChoice
  std::string doc{};                   // one line
};

// A named bundle of overrides applied before the YAML file.
struct Preset {
  std::string name;
  std::vector<std::pair<std::string, std::string>> overrides;  // key, value as text
  std::string doc;
};

// The set of known keys and presets. Declaring a key twice, or a key that is also a group of
// other keys ("a.b" next to "a.b.c"), is a bug and aborts.
class Schema {
 public:
  // Declares an integer key with an inclusive range.
  Schema& add_int(std::string key, std::int64_t default_value, std::string doc,
                  std::int64_t min = std::numeric_limits<std::int64_t>::min(),
                  std::int64_t max = std::numeric_limits<std::int64_t>::max());
  // Declares a floating-point key with an inclusive range.
  Schema& add_float(std::string key, double default_value, std::string doc,
                    double min = -std::numeric_limits<double>::infinity(),
                    double max = std::numeric_limits<double>::infinity());
  // Declares a boolean key.
  Schema& add_bool(std::string key, bool default_value, std::string doc);
  // Declares a free-text key.
  Schema& add_string(std::string key, std::string default_value, std::string doc);
  // Declares a key whose value must be one of `choices`.
  Schema& add_choice(std::string key, std::string default_value, std::vector<std::string> choices,
                     std::string doc);
  // Declares a list of numbers, each within the inclusive range.
  Schema& add_number_list(std::string key, std::vector<double> default_value, std::string doc,
                          double min = -std::numeric_limits<double>::infinity(),
                          double max = std::numeric_limits<double>::infinity());
  // Registers a preset; its overrides are checked when it is applied.
  Schema& add_preset(std::string name, std::vector<std::pair<std::string, std::string>> overrides,
                     std::string doc);

  // The declaration of `key`, or nullptr.
  const KeySpec* find(std::string_view key) const;
  // The preset called `name`, or nullptr.
  const Preset* find_preset(std::string_view name) const;
  // All keys, sorted.
  const std::map<std::string, KeySpec, std::less<>>& keys() const { return keys_; }
  // All presets by name.
  const std::map<std::string, Preset, std::less<>>& presets() const { return presets_; }
  // The known key closest to `key` by edit distance, or "" when none is close.
  std::string closest_key(std::string_view key) const;
  // Human-readable list of keys (type, default, allowed values, doc) and presets, for --help.
  std::string describe() const;

 private:
  Schema& add(KeySpec spec);
  std::map<std::string, KeySpec, std::less<>> keys_;
  std::map<std::string, Preset, std::less<>> presets_;
};

// Where a configuration comes from, applied in this order after the schema defaults.
struct Sources {
  std::string preset{};                  // empty: the file's or --set's `preset`, if any
  std::filesystem::path file{};          // YAML file; empty: none
  std::vector<std::string> overrides{};  // "a.b=c" each, from --set
};

// A fully resolved configuration: one value for every key of its schema.
class Config {
 public:
  // Resolves defaults -> preset -> file -> overrides; throws ConfigError on any mistake.
  static Config resolve(const Schema& schema, const Sources& sources);
  // As resolve, with YAML text in place of a file; `origin` names it in messages.
  static Config resolve_text(const Schema& schema, std::string_view yaml_text,
                             std::string_view origin, const Sources& sources = {});

  // The value of `key` as T (int, int64_t, double, float, bool, std::string,
  // std::vector<double>); throws ConfigError for an unknown key or a type that does not fit.
  template <typename T>
  T get(std::string_view key) const;

  // Parses `text` for `key` and stores it; `origin` names the source in error messages.
  void set(std::string_view key, std::string_view text, std::string_view origin);
  // Applies one "a.b=c" override; throws ConfigError when malformed.
  void apply_override(std::string_view assignment);

  // The preset that was applied ("" when none).
  const std::string& preset() const { return preset_; }
  // Where the preset's name came from ("--set preset=tiny", "config file f line 1"); "" when
  // none was applied.
  const std::string& preset_origin() const { return preset_origin_; }
  // Where the value of `key` came from: "preset 'tiny'", "config file f line 3", "--set k=v" or
  // the origin given to set(); "" while it holds the schema default.
  std::string origin(std::string_view key) const;
  // The resolved configuration as nested YAML (keys sorted), readable by resolve().
  std::string to_yaml() const;
  // Writes to_yaml() to `path`; throws ConfigError when the file cannot be written.
  void write_yaml(const std::filesystem::path& path) const;

  const Schema& schema() const { return *schema_; }
  const std::map<std::string, Value, std::less<>>& values() const { return values_; }
  bool operator==(const Config& other) const {
    return preset_ == other.preset_ && values_ == other.values_;
  }

 private:
  explicit Config(const Schema& schema);
  void apply_preset(std::string_view name, std::string_view origin);
  void apply_yaml(std::string_view yaml_text, std::string_view origin, bool skip_preset_key);
  const Value& lookup(std::string_view key, Type* type) const;

  const Schema* schema_;
  std::string preset_;
  std::string preset_origin_;
  std::map<std::string, Value, std::less<>> values_;
  // Origin of every value set after the defaults (not compared: it says how, not what).
  std::map<std::string, std::string, std::less<>> origins_;
};

// The configuration flags every executable shares, parsed from argv.
struct CommandLine {
  Sources sources;                  // --config FILE, --preset NAME, --set KEY=VALUE (repeatable)
  bool help = false;                // --help or -h
  std::vector<std::string> rest{};  // arguments this parser does not own, in order
};

// Parses --config, --preset, --set (each also as --flag=value) and --help; `aliases` maps extra
// flags to keys, e.g. {"--dds-profiles", "dds.profiles_file"} turns `--dds-profiles F` into
// `--set dds.profiles_file=F`. Throws ConfigError when a flag lacks its value.
CommandLine parse_command_line(int argc, const char* const* argv,
                               const std::map<std::string, std::string>& aliases = {});

}  // namespace indrive::config
