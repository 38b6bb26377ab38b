// libFuzzer: what the client (and the node's mDNS browser) reads from a node or the network
// before trusting it — mDNS TXT items, status answers (GET /rcan/v1/status), error bodies of every
// shape, and URLs given by the user or built from mDNS answers. Invariants: nothing crashes; TXT
// keys are non-empty and lower-case; a failed status parse says SCHEMA_VALIDATION_FAILED; an
// accepted URL re-parses to itself.
#include <cctype>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/client.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  // TXT: NUL separates items (each item is a length-prefixed string on the wire).
  std::vector<std::string> items;
  size_t start = 0;
  while (start <= bytes.size()) {
    size_t z = bytes.find('\0', start);
    items.emplace_back(
        bytes.substr(start, z == std::string_view::npos ? std::string_view::npos : z - start));
    if (z == std::string_view::npos) break;
    start = z + 1;
  }
  // The same parser reads the TXT records the node's mDNS browser hears (dashboard.mdns).
  const auto txt = rcan::parse_txt(items);
  for (const auto& [k, v] : txt) {
    if (k.empty()) std::abort();
    for (char c : k)
      if (std::isupper(static_cast<unsigned char>(c))) std::abort();
  }
  const bool tls = rcan::txt_says_tls(txt);
  const auto tls_of = txt.find("tls");
  const auto scheme = txt.find("scheme");
  if (tls != ((tls_of != txt.end() && tls_of->second == "1") ||
              (scheme != txt.end() && scheme->second == "https")))
    std::abort();
  auto st = rcan::client::parse_status(bytes);
  if (!st.ok() && st.error().code != "SCHEMA_VALIDATION_FAILED") std::abort();
  if (st.ok() && st->ruri.empty() && !st->raw.get("ruri")) std::abort();
  auto e = rcan::client::error_from_response(400, bytes, bytes.substr(0, 8));
  if (e.code.empty() || e.http_status != 400) std::abort();
  auto ep = rcan::client::parse_endpoint(bytes);
  if (ep.ok()) {
    auto again = rcan::client::parse_endpoint(ep->url());
    if (!again.ok() || again->url() != ep->url()) std::abort();
  }
  return 0;
}
