// libFuzzer target: the revocation list's file (src/node/admission/revocation.h) — the JSON
// document rcand reads from `revocations.json` at start-up, and each entry as a POST would give
// it. Must never crash; every rejection carries a message; what parses serialises and parses
// back to the same entries; a parsed list answers lookups.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "node/admission/revocation.h"
#include "rcan/json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  auto v = json::parse(text, {.max_depth = 32, .max_bytes = 1u << 20});
  if (!v.ok()) return 0;
  auto entries = node::RevocationList::parse(*v, 64);
  if (!entries.ok()) {
    if (entries.error().message.empty()) std::abort();
    auto one = node::Revocation::from_json(*v);  // a single entry, as a request body might be
    if (!one.ok() && one.error().message.empty()) std::abort();
    return 0;
  }
  json::Array arr;
  for (const auto& e : *entries) arr.push_back(e.to_json());
  json::Value doc(json::Object{{"version", 1}, {"revocations", std::move(arr)}});
  auto again = node::RevocationList::parse(doc, 64);
  if (!again.ok() || again->size() != entries->size()) std::abort();
  for (size_t i = 0; i < entries->size(); ++i) {
    const auto& a = (*entries)[i];
    const auto& b = (*again)[i];
    if (a.kind != b.kind || a.value != b.value || a.iss != b.iss || a.exp != b.exp ||
        a.at_ms != b.at_ms || a.by != b.by || a.reason != b.reason || a.feed != b.feed)
      std::abort();
  }
  node::RevocationList list;
  for (auto& e : *entries) (void)list.add(e, 0);
  node::Principal p;
  p.authenticated = true;
  p.issuer = entries->empty() ? "i" : (*entries)[0].iss;
  p.sub = entries->empty() ? "s" : (*entries)[0].value;
  p.jti = p.sub;
  p.kid = p.sub;
  (void)list.revoked(p);
  return 0;
}
