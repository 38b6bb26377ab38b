// SHA-256 and HMAC-SHA256 (OpenSSL), the digests the protocol is built on.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

namespace rcan {

using Digest256 = std::array<uint8_t, 32>;

Digest256 sha256(const void* data, size_t len);
inline Digest256 sha256(std::string_view s) { return sha256(s.data(), s.size()); }
std::string sha256_hex(std::string_view s);

Digest256 hmac_sha256(const void* key, size_t key_len, const void* data, size_t len);
inline Digest256 hmac_sha256(std::string_view key, std::string_view data) {
  return hmac_sha256(key.data(), key.size(), data.data(), data.size());
}
std::string hmac_sha256_hex(std::string_view key, std::string_view data);

// Constant-time comparison of equal-length buffers (false when lengths differ).
bool constant_time_equal(std::string_view a, std::string_view b);

// Overwrites memory in a way the compiler may not elide.
void secure_wipe(void* p, size_t len);

// Cryptographically secure random bytes (OpenSSL RAND_bytes); false on failure.
bool random_bytes(void* out, size_t len);

}  // namespace rcan
