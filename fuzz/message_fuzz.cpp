// libFuzzer: the message codec (all three shapes). A decoded seed-shape message must encode and
// decode again to the same encoding. The seed-shape rendering of an rcan-py or rcan-ts message is
// informational (its id need not be a UUID — rcan-ts's is derived —, and its signature covers
// the SDK's own pre-image), so for those shapes only encoding is exercised.
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
  if (m->shape != rcan::WireShape::kSeed) return 0;  // rcan-py and rcan-ts shapes
  auto again = rcan::decode_message(enc);
  if (!again.ok()) std::abort();
  if (rcan::json::dump(rcan::encode_message(*again)) != rcan::json::dump(enc)) std::abort();
  return 0;
}
