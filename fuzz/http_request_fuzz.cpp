// Fuzzes the HTTP request path of the transport without sockets: Beast's request parser with
// the server's header/body limits, the error classification (413/431/400), the message →
// HttpRequest conversion (percent-decoding of path and query, lower-cased header names), the
// WebSocket upgrade checks and the error body. The same header-only code runs in
// src/transport/http_server.cpp. Invariants checked: nothing crashes, every error has a
// 4xx status and a JSON error body, decoded paths start with '/' (or are "*"), and a request
// that parses at one set of limits never claims more bytes than it was given.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "rcan/json.h"
#include "transport/http_parse.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using rcan::transport::detail::ParseOutcome;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  // Small limits so that the fuzzer reaches the limit paths; then the defaults.
  for (auto [hdr, body] : {std::pair<size_t, size_t>{256, 64}, {8 * 1024, 64 * 1024}}) {
    ParseOutcome out = rcan::transport::detail::parse_request_bytes(bytes, hdr, body);
    if (out.consumed > bytes.size()) std::abort();
    switch (out.kind) {
      case ParseOutcome::Kind::kError: {
        if (out.error.status < 400 || out.error.status > 499) std::abort();
        auto v = rcan::json::parse(out.error_body);
        if (!v.ok() || !v->is_object()) std::abort();
        break;
      }
      case ParseOutcome::Kind::kRequest: {
        const auto& p = out.request.path;
        if (p.empty() || (p[0] != '/' && p != "*")) std::abort();
        if (p.find('\0') != std::string::npos) std::abort();
        if (out.request.body.size() > body) std::abort();
        for (const auto& h : out.request.headers)
          for (char c : h.first)
            if (c >= 'A' && c <= 'Z') std::abort();
        break;
      }
      case ParseOutcome::Kind::kNeedMore:
      case ParseOutcome::Kind::kSilent:
        break;
    }
  }
  return 0;
}
