// UDP datagrams of the node (docs/TRANSPORT.md §UDP): HEARTBEAT (a control session's deadman,
// authenticated with the per-session key issued at claim), DISCOVER and ANNOUNCE. Pure
// encoding and parsing: no sockets (librcan). Shared by the node's UDP service
// (src/node/bindings/udp_service.cpp), the CLI (rcan udp-discover), tests and
// fuzz/udp_datagram_fuzz.cpp.
//
// Every datagram starts with the same 8-byte header:
//   0..3  magic "RCAN" (0x52 0x43 0x41 0x4E)
//   4     version 0x01
//   5     kind: 0x01 HEARTBEAT, 0x02 DISCOVER, 0x03 ANNOUNCE
//   6..7  flags, 0x0000 (anything else is malformed)
// HEARTBEAT, exactly 64 bytes:
//   8..23   key id (16 bytes, issued with the key)
//   24..31  sequence number, unsigned 64-bit big-endian, strictly increasing per key
//   32..63  HMAC-SHA256(session key, bytes 0..31)
// DISCOVER, 16 to 8192 bytes:
//   8..15   nonce chosen by the sender (echoed in the ANNOUNCE)
//   16..    zero padding (anything else is malformed). The node's answer is never longer than
//           the DISCOVER (no amplification): senders pad to kDiscoverPaddedSize, and a DISCOVER
//           too short for the full ANNOUNCE gets, when that fits, a short one that says how long
//           a DISCOVER must be ({"type":"ANNOUNCE","payload":{"discover_size":N}}).
// ANNOUNCE, 16 bytes + body:
//   8..15   the DISCOVER's nonce
//   16..    UTF-8 JSON: the ANNOUNCE message (same as POST /rcan/v1/discover answers)
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace rcan::udp {

inline constexpr size_t kHeaderSize = 8;
inline constexpr size_t kKeyIdSize = 16;
inline constexpr size_t kKeySize = 32;
inline constexpr size_t kMacSize = 32;
inline constexpr size_t kHeartbeatSize = 64;
inline constexpr size_t kDiscoverSize = 16;  // the shortest DISCOVER (no padding)
// What senders pad a DISCOVER to: room for a node's ANNOUNCE, within one IPv6 minimum-MTU packet.
inline constexpr size_t kDiscoverPaddedSize = 1200;
inline constexpr size_t kMaxAnnounceSize = 8192;
inline constexpr uint8_t kVersion = 1;

enum class Kind : uint8_t { kHeartbeat = 1, kDiscover = 2, kAnnounce = 3 };

using KeyId = std::array<uint8_t, kKeyIdSize>;
using Key = std::array<uint8_t, kKeySize>;
using Nonce = std::array<uint8_t, 8>;

enum class ParseError {
  kNone,
  kTooShort,  // shorter than the header
  kBadMagic,
  kBadVersion,
  kBadKind,
  kBadFlags,
  kBadLength,   // wrong size for its kind
  kBadBody,     // ANNOUNCE body not a JSON object
  kBadPadding,  // DISCOVER padding not all zero
};
std::string_view parse_error_name(ParseError e);

struct Datagram {
  Kind kind = Kind::kHeartbeat;
  // HEARTBEAT
  KeyId key_id{};
  uint64_t seq = 0;
  std::array<uint8_t, kMacSize> mac{};
  // DISCOVER / ANNOUNCE
  Nonce nonce{};
  std::string body;  // ANNOUNCE JSON text
  size_t size = 0;   // the datagram's length (a DISCOVER's answer may be no longer)
};

struct Parsed {
  ParseError error = ParseError::kNone;
  Datagram d;
  bool ok() const { return error == ParseError::kNone; }
};

// Structure only: the HEARTBEAT's MAC is checked by verify_heartbeat with the key.
Parsed parse(std::span<const uint8_t> bytes);

// True when `bytes` is a 64-byte HEARTBEAT whose MAC is HMAC-SHA256(key, bytes[0..32))
// (constant-time comparison).
bool verify_heartbeat(std::span<const uint8_t> bytes, const Key& key);

std::array<uint8_t, kHeartbeatSize> encode_heartbeat(const KeyId& key_id, uint64_t seq,
                                                     const Key& key);
// The shortest DISCOVER (16 bytes): a node answers it with nothing, having nothing that short.
std::array<uint8_t, kDiscoverSize> encode_discover(const Nonce& nonce);
// A DISCOVER zero-padded to `size` bytes (clamped to 16..8192).
std::string encode_discover_padded(const Nonce& nonce, size_t size = kDiscoverPaddedSize);
std::string encode_announce(const Nonce& nonce, std::string_view json_body);

}  // namespace rcan::udp
