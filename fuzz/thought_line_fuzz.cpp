// libFuzzer target: one line of the §16.5 thought file (node/ai/thoughts.h). parse_thought_line()
// must never crash; a line it accepts writes back (thought_record) to a line that reads back to
// the same record.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "node/ai/thoughts.h"
#include "rcan/json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view line(reinterpret_cast<const char*>(data), size);
  auto t = node::parse_thought_line(line);
  if (!t.ok()) {
    if (t.error().message.empty()) std::abort();
    return 0;
  }
  if (t->id.empty() || t->id.size() > 128) std::abort();
  const std::string written = json::canonical(json::Value(node::thought_record(*t)));
  auto again = node::parse_thought_line(written);
  if (!again.ok()) std::abort();
  if (json::canonical(json::Value(node::thought_record(*again))) != written) std::abort();
  return 0;
}
