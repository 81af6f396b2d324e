#include "indrive/basics/config.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <optional>
#include <sstream>

#include "indrive/basics/check.h"

namespace indrive::config {
namespace {

// The top-level key that names a preset inside a file or an override.
constexpr std::string_view kPresetKey = "preset";

std::string format_number(double value) {
  char buffer[64];
  // Shortest text that reads back to the same double, so the resolved YAML round-trips; plain
  // digits for everyday magnitudes (100000000, not 1e+08).
  const double magnitude = std::fabs(value);
  const auto format = (magnitude == 0.0 || (magnitude >= 1e-4 && magnitude < 1e15))
                          ? std::chars_format::fixed
                          : std::chars_format::general;
  auto [end, error] = std::to_chars(buffer, buffer + sizeof(buffer), value, format);
  INDRIVE_CHECK(error == std::errc()) << "to_chars failed";
  return std::string(buffer, end);
}

std::string format_range(const KeySpec& spec) {
  std::ostringstream out;
  out << "[" << (std::isinf(spec.min) ? "-inf" : format_number(spec.min)) << ", "
      << (std::isinf(spec.max) ? "inf" : format_number(spec.max)) << "]";
  return out.str();
}

std::string join(const std::vector<std::string>& items, std::string_view separator) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) {
    if (i > 0) out += separator;
    out += items[i];
  }
  return out;
}

std::string format_value(const Value& value) {
  struct Visitor {
    std::string operator()(std::int64_t v) const { return std::to_string(v); }
    std::string operator()(double v) const { return format_number(v); }
    std::string operator()(bool v) const { return v ? "true" : "false"; }
    std::string operator()(const std::string& v) const { return v; }
    std::string operator()(const std::vector<double>& v) const {
      std::vector<std::string> items;
      for (double x : v) items.push_back(format_number(x));
      return "[" + join(items, ", ") + "]";
    }
  };
  return std::visit(Visitor{}, value);
}

std::string trim(std::string_view text) {
  const auto begin = text.find_first_not_of(" \t\r\n");
  if (begin == std::string_view::npos) return "";
  const auto end = text.find_last_not_of(" \t\r\n");
  return std::string(text.substr(begin, end - begin + 1));
}

std::string lower(std::string_view text) {
  std::string out(text);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

[[noreturn]] void fail(std::string_view origin, std::string_view key, const std::string& problem) {
  throw ConfigError(std::string(origin) + ": key '" + std::string(key) + "': " + problem);
}

bool parse_double(std::string_view text, double* out) {
  // from_chars rejects a leading '+', which YAML allows.
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), *out);
  return error == std::errc() && end == text.data() + text.size() && std::isfinite(*out);
}

void check_range(const KeySpec& spec, double value, std::string_view origin) {
  if (value < spec.min || value > spec.max) {
    fail(origin, spec.key,
         "out of range: " + format_number(value) + " is not in " + format_range(spec) + " (" +
             spec.doc + ")");
  }
}

std::int64_t parse_int(const KeySpec& spec, const std::string& text, std::string_view origin) {
  std::string_view view = text;
  if (!view.empty() && view.front() == '+') view.remove_prefix(1);
  std::int64_t value = 0;
  auto [end, error] = std::from_chars(view.data(), view.data() + view.size(), value);
  if (error != std::errc() || end != view.data() + view.size()) {
    // Budgets read naturally as 5e5: accept a float text that is an exact integer.
    double as_double = 0.0;
    if (!parse_double(view, &as_double) || std::floor(as_double) != as_double ||
        std::fabs(as_double) > 9.0e18) {
      fail(origin, spec.key, "expected an integer, got '" + text + "'");
    }
    value = static_cast<std::int64_t>(as_double);
  }
  if (static_cast<double>(value) < spec.min || static_cast<double>(value) > spec.max) {
    fail(origin, spec.key,
         "out of range: " + std::to_string(value) + " is not in " + format_range(spec) + " (" +
             spec.doc + ")");
  }
  return value;
}

double parse_float(const KeySpec& spec, const std::string& text, std::string_view origin) {
  double value = 0.0;
  if (!parse_double(text, &value)) fail(origin, spec.key, "expected a number, got '" + text + "'");
  check_range(spec, value, origin);
  return value;
}

bool parse_bool(const KeySpec& spec, const std::string& text, std::string_view origin) {
  const std::string word = lower(text);
  if (word == "true" || word == "yes" || word == "on") return true;
  if (word == "false" || word == "no" || word == "off") return false;
  fail(origin, spec.key, "expected true or false, got '" + text + "'");
}

std::vector<double> parse_list_items(const KeySpec& spec, const std::vector<std::string>& items,
                                     std::string_view origin) {
  std::vector<double> values;
  for (const auto& item : items) {
    double value = 0.0;
    if (!parse_double(trim(item), &value)) {
      fail(origin, spec.key,
           "expected a list of numbers such as [5, 10, 20], but '" + item + "' is not a number");
    }
    check_range(spec, value, origin);
    values.push_back(value);
  }
  return values;
}

// Parses the text form of a value: a YAML scalar, or for lists "[a, b]" or "a,b".
Value parse_text(const KeySpec& spec, const std::string& raw, std::string_view origin) {
  const std::string text = trim(raw);
  switch (spec.type) {
    case Type::kInt:
      return parse_int(spec, text, origin);
    case Type::kFloat:
      return parse_float(spec, text, origin);
    case Type::kBool:
      return parse_bool(spec, text, origin);
    case Type::kString:
      return text;
    case Type::kChoice:
      if (std::find(spec.choices.begin(), spec.choices.end(), text) == spec.choices.end()) {
        fail(origin, spec.key,
             "'" + text + "' is not one of the choices: " + join(spec.choices, ", "));
      }
      return text;
    case Type::kNumberList: {
      std::string body = text;
      if (!body.empty() && body.front() == '[') {
        if (body.back() != ']') fail(origin, spec.key, "list '" + text + "' lacks its closing ']'");
        body = body.substr(1, body.size() - 2);
      }
      std::vector<std::string> items;
      if (!trim(body).empty()) {
        std::stringstream stream(body);
        for (std::string item; std::getline(stream, item, ',');) items.push_back(item);
      }
      return parse_list_items(spec, items, origin);
    }
  }
  INDRIVE_CHECK(false) << "unhandled type";
  return {};
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string unknown_key_message(const Schema& schema, std::string_view key) {
  std::string message = "unknown key";
  if (const std::string close = schema.closest_key(key); !close.empty()) {
    return message + "; did you mean '" + close + "'?";
  }
  // No close match: list the keys of the same group so the user sees what exists.
  const std::string group(key.substr(0, key.find('.')));
  std::vector<std::string> siblings;
  for (const auto& [name, spec] : schema.keys()) {
    if (name.rfind(group + ".", 0) == 0) siblings.push_back(name);
  }
  if (!siblings.empty())
    return message + "; keys under '" + group + ".' are: " + join(siblings, ", ");
  return message + "; no key starts with '" + group + "' (see --help for the list)";
}

std::string node_origin(std::string_view origin, const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  if (mark.is_null()) return std::string(origin);
  return std::string(origin) + " line " + std::to_string(mark.line + 1);
}

}  // namespace

std::string_view type_name(Type type) {
  switch (type) {
    case Type::kInt:
      return "integer";
    case Type::kFloat:
      return "number";
    case Type::kBool:
      return "boolean";
    case Type::kString:
      return "string";
    case Type::kChoice:
      return "choice";
    case Type::kNumberList:
      return "list of numbers";
  }
  return "unknown";
}

// ---- Schema -------------------------------------------------------------------------------

Schema& Schema::add(KeySpec spec) {
  INDRIVE_CHECK(!spec.key.empty() && spec.key.front() != '.' && spec.key.back() != '.' &&
                spec.key.find("..") == std::string::npos)
      << "malformed config key '" << spec.key << "'";
  INDRIVE_CHECK(spec.key != kPresetKey) << "'preset' is reserved for the preset mechanism";
  INDRIVE_CHECK(!keys_.contains(spec.key)) << "config key '" << spec.key << "' declared twice";
  // A key may not also be a group: YAML could not hold both "a.b: 1" and "a.b.c: 2".
  for (const auto& [name, other] : keys_) {
    INDRIVE_CHECK(name.rfind(spec.key + ".", 0) != 0 && spec.key.rfind(name + ".", 0) != 0)
        << "config keys '" << name << "' and '" << spec.key << "' overlap";
  }
  keys_.emplace(spec.key, std::move(spec));
  return *this;
}

Schema& Schema::add_int(std::string key, std::int64_t default_value, std::string doc,
                        std::int64_t min, std::int64_t max) {
  INDRIVE_CHECK(min <= default_value && default_value <= max) << "default of '" << key << "'";
  return add({.key = std::move(key),
              .type = Type::kInt,
              .default_value = default_value,
              .min = static_cast<double>(min),
              .max = static_cast<double>(max),
              .doc = std::move(doc)});
}

Schema& Schema::add_float(std::string key, double default_value, std::string doc, double min,
                          double max) {
  INDRIVE_CHECK(min <= default_value && default_value <= max) << "default of '" << key << "'";
  return add({.key = std::move(key),
              .type = Type::kFloat,
              .default_value = default_value,
              .min = min,
              .max = max,
              .doc = std::move(doc)});
}

Schema& Schema::add_bool(std::string key, bool default_value, std::string doc) {
  return add({.key = std::move(key),
              .type = Type::kBool,
              .default_value = default_value,
              .doc = std::move(doc)});
}

Schema& Schema::add_string(std::string key, std::string default_value, std::string doc) {
  return add({.key = std::move(key),
              .type = Type::kString,
              .default_value = std::move(default_value),
              .doc = std::move(doc)});
}

Schema& Schema::add_choice(std::string key, std::string default_value,
                           std::vector<std::string> choices, std::string doc) {
  INDRIVE_CHECK(std::find(choices.begin(), choices.end(), default_value) != choices.end())
      << "default of '" << key << "' is not one of its choices";
  return add({.key = std::move(key),
              .type = Type::kChoice,
              .default_value = std::move(default_value),
              .choices = std::move(choices),
              .doc = std::move(doc)});
}

Schema& Schema::add_number_list(std::string key, std::vector<double> default_value, std::string doc,
                                double min, double max) {
  for (double value : default_value) {
    INDRIVE_CHECK(min <= value && value <= max) << "default of '" << key << "'";
  }
  return add({.key = std::move(key),
              .type = Type::kNumberList,
              .default_value = std::move(default_value),
              .min = min,
              .max = max,
              .doc = std::move(doc)});
}

Schema& Schema::add_preset(std::string name,
                           std::vector<std::pair<std::string, std::string>> overrides,
                           std::string doc) {
  INDRIVE_CHECK(!name.empty() && !presets_.contains(name)) << "preset '" << name << "'";
  presets_.emplace(name, Preset{name, std::move(overrides), std::move(doc)});
  return *this;
}

const KeySpec* Schema::find(std::string_view key) const {
  auto it = keys_.find(key);
  return it == keys_.end() ? nullptr : &it->second;
}

const Preset* Schema::find_preset(std::string_view name) const {
  auto it = presets_.find(name);
  return it == presets_.end() ? nullptr : &it->second;
}

std::string Schema::closest_key(std::string_view key) const {
  std::string best;
  std::size_t best_distance = std::numeric_limits<std::size_t>::max();
  for (const auto& [name, spec] : keys_) {
    const std::size_t distance = edit_distance(key, name);
    if (distance < best_distance) {
      best_distance = distance;
      best = name;
    }
  }
  // Only typos count as close: a third of the key may differ, at least two characters.
  const std::size_t allowed = std::max<std::size_t>(2, key.size() / 3);
  return best_distance <= allowed ? best : "";
}

std::string Schema::describe() const {
  std::ostringstream out;
  for (const auto& [name, spec] : keys_) {
    out << name << " (" << type_name(spec.type) << ", default " << format_value(spec.default_value);
    if (spec.type == Type::kChoice) out << ", one of " << join(spec.choices, "|");
    if ((spec.type == Type::kInt || spec.type == Type::kFloat || spec.type == Type::kNumberList) &&
        (!std::isinf(spec.min) || !std::isinf(spec.max))) {
      out << ", in " << format_range(spec);
    }
    out << "): " << spec.doc << "\n";
  }
  for (const auto& [name, preset] : presets_) {
    out << "preset " << name << ": " << preset.doc << "\n";
  }
  return out.str();
}

// ---- Config -------------------------------------------------------------------------------

Config::Config(const Schema& schema) : schema_(&schema) {
  for (const auto& [name, spec] : schema.keys()) values_.emplace(name, spec.default_value);
}

Config Config::resolve(const Schema& schema, const Sources& sources) {
  std::string text;
  std::string origin;
  if (!sources.file.empty()) {
    std::ifstream in(sources.file);
    if (!in) {
      throw ConfigError("config file '" + sources.file.string() +
                        "' cannot be read; check the path given with --config");
    }
    std::ostringstream buffer;
    buffer << in.rdbuf();
    text = buffer.str();
    origin = "config file " + sources.file.string();
  }
  return resolve_text(schema, text, origin, sources);
}

Config Config::resolve_text(const Schema& schema, std::string_view yaml_text,
                            std::string_view origin, const Sources& sources) {
  Config config(schema);
  // The preset is applied first, so find its name: explicit > last --set preset= > file.
  std::string preset = sources.preset;
  std::string preset_origin = "preset argument";
  if (preset.empty()) {
    for (const auto& assignment : sources.overrides) {
      const auto eq = assignment.find('=');
      if (eq != std::string::npos && trim(assignment.substr(0, eq)) == kPresetKey) {
        preset = trim(assignment.substr(eq + 1));
        preset_origin = "--set " + assignment;
      }
    }
  }
  if (preset.empty() && !yaml_text.empty()) {
    try {
      const YAML::Node root = YAML::Load(std::string(yaml_text));
      if (root.IsMap() && root[std::string(kPresetKey)] &&
          root[std::string(kPresetKey)].IsScalar()) {
        preset = root[std::string(kPresetKey)].Scalar();
        preset_origin = node_origin(origin, root[std::string(kPresetKey)]);
      }
    } catch (const YAML::Exception&) {
      // Reported with its line by apply_yaml below.
    }
  }
  if (!preset.empty()) config.apply_preset(preset, preset_origin);
  if (!yaml_text.empty()) config.apply_yaml(yaml_text, origin, /*skip_preset_key=*/true);
  for (const auto& assignment : sources.overrides) config.apply_override(assignment);
  return config;
}

void Config::apply_preset(std::string_view name, std::string_view origin) {
  const Preset* preset = schema_->find_preset(name);
  if (preset == nullptr) {
    std::vector<std::string> names;
    for (const auto& [known, unused] : schema_->presets()) names.push_back(known);
    throw ConfigError(std::string(origin) + ": unknown preset '" + std::string(name) +
                      "'; known presets: " + (names.empty() ? "(none)" : join(names, ", ")));
  }
  for (const auto& [key, text] : preset->overrides) set(key, text, "preset '" + preset->name + "'");
  preset_ = preset->name;
  preset_origin_ = std::string(origin);
}

void Config::apply_yaml(std::string_view yaml_text, std::string_view origin, bool skip_preset_key) {
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml_text));
  } catch (const YAML::ParserException& error) {
    throw ConfigError(std::string(origin) + " line " + std::to_string(error.mark.line + 1) +
                      ": YAML syntax error: " + error.msg);
  }
  if (root.IsNull()) return;  // an empty file changes nothing
  if (!root.IsMap()) {
    throw ConfigError(std::string(origin) +
                      ": expected a map of keys at the top level (key: value lines)");
  }
  // Walk nested maps; "a: {b: 1}" and "a.b: 1" both set key "a.b".
  auto walk = [&](auto&& self, const YAML::Node& map, const std::string& prefix) -> void {
    for (const auto& item : map) {
      // YAML allows lists and maps as keys ("? [a, b]: 1"); a config key is a plain name.
      if (!item.first.IsScalar()) {
        throw ConfigError(node_origin(origin, item.first) +
                          ": a key must be a plain name such as 'learner.replay_ratio'");
      }
      const std::string name = prefix + item.first.as<std::string>();
      const YAML::Node& value = item.second;
      const std::string where = node_origin(origin, item.first);
      if (prefix.empty() && name == kPresetKey) {
        if (skip_preset_key) continue;
        throw ConfigError(where + ": 'preset' can only be chosen before the file is applied");
      }
      const KeySpec* spec = schema_->find(name);
      if (value.IsMap()) {
        if (spec != nullptr) {
          fail(where, name,
               "expected a " + std::string(type_name(spec->type)) + ", got a map of sub-keys");
        }
        self(self, value, name + ".");
        continue;
      }
      if (spec == nullptr) fail(where, name, unknown_key_message(*schema_, name));
      if (value.IsNull()) fail(where, name, "has no value");
      if (value.IsSequence()) {
        if (spec->type != Type::kNumberList) {
          fail(where, name, "expected a " + std::string(type_name(spec->type)) + ", got a list");
        }
        std::vector<std::string> items;
        for (const auto& element : value) {
          if (!element.IsScalar()) {
            fail(where, name, "expected a list of numbers such as [5, 10, 20]");
          }
          items.push_back(element.Scalar());
        }
        values_[spec->key] = parse_list_items(*spec, items, where);
        origins_[spec->key] = where;
        continue;
      }
      set(name, value.Scalar(), where);
    }
  };
  walk(walk, root, "");
}

void Config::set(std::string_view key, std::string_view text, std::string_view origin) {
  const KeySpec* spec = schema_->find(key);
  if (spec == nullptr) fail(origin, key, unknown_key_message(*schema_, key));
  values_[spec->key] = parse_text(*spec, std::string(text), origin);
  origins_[spec->key] = std::string(origin);
}

std::string Config::origin(std::string_view key) const {
  const auto it = origins_.find(key);
  return it == origins_.end() ? std::string() : it->second;
}

void Config::apply_override(std::string_view assignment) {
  const std::string origin = "--set " + std::string(assignment);
  const auto eq = assignment.find('=');
  if (eq == std::string_view::npos) {
    throw ConfigError(origin +
                      ": malformed override; write --set key=value, e.g. "
                      "--set replay.capacity=1000");
  }
  const std::string key = trim(assignment.substr(0, eq));
  if (key.empty()) {
    throw ConfigError(origin + ": malformed override: the key before '=' is empty");
  }
  if (key == kPresetKey) return;  // applied first, in resolve_text
  set(key, assignment.substr(eq + 1), origin);
}

const Value& Config::lookup(std::string_view key, Type* type) const {
  const KeySpec* spec = schema_->find(key);
  if (spec == nullptr) {
    throw ConfigError("config key '" + std::string(key) + "' read but never declared; " +
                      unknown_key_message(*schema_, key));
  }
  *type = spec->type;
  return values_.find(key)->second;
}

template <typename T>
T Config::get(std::string_view key) const {
  Type type;
  const Value& value = lookup(key, &type);
  auto mismatch = [&](std::string_view wanted) {
    return ConfigError("config key '" + std::string(key) + "' is a " +
                       std::string(type_name(type)) + ", read as " + std::string(wanted));
  };
  if constexpr (std::is_same_v<T, bool>) {
    if (type != Type::kBool) throw mismatch("boolean");
    return std::get<bool>(value);
  } else if constexpr (std::is_integral_v<T>) {
    if (type != Type::kInt) throw mismatch("integer");
    const std::int64_t v = std::get<std::int64_t>(value);
    if (v < static_cast<std::int64_t>(std::numeric_limits<T>::min()) ||
        (v > 0 && static_cast<std::uint64_t>(v) > std::numeric_limits<T>::max())) {
      throw ConfigError("config key '" + std::string(key) + "' = " + std::to_string(v) +
                        " does not fit the integer type it is read as");
    }
    return static_cast<T>(v);
  } else if constexpr (std::is_floating_point_v<T>) {
    if (type != Type::kFloat) throw mismatch("number");
    return static_cast<T>(std::get<double>(value));
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (type != Type::kString && type != Type::kChoice) throw mismatch("string");
    return std::get<std::string>(value);
  } else {
    static_assert(std::is_same_v<T, std::vector<double>>, "unsupported config value type");
    if (type != Type::kNumberList) throw mismatch("list of numbers");
    return std::get<std::vector<double>>(value);
  }
}

template int Config::get<int>(std::string_view) const;
template std::int64_t Config::get<std::int64_t>(std::string_view) const;
template std::uint32_t Config::get<std::uint32_t>(std::string_view) const;
template std::uint64_t Config::get<std::uint64_t>(std::string_view) const;
template double Config::get<double>(std::string_view) const;
template float Config::get<float>(std::string_view) const;
template bool Config::get<bool>(std::string_view) const;
template std::string Config::get<std::string>(std::string_view) const;
template std::vector<double> Config::get<std::vector<double>>(std::string_view) const;

std::string Config::to_yaml() const {
  // Build the nested tree in sorted key order, so groups come out contiguous and stable.
  YAML::Node root(YAML::NodeType::Map);
  if (!preset_.empty()) root[std::string(kPresetKey)] = preset_;
  for (const auto& [key, value] : values_) {
    std::vector<std::string> parts;
    std::stringstream stream(key);
    for (std::string part; std::getline(stream, part, '.');) parts.push_back(part);
    YAML::Node node = root;
    for (std::size_t i = 0; i + 1 < parts.size(); ++i) node.reset(node[parts[i]]);
    if (const auto* list = std::get_if<std::vector<double>>(&value)) {
      YAML::Node sequence(YAML::NodeType::Sequence);
      for (double x : *list) sequence.push_back(format_number(x));
      sequence.SetStyle(YAML::EmitterStyle::Flow);
      node[parts.back()] = sequence;
    } else {
      node[parts.back()] = format_value(value);
    }
  }
  YAML::Emitter out;
  out << root;
  return std::string("# Fully resolved configuration (defaults, preset, file, --set).\n") +
         out.c_str() + "\n";
}

void Config::write_yaml(const std::filesystem::path& path) const {
  std::ofstream out(path);
  out << to_yaml();
  if (!out) throw ConfigError("cannot write the resolved config to '" + path.string() + "'");
}

CommandLine parse_command_line(int argc, const char* const* argv,
                               const std::map<std::string, std::string>& aliases) {
  CommandLine line;
  for (int i = 1; i < argc; ++i) {
    std::string flag = argv[i];
    std::optional<std::string> value;
    if (const auto eq = flag.find('='); flag.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = flag.substr(eq + 1);
      flag = flag.substr(0, eq);
    }
    const bool owned =
        flag == "--config" || flag == "--preset" || flag == "--set" || aliases.contains(flag);
    if (flag == "--help" || flag == "-h") {
      line.help = true;
      continue;
    }
    if (!owned) {
      line.rest.push_back(argv[i]);
      continue;
    }
    if (!value) {
      if (i + 1 >= argc) throw ConfigError("flag " + flag + " needs a value");
      value = argv[++i];
    }
    if (flag == "--config") {
      line.sources.file = *value;
    } else if (flag == "--preset") {
      line.sources.preset = *value;
    } else if (flag == "--set") {
      line.sources.overrides.push_back(*value);
    } else {
      line.sources.overrides.push_back(aliases.at(flag) + "=" + *value);
    }
  }
  return line;
}

}  // namespace indrive::config
