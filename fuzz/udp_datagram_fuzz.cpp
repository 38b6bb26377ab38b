// libFuzzer: the node's UDP datagram parser (rcan/udp_wire.h). Invariants: a HEARTBEAT or
// DISCOVER that parses re-encodes to the same bytes (the format has no slack), and a
// heartbeat only verifies with the key that made it.
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "rcan/udp_wire.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::span<const uint8_t> bytes(data, size);
  rcan::udp::Parsed p = rcan::udp::parse(bytes);
  if (!p.ok()) {
    if (rcan::udp::parse_error_name(p.error).empty()) std::abort();
    return 0;
  }
  rcan::udp::Key key{};
  key.fill(0x5a);
  switch (p.d.kind) {
    case rcan::udp::Kind::kHeartbeat: {
      if (size != rcan::udp::kHeartbeatSize) std::abort();
      auto again = rcan::udp::encode_heartbeat(p.d.key_id, p.d.seq, key);
      if (std::memcmp(again.data(), data, 32) != 0) std::abort();
      if (!rcan::udp::verify_heartbeat(again, key)) std::abort();
      bool same_mac = std::memcmp(again.data() + 32, data + 32, 32) == 0;
      if (rcan::udp::verify_heartbeat(bytes, key) != same_mac) std::abort();
      break;
    }
    case rcan::udp::Kind::kDiscover: {
      std::string again = rcan::udp::encode_discover_padded(p.d.nonce, size);
      if (size != again.size() || p.d.size != size || std::memcmp(again.data(), data, size) != 0)
        std::abort();
      break;
    }
    case rcan::udp::Kind::kAnnounce: {
      std::string again = rcan::udp::encode_announce(p.d.nonce, p.d.body);
      if (again.size() != size || std::memcmp(again.data(), data, size) != 0) std::abort();
      break;
    }
  }
  return 0;
}
