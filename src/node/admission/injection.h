// InjectionScreen — the prompt-injection scan of the safety invariants (v1.1 invariant 7):
// every string in a command's payload is matched, case-insensitively, against configured
// patterns before anything reaches a model or a driver. A hit refuses the command with
// COMMAND_REJECTED, reason prompt_injection (audited as INJECTION_BLOCKED).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "rcan/json.h"

namespace rcan::node {

class InjectionScreen {
 public:
  // The default patterns when the configuration names none.
  static std::vector<std::string> default_patterns();
  explicit InjectionScreen(std::vector<std::string> patterns);

  // The first pattern found in any string (keys included) of `value`, or nullopt.
  std::optional<std::string> scan(const json::Value& value) const;
  std::optional<std::string> scan_text(const std::string& text) const;

 private:
  std::vector<std::string> patterns_;  // lower-cased
};

}  // namespace rcan::node
