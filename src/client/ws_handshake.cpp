// The WebSocket upgrade of a client connection (RFC 6455 §4.1): the GET with its key, the
// 101 and its Sec-WebSocket-Accept, or the refusal as a ClientError. In rcan_client (it words a
// refusal with error_from_response); the connection itself is net.cpp's.
#include <string>

#include "client/net.h"
#include "client/wire.h"
#include "rcan/client.h"
#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace rcan::client::net {

Result<bool> ws_handshake(Conn& conn, const Endpoint& ep, const std::string& path,
                          const std::string& token, int timeout_ms, std::string& leftover) {
  uint8_t raw[16];
  random_bytes(raw, sizeof raw);
  std::string key = base64_encode(raw, sizeof raw);
  std::string host = ep.host.find(':') != std::string::npos ? "[" + ep.host + "]" : ep.host;
  std::string req = "GET " + ep.base_path + path + " HTTP/1.1\r\nHost: " + host + ":" +
                    std::to_string(ep.port) +
                    "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                    "Sec-WebSocket-Key: " +
                    key + "\r\nUser-Agent: rcan-client/0.1\r\n";
  if (!token.empty()) req += "Authorization: Bearer " + token + "\r\n";
  req += "\r\n";
  if (auto w = conn.write_all(req, timeout_ms); !w.ok()) return w.error();
  std::string buf;
  int64_t deadline = mono_ms() + timeout_ms;
  while (true) {
    size_t head_end = buf.find("\r\n\r\n");
    if (head_end != std::string::npos) {
      wire::ParsedResponse pr;
      size_t consumed = 0;
      std::string err;
      // Parse the head only (a refusal carries a body; a 101 has none).
      wire::Parse p = wire::parse_response(std::string_view(buf).substr(0, head_end + 4), false, pr,
                                           consumed, err);
      if (p == wire::Parse::kError)
        return transport_error("BAD_RESPONSE", "bad upgrade answer: " + err);
      if (pr.status != 101) {
        // Read the refusal body for its error code.
        std::string all = buf;
        bool eof = false;
        while (true) {
          wire::ParsedResponse full;
          wire::Parse q = wire::parse_response(all, eof, full, consumed, err);
          if (q == wire::Parse::kComplete) {
            std::string ra;
            for (auto& [k, v] : full.headers)
              if (k == "retry-after") ra = v;
            return error_from_response(full.status, full.body, ra);
          }
          if (q == wire::Parse::kError || mono_ms() >= deadline)
            return error_from_response(pr.status, "", "");
          auto n = conn.read_some(all, static_cast<int>(deadline - mono_ms()));
          if (!n.ok()) return error_from_response(pr.status, "", "");
          if (*n == 0) eof = true;
        }
      }
      std::string accept;
      for (auto& [k, v] : pr.headers)
        if (k == "sec-websocket-accept") accept = v;
      if (accept != wire::ws_accept(key))
        return transport_error("BAD_RESPONSE", "bad Sec-WebSocket-Accept");
      leftover = buf.substr(head_end + 4);
      return true;
    }
    if (buf.size() > wire::kMaxHeaderBytes)
      return transport_error("BAD_RESPONSE", "upgrade answer too large");
    int left = static_cast<int>(deadline - mono_ms());
    if (left <= 0) return transport_error("TIMEOUT", "WebSocket upgrade timed out");
    auto n = conn.read_some(buf, left);
    if (!n.ok()) return n.error();
    if (*n == 0)
      return transport_error("CONNECTION_FAILED", "connection closed during the WebSocket upgrade");
  }
}

}  // namespace rcan::client::net
