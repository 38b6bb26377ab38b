// Hybrid Ed25519 + ML-DSA-65 signed bodies: rcan-py `sign_body`/`verify_body` and rcan-ts
// `signBody`/`verifyBody` (the two SDKs interoperate on this format).
//
// Signing: drop any top-level "sig"; add
//   pq_signing_pub = standard base64 (padded) of the raw 1952-byte ML-DSA-65 public key,
//   pq_kid         = first 8 hex of SHA-256(pk);
// pre-image = rcan-canonical-json-v1 of that object; ML-DSA-65 (pure, empty context) and
// Ed25519 both sign it; output = object + "sig": {ml_dsa, ed25519, ed25519_pub} (standard
// base64, padded).
//
// Verification removes "sig", canonicalises the rest, verifies ML-DSA-65 with the verifier's
// trusted key (never the embedded one) and Ed25519 with the embedded sig.ed25519_pub. The SDKs
// stop there; the strict mode (default) also requires pq_signing_pub to be the trusted key and
// pq_kid to be its kid, so that a body cannot name a key other than the one that signed it,
// and optionally pins the Ed25519 key.
#pragma once

#include <cstdint>
#include <optional>
#include <span>

#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::hybrid {

struct SignOptions {
  bool deterministic = false;  // ML-DSA rnd = 0^32
};

// Returns the signed body. `mldsa_sk` 4032 bytes, `mldsa_pk` 1952 bytes, `ed25519_seed` 32.
Result<json::Object> sign_body(const json::Object& body, std::span<const uint8_t> mldsa_sk,
                               std::span<const uint8_t> mldsa_pk,
                               std::span<const uint8_t> ed25519_seed, const SignOptions& opts = {});

struct VerifyOptions {
  // Require pq_signing_pub == trusted key and pq_kid == kid(trusted key).
  bool strict = true;
  // When set, sig.ed25519_pub must equal this key.
  std::optional<Bytes> expected_ed25519_pub;
};

// Ok when both signatures verify (and, in strict mode, the embedded key fields match).
// Errors: kSignatureInvalid with a message saying which check failed.
Status verify_body(const json::Object& signed_body, std::span<const uint8_t> trusted_mldsa_pk,
                   const VerifyOptions& opts = {});

// The canonical pre-image verify_body() checks (body without "sig").
std::string preimage(const json::Object& signed_body);

}  // namespace rcan::hybrid
