// InjectionScreen — the prompt-injection scan of the safety invariants (v1.1 invariant 7):
// every string in a command's payload is matched, case-insensitively, against configured
// patterns before anything reaches a model or a driver. A hit refuses the command with
// COMMAND_REJECTED, reason prompt_injection (audited as INJECTION_BLOCKED).
//
// A pattern is a substring or an ECMAScript regular expression (security.injection.patterns,
// `{regex: …}`). Both see each string folded: ASCII lower-case, every run of whitespace one
// space. A regular expression is searched in windows of kRegexWindow bytes that overlap by
// kRegexOverlap (bounded work and recursion per window, whatever the string's length): a match
// is found when it lies within one window, which every match of up to kRegexOverlap bytes does.
// A search that the regex engine gives up on (too complex) counts as a hit: fail closed.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <regex>
#include <string>
#include <vector>

#include "rcan/json.h"

namespace rcan::node {

struct InjectionRule {
  std::string text;  // a substring, or an ECMAScript regular expression when `regex`
  bool regex = false;
};

class InjectionScreen {
 public:
  static constexpr size_t kRegexWindow = 1024;
  static constexpr size_t kRegexOverlap = 256;

  // The default patterns when the configuration names none (substrings).
  static std::vector<std::string> default_patterns();
  static std::vector<InjectionRule> default_rules();
  // Substrings only.
  explicit InjectionScreen(std::vector<std::string> patterns);
  // A rule whose regular expression does not compile is an error the config loader reports
  // (security.injection.patterns[i].regex); here it is skipped and `error` says which.
  explicit InjectionScreen(const std::vector<InjectionRule>& rules, std::string* error = nullptr);

  // The first pattern found in any string (keys included) of `value`, or nullopt.
  std::optional<std::string> scan(const json::Value& value) const;
  std::optional<std::string> scan_text(const std::string& text) const;

 private:
  struct Regex {
    std::string source;  // as configured, what a hit names
    std::shared_ptr<const std::regex> re;
  };
  bool regex_hit(const Regex& r, const std::string& folded) const;

  std::vector<std::string> patterns_;  // lower-cased substrings
  std::vector<Regex> regexes_;
};

}  // namespace rcan::node
