// libFuzzer target: transport's Router (src/transport/router.h) — path patterns and the paths
// anyone sends. Input: lines; the first is a method, the second a path, the rest patterns.
// Must never crash; a match fills one parameter per `{…}` and `*` segment (a `{…}` one non-empty,
// at most 128 bytes and without '/'; a `*` one non-empty) and matches the same without them;
// find() on a table of the patterns returns a row that serves the method and whose pattern
// matches the path, a 405 that lists methods, or a 404 on a path no pattern matches.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "transport/router.h"

namespace {

// The variable segments of `pattern`, in order: true for `{…}`, false for a final `*`.
std::vector<bool> variable_segments(std::string_view pattern) {
  std::vector<bool> kinds;
  for (size_t at = 1; at <= pattern.size();) {
    size_t end = pattern.find('/', at);
    std::string_view seg = pattern.substr(at, end == std::string_view::npos ? end : end - at);
    if (seg.size() > 2 && seg.front() == '{' && seg.back() == '}') kinds.push_back(true);
    if (seg == "*" && end == std::string_view::npos) kinds.push_back(false);
    if (end == std::string_view::npos) break;
    at = end + 1;
  }
  return kinds;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using rcan::transport::match_path;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  std::vector<std::string> lines;
  while (!text.empty() && lines.size() < 18) {
    const size_t nl = text.find('\n');
    lines.emplace_back(text.substr(0, nl));
    text = nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
  }
  if (lines.size() < 2) return 0;
  const std::string& method = lines[0];
  const std::string& path = lines[1];
  rcan::transport::Router<size_t> router;
  const char* methods[] = {"GET", "POST", "*"};
  for (size_t i = 2; i < lines.size(); ++i) {
    const std::string& pattern = lines[i];
    std::vector<std::string> params;
    const bool matched = match_path(pattern, path, &params);
    if (matched != match_path(pattern, path, nullptr)) std::abort();
    if (matched) {
      const std::vector<bool> kinds = variable_segments(pattern);
      if (params.size() != kinds.size()) std::abort();
      for (size_t k = 0; k < params.size(); ++k) {
        if (params[k].empty()) std::abort();
        if (kinds[k] && (params[k].size() > 128 || params[k].find('/') != std::string::npos))
          std::abort();
      }
    }
    router.add(methods[i % 3], pattern, i);
  }
  const auto m = router.find(method, path);
  if (m.found()) {
    if (m.route->method != method && m.route->method != "*") std::abort();
    if (!match_path(m.route->pattern, path, nullptr)) std::abort();
  } else if (m.method_not_allowed()) {
    if (m.allow.empty() || !match_path(m.path->pattern, path, nullptr)) std::abort();
  } else {
    for (size_t i = 2; i < lines.size(); ++i)
      if (match_path(lines[i], path, nullptr)) std::abort();
    if (!m.params.empty()) std::abort();
  }
  return 0;
}
