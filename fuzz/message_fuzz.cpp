// libFuzzer: the message codec (both shapes). A decoded seed-shape message must encode and
// decode again to the same encoding. An rcan-py message's seed-shape rendering is informational
// (its msg_id need not be a UUID, and its signature covers rcan-py's own pre-image), so for that
// shape only encoding is exercised.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "rcan/errors.h"
#include "rcan/message.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  auto m = rcan::parse_message(text);
  if (!m.ok()) {
    rcan::json::Value body =
        rcan::error_body(m.error(), "", 0, "00000000-0000-4000-8000-000000000000");
    if (rcan::json::dump(body).empty()) std::abort();
    return 0;
  }
  (void)m->action();
  rcan::json::Value enc = rcan::encode_message(*m);
  if (m->shape == rcan::WireShape::kRcanPy) return 0;
  auto again = rcan::decode_message(enc);
  if (!again.ok()) std::abort();
  if (rcan::json::dump(rcan::encode_message(*again)) != rcan::json::dump(enc)) std::abort();
  return 0;
}
