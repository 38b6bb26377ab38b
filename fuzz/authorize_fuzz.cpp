// libFuzzer target: AUTHORIZE bodies and pending-file entries (node/hitl.h). parse_authorize()
// must never crash and, when it accepts, give a bounded target and an id; a pending item that
// parses must survive its own round trip through to_json().
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "node/ai/hitl.h"
#include "rcan/json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  auto v = json::parse(std::string_view(reinterpret_cast<const char*>(data), size),
                       {.max_depth = 16, .max_bytes = 65536});
  if (!v.ok()) return 0;
  auto a = node::parse_authorize(*v);
  if (a.ok() && (a->target.empty() || a->target.size() > 128 || a->authorize_id.empty() ||
                 a->reason.size() > 512))
    std::abort();
  auto p = node::PendingItem::from_json(*v);
  if (p.ok()) {
    auto again = node::PendingItem::from_json(p->to_json());
    if (!again.ok() || again->message_id != p->message_id || again->role != p->role ||
        again->expires_at_ms != p->expires_at_ms || again->allow_on_timeout != p->allow_on_timeout)
      std::abort();
  }
  return 0;
}
