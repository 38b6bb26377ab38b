// libFuzzer: the client's byte-level parsers — HTTP/1.1 responses (Content-Length, chunked,
// close-delimited, interim 1xx) and WebSocket frames. Invariants: nothing crashes; a complete
// parse never consumes more than it was given; a response parsed whole parses the same when
// fed in two pieces (incremental parsing agrees with one-shot parsing); frames re-encode.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "client/wire.h"

using rcan::client::wire::Parse;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  for (bool eof : {false, true}) {
    rcan::client::wire::ParsedResponse r;
    size_t used = 0;
    std::string err;
    Parse p = rcan::client::wire::parse_response(bytes, eof, r, used, err, 1u << 16);
    if (p == Parse::kComplete) {
      if (used > size || r.status < 100 || r.status > 599) std::abort();
      if (!eof) {
        // A prefix that ends before `used` never completes (incremental = one-shot).
        for (size_t cut : {used / 2, used > 0 ? used - 1 : 0}) {
          if (cut >= used) continue;
          rcan::client::wire::ParsedResponse q;
          size_t u2 = 0;
          std::string e2;
          if (rcan::client::wire::parse_response(bytes.substr(0, cut), false, q, u2, e2,
                                                 1u << 16) == Parse::kComplete)
            std::abort();
        }
      }
    } else if (p == Parse::kError && err.empty()) {
      std::abort();
    }
  }
  rcan::client::wire::WsFrame f;
  size_t used = 0;
  std::string err;
  if (rcan::client::wire::ws_parse(bytes, f, used, err, 1u << 16) == Parse::kComplete) {
    if (used > size || f.payload.size() > used) std::abort();
    const uint8_t mask[4] = {9, 8, 7, 6};
    std::string again = rcan::client::wire::ws_frame(f.opcode, f.payload, mask);
    rcan::client::wire::WsFrame g;
    size_t u2 = 0;
    if (rcan::client::wire::ws_parse(again, g, u2, err, 1u << 16) != Parse::kComplete ||
        g.payload != f.payload || g.opcode != f.opcode || u2 != again.size())
      std::abort();
  }
  return 0;
}
