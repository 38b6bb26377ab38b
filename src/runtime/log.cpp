#include "runtime/log.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <deque>
#include <utility>

#include "base/clock.h"
#include "base/thread_annotations.h"

namespace rcan {
namespace {

std::atomic<int> g_level{static_cast<int>(LogLevel::kInfo)};

// Where lines go (stderr while `sink` is empty), and the lock that keeps each line whole.
struct Output {
  Mutex mu;
  std::function<void(std::string_view)> sink GUARDED_BY(mu);
};

// The last kLogRingCapacity lines (redacted), under a lock of its own so that a reader never
// waits for a write to stderr.
struct Ring {
  Mutex mu;
  std::deque<std::string> lines GUARDED_BY(mu);
  uint64_t written GUARDED_BY(mu) = 0;
};

Ring& ring() {
  static Ring r;
  return r;
}

bool url_end(char c) {
  return c == '"' || c == '\\' || c == '\'' || c == '<' || c == '>' ||
         static_cast<unsigned char>(c) <= ' ';
}

bool scheme_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '+' ||
         c == '-' || c == '.';
}

void keep(const std::string& text, const std::string& ts, LogLevel level, std::string_view event) {
  std::string kept = redact_urls(text);
  if (kept.size() > kLogRingMaxLine) {
    json::Object small;
    small.append_unchecked("ts", ts);
    small.append_unchecked("level", std::string(log_level_name(level)));
    small.append_unchecked("event", redact_urls(event.substr(0, 256)));
    small.append_unchecked("truncated", static_cast<int64_t>(kept.size()));
    kept = json::dump(json::Value(std::move(small)));
  }
  Ring& r = ring();
  MutexLock lock(r.mu);
  r.lines.push_back(std::move(kept));
  while (r.lines.size() > kLogRingCapacity) r.lines.pop_front();
  ++r.written;
}

Output& output() {
  static Output out;
  return out;
}

// ISO 8601 UTC with milliseconds.
std::string now_iso8601() {
  const int64_t ms = unix_ms();
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
  const std::string ts = now_iso8601();
  line.append_unchecked("ts", ts);
  line.append_unchecked("level", std::string(log_level_name(level)));
  line.append_unchecked("event", std::string(event));
  for (auto& [k, v] : fields) {
    if (k == "ts" || k == "level" || k == "event") continue;
    line.set(k, std::move(v));
  }
  std::string text = json::dump(json::Value(std::move(line)));
  keep(text, ts, level, event);
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

RecentLog recent_log_lines(size_t limit) {
  RecentLog out;
  Ring& r = ring();
  MutexLock lock(r.mu);
  const size_t n = std::min(limit, r.lines.size());
  out.lines.assign(r.lines.end() - static_cast<std::ptrdiff_t>(n), r.lines.end());
  out.written = r.written;
  return out;
}

std::string redact_urls(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  size_t done = 0;  // text[0, done) is in `out`
  for (size_t at = text.find("://"); at != std::string_view::npos;
       at = text.find("://", std::max(at + 3, done))) {
    size_t start = at;
    while (start > done && scheme_char(text[start - 1])) --start;
    if (start == at) continue;  // no scheme before "://"
    std::string_view scheme = text.substr(start, at - start);
    if (scheme == "rcan" || scheme == "RCAN") continue;  // a RURI: the robot's public name
    size_t host = at + 3;
    size_t end = host;
    while (end < text.size() && !url_end(text[end])) ++end;
    size_t auth_end = host;
    while (auth_end < end && text[auth_end] != '/' && text[auth_end] != '?' &&
           text[auth_end] != '#')
      ++auth_end;
    std::string_view authority = text.substr(host, auth_end - host);
    if (size_t a = authority.rfind('@'); a != std::string_view::npos)
      authority.remove_prefix(a + 1);
    out.append(text.substr(done, host - done));
    out.append(authority);
    if (auth_end < end) out.append("/\xe2\x80\xa6");  // "/…"
    done = end;
  }
  out.append(text.substr(done));
  return out;
}

}  // namespace rcan
