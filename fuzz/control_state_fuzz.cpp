// libFuzzer: the parsers of the control state (docs/SESSIONS.md) — the state files read at
// start-up (leases, ownership, consent, credential cache) and the outbound HTTP client's URL
// and status-line parsers. Loading anything must not crash, and what loads must persist to a
// document that loads to the same thing.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "node/control/consent.h"
#include "node/control/ownership.h"
#include "node/control/partition.h"
#include "node/control/sessions.h"
#include "rcan/json.h"
#include "runtime/http_client.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)rcan::parse_http_url(text);
  int code = rcan::parse_status_line(text);
  if (code != 0 && (code < 100 || code > 599)) std::abort();
  auto v = rcan::json::parse(text, {.max_depth = 32, .max_bytes = 1u << 20});
  if (!v.ok() || !v->is_object()) return 0;
  constexpr int64_t kNow = 1'750'000'000'000;
  rcan::node::SessionTable t;
  t.load_json(*v, kNow);
  std::string once = rcan::json::dump(t.persist_json());
  rcan::node::SessionTable t2;
  t2.load_json(t.persist_json(), kNow);
  if (rcan::json::dump(t2.persist_json()) != once) std::abort();
  rcan::node::Ownership o;
  o.load_json(*v);
  rcan::node::Ownership o2;
  o2.load_json(o.persist_json());
  if (rcan::json::dump(o2.persist_json()) != rcan::json::dump(o.persist_json())) std::abort();
  rcan::node::ConsentBook c;
  c.load_json(*v);
  (void)c.persist_json();
  rcan::node::PartitionMonitor p;
  p.load_json(*v, kNow);
  (void)p.persist_json();
  return 0;
}
