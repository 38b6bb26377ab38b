// libFuzzer: the token authority's request parsing (src/registry/api/oauth_form.h). Any bytes
// must parse or fail cleanly as a form body, an HTTP Basic header, a scope list and a user
// code; whatever is accepted must hold the invariants the token endpoint relies on.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "registry/api/oauth_form.h"

namespace {

void require(bool cond) {
  if (!cond) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan::registry::api;
  std::string_view in(reinterpret_cast<const char*>(data), size);
  auto f = parse_form(in);
  if (f.ok()) {
    require(in.size() <= kMaxFormBytes);
    require(f->fields.size() <= kMaxFormFields);
    for (const auto& [k, v] : f->fields) {
      require(!k.empty());
      require(k.find('\0') == std::string::npos && v.find('\0') == std::string::npos);
    }
    (void)parse_scope(f->get("scope"));
  }
  if (auto b = parse_basic(in)) require(!b->id.empty());
  if (auto s = parse_scope(in)) {
    require(s->size() <= 32);
    for (const auto& t : *s) {
      require(!t.empty() && t.size() <= 64);
      for (char c : t) require(c > 0x20 && c < 0x7f && c != '"' && c != '\\');
    }
  }
  std::string code = normalize_user_code(in);
  if (!code.empty()) {
    require(code.size() == 9 && code[4] == '-');
    for (size_t i = 0; i < 9; ++i)
      if (i != 4) require(std::strchr(kUserCodeAlphabet, code[i]) != nullptr);
    require(normalize_user_code(code) == code);
  }
  return 0;
}
