// One logging sink for the whole project.
//
// Library code never writes to stdout or stderr directly: it logs through this sink with a
// level and a category, and the executable decides where the lines go (stderr by default).
//
//   INDRIVE_LOG(kInfo, "learner") << "snapshot v" << version << " published";
//   indrive::log::set_level(indrive::log::Level::kDebug);
//   indrive::log::set_sink([](const indrive::log::Record& r) { ... });
#pragma once

#include <functional>
#include <sstream>
#include <string>
#include <string_view>

namespace indrive::log {

enum class Level { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3, kOff = 4 };

// One log line as handed to the sink.
struct Record {
  Level level;
  std::string_view category;  // subsystem, e.g. "dds", "env", "learner"
  std::string_view message;
  const char* file;
  int line;
};

using Sink = std::function<void(const Record&)>;

// Replaces the sink; an empty function restores the default (stderr, one line per record).
void set_sink(Sink sink);
// Records below this level are dropped before formatting.
void set_level(Level level);
Level level();
// Parses "debug" | "info" | "warn" | "error" | "off"; throws std::invalid_argument otherwise.
Level parse_level(std::string_view name);
std::string_view level_name(Level level);

// Sends one record to the sink (thread-safe).
void write(Level level, std::string_view category, std::string_view message, const char* file,
           int line);

// Collects a message with operator<< and writes it when destroyed.
class Line {
 public:
  Line(Level level, std::string_view category, const char* file, int line)
      : level_(level), category_(category), file_(file), line_(line) {}
  ~Line() { write(level_, category_, stream_.str(), file_, line_); }
  template <typename T>
  Line& operator<<(const T& value) {
    stream_ << value;
    return *this;
  }

 private:
  Level level_;
  std::string_view category_;
  const char* file_;
  int line_;
  std::ostringstream stream_;
};

}  // namespace indrive::log

#define INDRIVE_LOG(severity, category)                            \
  if (::indrive::log::Level::severity < ::indrive::log::level()) { \
  } else                                                           \
    ::indrive::log::Line(::indrive::log::Level::severity, category, __FILE__, __LINE__)

// Same as INDRIVE_LOG with a level chosen at run time: INDRIVE_LOG_AT(ok ? kInfo : kWarn, ...).
#define INDRIVE_LOG_AT(level_value, category)    \
  if ((level_value) < ::indrive::log::level()) { \
  } else                                         \
    ::indrive::log::Line((level_value), category, __FILE__, __LINE__)
