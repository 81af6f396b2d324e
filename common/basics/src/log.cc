#include "indrive/basics/log.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <stdexcept>
#include <string>

namespace indrive::log {
namespace {

std::mutex& sink_mutex() {
  static std::mutex mutex;
  return mutex;
}
Sink& sink_slot() {
  static Sink sink;
  return sink;
}
std::atomic<Level>& level_slot() {
  static std::atomic<Level> current{Level::kInfo};
  return current;
}

// Default sink: "2026-11-23 08:30:01.123 I [dds] message" on stderr.
void write_stderr(const Record& record) {
  using namespace std::chrono;
  const auto now = system_clock::now();
  const std::time_t seconds = system_clock::to_time_t(now);
  const auto millis = duration_cast<milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm tm{};
  localtime_r(&seconds, &tm);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%d %H:%M:%S", &tm);
  std::fprintf(stderr, "%s.%03d %c [%.*s] %.*s\n", stamp, static_cast<int>(millis),
               "DIWEO"[static_cast<int>(record.level)], static_cast<int>(record.category.size()),
               record.category.data(), static_cast<int>(record.message.size()),
               record.message.data());
}

}  // namespace

void set_sink(Sink sink) {
  std::lock_guard lock(sink_mutex());
  sink_slot() = std::move(sink);
}

void set_level(Level level) { level_slot().store(level); }
Level level() { return level_slot().load(std::memory_order_relaxed); }

Level parse_level(std::string_view name) {
  if (name == "debug") return Level::kDebug;
  if (name == "info") return Level::kInfo;
  if (name == "warn") return Level::kWarn;
  if (name == "error") return Level::kError;
  if (name == "off") return Level::kOff;
  throw std::invalid_argument("unknown log level '" + std::string(name) +
                              "': use debug, info, warn, error or off");
}

std::string_view level_name(Level level) {
  switch (level) {
    case Level::kDebug:
      return "debug";
    case Level::kInfo:
      return "info";
    case Level::kWarn:
      return "warn";
    case Level::kError:
      return "error";
    case Level::kOff:
      return "off";
  }
  return "?";
}

void write(Level level, std::string_view category, std::string_view message, const char* file,
           int line) {
  if (level < log::level()) return;
  const Record record{level, category, message, file, line};
  std::lock_guard lock(sink_mutex());
  if (sink_slot()) {
    sink_slot()(record);
  } else {
    write_stderr(record);
  }
}

}  // namespace indrive::log
