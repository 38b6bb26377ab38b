#include "base/log.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <utility>

#include "base/thread_annotations.h"

namespace rcan {
namespace {

std::atomic<int> g_level{static_cast<int>(LogLevel::kInfo)};

// Where lines go (stderr while `sink` is empty), and the lock that keeps each line whole.
struct Output {
  Mutex mu;
  std::function<void(std::string_view)> sink GUARDED_BY(mu);
};

Output& output() {
  static Output out;
  return out;
}

// ISO 8601 UTC with milliseconds.
std::string now_iso8601() {
  const auto now = std::chrono::system_clock::now();
  const auto ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count();
  const std::time_t secs = static_cast<std::time_t>(ms / 1000);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[96];
  const int frac = static_cast<int>(ms % 1000);
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900,
                tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, frac < 0 ? 0 : frac);
  return buf;
}

}  // namespace

std::string_view log_level_name(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarn:
      return "warn";
    case LogLevel::kError:
      return "error";
  }
  return "info";
}

std::optional<LogLevel> parse_log_level(std::string_view name) {
  if (name == "debug") return LogLevel::kDebug;
  if (name == "info") return LogLevel::kInfo;
  if (name == "warn" || name == "warning") return LogLevel::kWarn;
  if (name == "error") return LogLevel::kError;
  return std::nullopt;
}

void set_log_level(LogLevel level) { g_level.store(static_cast<int>(level)); }
LogLevel log_level() { return static_cast<LogLevel>(g_level.load(std::memory_order_relaxed)); }

void log(LogLevel level, std::string_view event, json::Object fields) {
  if (!log_enabled(level)) return;
  json::Object line;
  line.append_unchecked("ts", now_iso8601());
  line.append_unchecked("level", std::string(log_level_name(level)));
  line.append_unchecked("event", std::string(event));
  for (auto& [k, v] : fields) {
    if (k == "ts" || k == "level" || k == "event") continue;
    line.set(k, std::move(v));
  }
  std::string text = json::dump(json::Value(std::move(line)));
  Output& out = output();
  MutexLock lock(out.mu);
  if (out.sink) {
    out.sink(text);
    return;
  }
  text.push_back('\n');
  std::fwrite(text.data(), 1, text.size(), stderr);
  std::fflush(stderr);
}

void set_log_sink(std::function<void(std::string_view line)> sink) {
  Output& out = output();
  MutexLock lock(out.mu);
  out.sink = std::move(sink);
}

}  // namespace rcan
