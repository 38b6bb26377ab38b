// JSON-lines logging on stderr, shared by the node and its transports.
//
// Each call writes one line: {"ts":"2025-06-15T12:34:56.789Z","level":"info","event":"…",…}
// followed by the caller's fields in the order given. Lines are written whole under a mutex,
// so concurrent callers never interleave. Messages below the global level are dropped
// before any formatting work beyond the caller's own argument construction.
//
// Never pass tokens, keys or request bodies as fields.
//
// The last kLogRingCapacity lines written are also kept in memory (recent_log_lines(), read by
// the node's GET /api/node/log), with every URL but a RURI cut to its scheme, host and port: a
// broker or webhook URL may carry credentials in its user part or a secret in its path or
// query, and the ring's lines leave the process.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/json.h"

namespace rcan {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3 };

// "debug", "info", "warn", "error".
std::string_view log_level_name(LogLevel level);
// Inverse of log_level_name() (also accepts "warning"); nullopt for anything else.
std::optional<LogLevel> parse_log_level(std::string_view name);

// The global threshold (default kInfo). Thread-safe.
void set_log_level(LogLevel level);
LogLevel log_level();
inline bool log_enabled(LogLevel level) { return level >= log_level(); }

// Writes one JSON line to stderr (or to the test sink). `fields` must not contain "ts",
// "level" or "event" (they would be duplicated keys; such fields are dropped).
void log(LogLevel level, std::string_view event, json::Object fields = {});

// Tests: route lines (without the trailing newline) to `sink` instead of stderr;
// an empty function restores stderr.
void set_log_sink(std::function<void(std::string_view line)> sink);

inline constexpr size_t kLogRingCapacity = 200;
// A line longer than this is kept in the ring as its ts, level and event with "truncated": its
// size (stderr still gets it whole).
inline constexpr size_t kLogRingMaxLine = 4096;

struct RecentLog {
  std::vector<std::string> lines;  // JSON texts, oldest first, URLs redacted
  uint64_t written = 0;            // lines written since start (the ring dropped written - size)
};
// The newest `limit` lines of the ring (at most kLogRingCapacity). Thread-safe.
RecentLog recent_log_lines(size_t limit);

// Every `scheme://…` in `text` cut to `scheme://host[:port]`, the user part dropped and any
// path, query or fragment replaced by "/…"; RURIs (`rcan://`, public names) are kept whole. A URL
// ends at whitespace, a quote, a backslash or the end, so applied to JSON text it never breaks an
// escape.
std::string redact_urls(std::string_view text);

}  // namespace rcan
