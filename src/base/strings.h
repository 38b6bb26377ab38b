// ASCII string helpers: case folding, splitting and trimming for protocol text (header names,
// scopes, role and action names, prefixes). ASCII only, on purpose: protocol tokens are ASCII,
// and a locale must never change how a header or a role name compares. Header-only, so the
// library and the CLI use them without linking rcan_base.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace rcan {

// `s` with A-Z folded to a-z; every other byte (UTF-8 included) unchanged.
inline std::string ascii_lower(std::string_view s) {
  std::string out(s);
  for (char& c : out)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return out;
}

// `s` with a-z folded to A-Z; every other byte unchanged.
inline std::string ascii_upper(std::string_view s) {
  std::string out(s);
  for (char& c : out)
    if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
  return out;
}

// `s` without the leading and trailing characters found in `chars` (by default ASCII blanks:
// space, tab, CR, LF). The view points into `s`.
inline std::string_view trim(std::string_view s, std::string_view chars = " \t\r\n") {
  while (!s.empty() && chars.find(s.front()) != std::string_view::npos) s.remove_prefix(1);
  while (!s.empty() && chars.find(s.back()) != std::string_view::npos) s.remove_suffix(1);
  return s;
}

// The fields of `s` between the separators `sep`, in order; with `keep_empty` false, the empty
// fields ("a,,b", a leading or trailing separator, an empty `s`) are dropped. The views point
// into `s`.
inline std::vector<std::string_view> split(std::string_view s, char sep, bool keep_empty = true) {
  std::vector<std::string_view> out;
  size_t start = 0;
  while (true) {
    const size_t at = s.find(sep, start);
    const std::string_view field =
        s.substr(start, at == std::string_view::npos ? std::string_view::npos : at - start);
    if (keep_empty || !field.empty()) out.push_back(field);
    if (at == std::string_view::npos) break;
    start = at + 1;
  }
  return out;
}

}  // namespace rcan
