// Ed25519 (RFC 8032) through OpenSSL. Seeds, public keys 32 bytes; signatures 64 bytes.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "rcan/encoding.h"
#include "rcan/result.h"

namespace rcan::ed25519 {

inline constexpr size_t kSeedBytes = 32;
inline constexpr size_t kPublicKeyBytes = 32;
inline constexpr size_t kSignatureBytes = 64;

// Public key of a 32-byte seed.
Result<Bytes> public_key_from_seed(std::span<const uint8_t> seed);
// Fresh random seed.
Bytes random_seed();
Result<Bytes> sign(std::span<const uint8_t> seed, std::span<const uint8_t> message);
// False for malformed keys/signatures, non-canonical S, or a bad signature.
bool verify(std::span<const uint8_t> public_key, std::span<const uint8_t> message,
            std::span<const uint8_t> signature);

// PEM (SubjectPublicKeyInfo) of a raw public key, and back.
Result<std::string> public_key_to_pem(std::span<const uint8_t> public_key);
Result<Bytes> public_key_from_pem(std::string_view pem);

}  // namespace rcan::ed25519
