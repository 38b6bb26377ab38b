#include "node/admission/injection.h"

#include <algorithm>
#include <cctype>

namespace rcan::node {
namespace {

std::string fold(const std::string& s) {
  // Lower-case ASCII and collapse runs of whitespace, so "Ignore   previous\ninstructions"
  // matches "ignore previous instructions".
  std::string out;
  out.reserve(s.size());
  bool space = false;
  for (unsigned char c : s) {
    if (std::isspace(c)) {
      if (!space && !out.empty()) out.push_back(' ');
      space = true;
      continue;
    }
    space = false;
    out.push_back(static_cast<char>(std::tolower(c)));
  }
  if (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

}  // namespace

std::vector<std::string> InjectionScreen::default_patterns() {
  return {"ignore previous instructions",
          "ignore all previous instructions",
          "ignore prior instructions",
          "disregard previous instructions",
          "disregard all prior",
          "forget your instructions",
          "you are now",
          "system prompt",
          "override safety",
          "disable safety",
          "bypass safety",
          "developer mode"};
}

std::vector<InjectionRule> InjectionScreen::default_rules() {
  std::vector<InjectionRule> out;
  for (auto& p : default_patterns()) out.push_back(InjectionRule{std::move(p), false});
  return out;
}

InjectionScreen::InjectionScreen(std::vector<std::string> patterns) {
  for (auto& p : patterns) {
    std::string f = fold(p);
    if (!f.empty()) patterns_.push_back(std::move(f));
  }
}

InjectionScreen::InjectionScreen(const std::vector<InjectionRule>& rules, std::string* error) {
  for (const auto& r : rules) {
    if (!r.regex) {
      std::string f = fold(r.text);
      if (!f.empty()) patterns_.push_back(std::move(f));
      continue;
    }
    try {
      regexes_.push_back(Regex{r.text, std::make_shared<const std::regex>(
                                           r.text, std::regex::ECMAScript | std::regex::icase)});
    } catch (const std::regex_error& e) {
      if (error && error->empty())
        *error = "injection pattern /" + r.text + "/ is not a regular expression: " + e.what();
    }
  }
}

bool InjectionScreen::regex_hit(const Regex& r, const std::string& folded) const {
  const size_t step = kRegexWindow - kRegexOverlap;
  for (size_t at = 0;; at += step) {
    const size_t len = std::min(kRegexWindow, folded.size() - at);
    try {
      if (std::regex_search(folded.begin() + static_cast<std::ptrdiff_t>(at),
                            folded.begin() + static_cast<std::ptrdiff_t>(at + len), *r.re))
        return true;
    } catch (const std::regex_error&) {
      return true;  // the engine gave up (complexity, stack): fail closed
    }
    if (at + len >= folded.size()) return false;
  }
}

std::optional<std::string> InjectionScreen::scan_text(const std::string& text) const {
  if (patterns_.empty() && regexes_.empty()) return std::nullopt;
  std::string f = fold(text);
  for (const auto& p : patterns_)
    if (f.find(p) != std::string::npos) return p;
  for (const auto& r : regexes_)
    if (regex_hit(r, f)) return r.source;
  return std::nullopt;
}

std::optional<std::string> InjectionScreen::scan(const json::Value& value) const {
  switch (value.kind()) {
    case json::Value::Kind::kString:
      return scan_text(value.as_string());
    case json::Value::Kind::kArray:
      for (const auto& e : value.as_array())
        if (auto hit = scan(e)) return hit;
      return std::nullopt;
    case json::Value::Kind::kObject:
      for (const auto& m : value.as_object()) {
        if (auto hit = scan_text(m.first)) return hit;
        if (auto hit = scan(m.second)) return hit;
      }
      return std::nullopt;
    default:
      return std::nullopt;
  }
}

}  // namespace rcan::node
