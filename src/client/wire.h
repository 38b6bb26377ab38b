// Byte-level pieces of the client, free of I/O so they can be fuzzed: the HTTP/1.1
// response parser and the WebSocket frame codec (RFC 6455, client side).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace rcan::client::wire {

inline constexpr size_t kMaxHeaderBytes = 64 * 1024;
inline constexpr size_t kMaxBodyBytes = 256u << 20;  // audit exports can be large

struct ParsedResponse {
  int status = 0;
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-cased
  std::string body;
};

enum class Parse { kIncomplete, kComplete, kError };

// Parses one HTTP/1.1 response from the start of `buf`. `eof` says the peer has closed
// (a response without Content-Length or chunking ends there). On kComplete `consumed` is
// the number of bytes used; on kError `error` says why. 1xx interim responses are skipped.
Parse parse_response(std::string_view buf, bool eof, ParsedResponse& out, size_t& consumed,
                     std::string& error, size_t max_body = kMaxBodyBytes);

// A masked client frame (FIN set) carrying `payload`.
std::string ws_frame(uint8_t opcode, std::string_view payload, const uint8_t mask[4]);

struct WsFrame {
  bool fin = true;
  uint8_t opcode = 0;
  std::string payload;
};
// Decodes one server frame (unmasked; a masked one is accepted too) from the start of
// `buf`. kComplete sets `consumed`; kError for reserved bits, bad lengths, oversize
// (> max_payload) or fragmented control frames.
Parse ws_parse(std::string_view buf, WsFrame& out, size_t& consumed, std::string& error,
               size_t max_payload = 16u << 20);

// Sec-WebSocket-Accept for a key (base64(SHA-1(key + GUID))).
std::string ws_accept(std::string_view key);

}  // namespace rcan::client::wire
