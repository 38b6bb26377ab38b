// libFuzzer target: the log ring's URL redaction (runtime/log.h redact_urls()), which reads log
// text that carries attacker-influenced strings (error messages, names). It must never crash;
// its result is redacted already (a second pass changes nothing); and a JSON line stays JSON
// (the ring's lines are spliced into GET /api/node/log's answer as they are).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "rcan/json.h"
#include "runtime/log.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  const std::string once = redact_urls(text);
  if (redact_urls(once) != once) std::abort();
  // The same bytes as a field of a log line: the redacted line must still parse.
  const std::string line =
      json::dump(json::Value(json::Object{{"event", "fuzz"}, {"text", std::string(text)}}));
  if (!json::parse(line).ok()) return 0;  // bytes the JSON reader refuses either way
  const std::string red = redact_urls(line);
  auto v = json::parse(red);
  if (!v.ok() || !v->is_object() || json::string_field(*v, "event") != "fuzz") std::abort();
  return 0;
}
