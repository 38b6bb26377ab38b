// JSON-lines logging on stderr, shared by the node and its transports.
//
// Each call writes one line: {"ts":"2025-06-15T12:34:56.789Z","level":"info","event":"…",…}
// followed by the caller's fields in the order given. Lines are written whole under a mutex,
// so concurrent callers never interleave. Messages below the global level are dropped
// before any formatting work beyond the caller's own argument construction.
//
// Never pass tokens, keys or request bodies as fields.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <string_view>

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

}  // namespace rcan
