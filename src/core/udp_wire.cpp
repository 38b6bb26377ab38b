// UDP datagram encoding and parsing (udp_wire.h).
#include "rcan/udp_wire.h"

#include <algorithm>
#include <cstring>

#include "rcan/hash.h"
#include "rcan/json.h"

namespace rcan::udp {

namespace {

constexpr uint8_t kMagic[4] = {'R', 'C', 'A', 'N'};

void put_header(uint8_t* out, Kind k) {
  std::memcpy(out, kMagic, 4);
  out[4] = kVersion;
  out[5] = static_cast<uint8_t>(k);
  out[6] = 0;
  out[7] = 0;
}

}  // namespace

std::string_view parse_error_name(ParseError e) {
  switch (e) {
    case ParseError::kNone:
      return "none";
    case ParseError::kTooShort:
      return "too_short";
    case ParseError::kBadMagic:
      return "bad_magic";
    case ParseError::kBadVersion:
      return "bad_version";
    case ParseError::kBadKind:
      return "bad_kind";
    case ParseError::kBadFlags:
      return "bad_flags";
    case ParseError::kBadLength:
      return "bad_length";
    case ParseError::kBadBody:
      return "bad_body";
    case ParseError::kBadPadding:
      return "bad_padding";
  }
  return "unknown";
}

Parsed parse(std::span<const uint8_t> b) {
  Parsed p;
  p.d.size = b.size();
  if (b.size() < kHeaderSize) {
    p.error = ParseError::kTooShort;
    return p;
  }
  if (std::memcmp(b.data(), kMagic, 4) != 0) {
    p.error = ParseError::kBadMagic;
    return p;
  }
  if (b[4] != kVersion) {
    p.error = ParseError::kBadVersion;
    return p;
  }
  if (b[6] != 0 || b[7] != 0) {
    p.error = ParseError::kBadFlags;
    return p;
  }
  switch (b[5]) {
    case static_cast<uint8_t>(Kind::kHeartbeat): {
      if (b.size() != kHeartbeatSize) {
        p.error = ParseError::kBadLength;
        return p;
      }
      p.d.kind = Kind::kHeartbeat;
      std::memcpy(p.d.key_id.data(), b.data() + 8, kKeyIdSize);
      uint64_t seq = 0;
      for (size_t i = 24; i < 32; ++i) seq = (seq << 8) | b[i];
      p.d.seq = seq;
      std::memcpy(p.d.mac.data(), b.data() + 32, kMacSize);
      return p;
    }
    case static_cast<uint8_t>(Kind::kDiscover): {
      if (b.size() < kDiscoverSize || b.size() > kMaxAnnounceSize) {
        p.error = ParseError::kBadLength;
        return p;
      }
      for (size_t i = kDiscoverSize; i < b.size(); ++i)
        if (b[i] != 0) {
          p.error = ParseError::kBadPadding;
          return p;
        }
      p.d.kind = Kind::kDiscover;
      std::memcpy(p.d.nonce.data(), b.data() + 8, 8);
      return p;
    }
    case static_cast<uint8_t>(Kind::kAnnounce): {
      if (b.size() <= 16 || b.size() > kMaxAnnounceSize) {
        p.error = ParseError::kBadLength;
        return p;
      }
      p.d.kind = Kind::kAnnounce;
      std::memcpy(p.d.nonce.data(), b.data() + 8, 8);
      p.d.body.assign(reinterpret_cast<const char*>(b.data() + 16), b.size() - 16);
      auto v = json::parse(p.d.body, {.max_depth = 16, .max_bytes = kMaxAnnounceSize});
      if (!v.ok() || !v->is_object()) p.error = ParseError::kBadBody;
      return p;
    }
    default:
      p.error = ParseError::kBadKind;
      return p;
  }
}

bool verify_heartbeat(std::span<const uint8_t> b, const Key& key) {
  if (b.size() != kHeartbeatSize) return false;
  Digest256 mac = hmac_sha256(key.data(), key.size(), b.data(), 32);
  return constant_time_equal(
      std::string_view(reinterpret_cast<const char*>(mac.data()), mac.size()),
      std::string_view(reinterpret_cast<const char*>(b.data() + 32), kMacSize));
}

std::array<uint8_t, kHeartbeatSize> encode_heartbeat(const KeyId& key_id, uint64_t seq,
                                                     const Key& key) {
  std::array<uint8_t, kHeartbeatSize> out{};
  put_header(out.data(), Kind::kHeartbeat);
  std::memcpy(out.data() + 8, key_id.data(), kKeyIdSize);
  for (int i = 0; i < 8; ++i)
    out[static_cast<size_t>(24 + i)] = static_cast<uint8_t>(seq >> (56 - 8 * i));
  Digest256 mac = hmac_sha256(key.data(), key.size(), out.data(), 32);
  std::memcpy(out.data() + 32, mac.data(), kMacSize);
  return out;
}

std::array<uint8_t, kDiscoverSize> encode_discover(const Nonce& nonce) {
  std::array<uint8_t, kDiscoverSize> out{};
  put_header(out.data(), Kind::kDiscover);
  std::memcpy(out.data() + 8, nonce.data(), 8);
  return out;
}

std::string encode_discover_padded(const Nonce& nonce, size_t size) {
  auto head = encode_discover(nonce);
  std::string out(std::clamp(size, kDiscoverSize, kMaxAnnounceSize), '\0');
  std::memcpy(out.data(), head.data(), head.size());
  return out;
}

std::string encode_announce(const Nonce& nonce, std::string_view json_body) {
  std::string out(16, '\0');
  put_header(reinterpret_cast<uint8_t*>(out.data()), Kind::kAnnounce);
  std::memcpy(out.data() + 8, nonce.data(), 8);
  out.append(json_body);
  return out;
}

}  // namespace rcan::udp
