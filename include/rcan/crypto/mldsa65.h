// ML-DSA-65 (FIPS 204, pure ML-DSA, security category 3), implemented on OpenSSL's SHAKE.
//
// Encodings are FIPS 204's: public key 1952 bytes, secret key 4032 bytes, signature 3309
// bytes. Keys derive deterministically from a 32-byte seed ξ (ML-DSA.KeyGen_internal).
// Signing is hedged by default (fresh 32-byte rnd); `deterministic` uses rnd = 0^32.
// The context string is at most 255 bytes; the signed message is M' = 0 ‖ |ctx| ‖ ctx ‖ M.
//
// Secret material is wiped before it goes out of scope. Arithmetic on secrets has no
// secret-dependent branches or memory indexing; the rejection loop in Sign reveals only
// the number of iterations, which FIPS 204 allows (see mldsa65.cpp).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "rcan/encoding.h"
#include "rcan/result.h"

namespace rcan::mldsa65 {

inline constexpr size_t kSeedBytes = 32;
inline constexpr size_t kPublicKeyBytes = 1952;
inline constexpr size_t kSecretKeyBytes = 4032;
inline constexpr size_t kSignatureBytes = 3309;
inline constexpr size_t kMaxContextBytes = 255;

struct KeyPair {
  Bytes public_key;  // kPublicKeyBytes
  Bytes secret_key;  // kSecretKeyBytes; wiped by the destructor
  KeyPair() = default;
  KeyPair(const KeyPair&) = default;
  KeyPair(KeyPair&&) noexcept = default;
  KeyPair& operator=(const KeyPair&) = default;
  KeyPair& operator=(KeyPair&&) noexcept = default;
  ~KeyPair();
};

// ML-DSA.KeyGen_internal(ξ). `seed` must be kSeedBytes long.
Result<KeyPair> keygen_from_seed(std::span<const uint8_t> seed);
// Fresh random seed from the OS CSPRNG.
Result<KeyPair> keygen_random();

struct SignOptions {
  bool deterministic = false;          // rnd = 0^32 instead of fresh randomness
  std::span<const uint8_t> context{};  // ≤ 255 bytes
};
// ML-DSA.Sign. Errors: wrong secret-key length, context too long, RNG failure.
Result<Bytes> sign(std::span<const uint8_t> secret_key, std::span<const uint8_t> message,
                   const SignOptions& opts = {});
// ML-DSA.Sign_internal with an explicit 32-byte rnd over the already-formatted M'.
Result<Bytes> sign_internal(std::span<const uint8_t> secret_key, std::span<const uint8_t> m_prime,
                            std::span<const uint8_t> rnd);

// ML-DSA.Verify: false for any malformed key/signature/context (never throws, never crashes).
bool verify(std::span<const uint8_t> public_key, std::span<const uint8_t> message,
            std::span<const uint8_t> signature, std::span<const uint8_t> context = {});

// Key id used by rcan-py/rcan-ts: first 8 lower-case hex characters of SHA-256(pk).
std::string kid(std::span<const uint8_t> public_key);

}  // namespace rcan::mldsa65
