// Byte encodings used across the protocol: hex, base64 and base64url.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace rcan {

using Bytes = std::vector<uint8_t>;

std::string to_hex(const uint8_t* data, size_t len);
inline std::string to_hex(const Bytes& b) { return to_hex(b.data(), b.size()); }
inline std::string to_hex(std::string_view s) {
  return to_hex(reinterpret_cast<const uint8_t*>(s.data()), s.size());
}
// Accepts upper or lower case; nullopt on odd length or a non-hex character.
std::optional<Bytes> from_hex(std::string_view hex);

// Standard base64 with padding (RFC 4648 §4).
std::string base64_encode(const uint8_t* data, size_t len);
inline std::string base64_encode(const Bytes& b) { return base64_encode(b.data(), b.size()); }
// Strict: padding required, no whitespace, canonical trailing bits.
std::optional<Bytes> base64_decode(std::string_view s);

// base64url (RFC 4648 §5); `pad` selects '=' padding.
std::string base64url_encode(const uint8_t* data, size_t len, bool pad = false);
inline std::string base64url_encode(const Bytes& b, bool pad = false) {
  return base64url_encode(b.data(), b.size(), pad);
}
// Accepts input with or without padding (both forms occur on the wire);
// rejects characters outside the url alphabet and non-canonical trailing bits.
std::optional<Bytes> base64url_decode(std::string_view s);

inline Bytes to_bytes(std::string_view s) { return Bytes(s.begin(), s.end()); }
inline std::string to_string(const Bytes& b) { return std::string(b.begin(), b.end()); }

}  // namespace rcan
