// libFuzzer target: what rcand reads from its registry's token authority
// (src/node/admission/registry_feed.h) — the JWKS of /.well-known/jwks.json and a page of
// /api/v1/revocations, both straight off the network. Must never crash; every rejection carries
// a message; an accepted JWKS holds only keys with a kid; an accepted page's seqs rise above
// `since` and next_since does not go back.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "node/admission/registry_feed.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  auto keys = node::parse_registry_jwks(text);
  if (!keys.ok()) {
    if (keys.error().message.empty()) std::abort();
  } else {
    if (keys->keys.empty() || keys->keys.size() > node::kMaxRegistryKeys) std::abort();
    for (const auto& k : keys->keys)
      if (k.kid().empty() || k.alg() == jwt::Alg::kHS256) std::abort();
  }
  for (int64_t since : {int64_t{0}, int64_t{7}}) {
    auto page = node::parse_revocation_page(text, since);
    if (!page.ok()) {
      if (page.error().message.empty()) std::abort();
      continue;
    }
    int64_t last = since;
    for (const auto& e : page->entries) {
      if (e.seq <= last || (e.jti.empty() && e.sub.empty())) std::abort();
      last = e.seq;
    }
    if (page->next_since < last || page->entries.size() > node::kRevocationPageSize) std::abort();
  }
  (void)node::parse_iso8601_ms(text.substr(0, 64));
  return 0;
}
