// libFuzzer: RURI, RRN and aud matching. Accepted RURIs must re-parse to themselves.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "rcan/ruri.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  auto r = rcan::parse_ruri(text);
  if (r.ok()) {
    std::string canon = r->str();
    auto again = rcan::parse_ruri(canon);
    if (!again.ok() || again->str() != canon) std::abort();
    (void)rcan::aud_matches(text, *r);
    if (!rcan::aud_matches(r->base(), *r) && r->capability.empty()) std::abort();
  } else if (r.error().code != rcan::ErrorCode::kInvalidRuri || r.error().message.empty()) {
    std::abort();
  }
  (void)rcan::parse_rrn(text);
  return 0;
}
