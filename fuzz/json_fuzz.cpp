// libFuzzer: the JSON parser and all three writers. Any input must parse or fail cleanly,
// and whatever parses must re-parse from each writer's output to an equal document.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "rcan/json.h"

namespace {

// The string-literal writer fed one character at a time (a run can then be one character
// long): what it writes for ASCII text must not depend on how it groups plain characters into
// runs. Bytes >= 0x80 are not split (a lone byte of a sequence is written differently).
std::string one_at_a_time(std::string_view s) {
  std::string out = "\"";
  for (char c : s) {
    std::string one;
    rcan::json::append_string(one, std::string_view(&c, 1));
    out.append(one, 1, one.size() - 2);  // without its quotes
  }
  out.push_back('"');
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  bool ascii = true;
  for (unsigned char c : text) ascii = ascii && c < 0x80;
  if (ascii) {  // any bytes, not only parsed strings: the raw input as a string value
    std::string lit;
    rcan::json::append_string(lit, text);
    if (lit != one_at_a_time(text)) std::abort();
  }
  auto v = rcan::json::parse(text);
  if (!v.ok()) return 0;
  std::string canon = rcan::json::canonical(*v);
  std::string dumped = rcan::json::dump(*v);
  std::string py = rcan::json::python_dumps(*v);
  auto d = rcan::json::parse(dumped, {.max_depth = 1000, .max_bytes = 1u << 30});
  if (!d.ok() || !(*d == *v)) std::abort();  // dump() must round-trip exactly
  auto p = rcan::json::parse(py, {.max_depth = 1000, .max_bytes = 1u << 30});
  if (!p.ok()) std::abort();
  auto c = rcan::json::parse(canon, {.max_depth = 1000, .max_bytes = 1u << 30});
  if (!c.ok() || rcan::json::canonical(*c) != canon) std::abort();  // canonical is a fixed point
  // The Object overload and the string-literal writer agree with the Value writers.
  if (v->is_object() && rcan::json::canonical(v->as_object()) != canon) std::abort();
  if (v->is_string()) {
    std::string lit;
    rcan::json::append_string(lit, v->as_string());
    if (lit != dumped || lit != canon) std::abort();
  }
  return 0;
}
