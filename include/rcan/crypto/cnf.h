// Key-bound tokens (RFC 7800 proof of possession): a token's `cnf` claim names the one key
// whose holder may use it, and every message sent with such a token carries a message signature
// (rcan/crypto/message_sig.h) by that key. A reader who copies the token off a shared channel
// (an MQTT topic) cannot write a message of their own with it.
//
//   {"cnf": {"jwk": {"kty": "OKP", "crv": "Ed25519", "x": "<base64url of 32 bytes>"}}}
//   {"cnf": {"jwk": {"kty": "OKP", "crv": "ML-DSA-65", "x": "<base64url of 1952 bytes>", …}}}
//
// The Ed25519 form is RFC 8037's; the ML-DSA-65 form is the JWK rcan-py writes
// (keys::mldsa65_jwk). Any other `cnf` (jkt, jwe, kid, another key type) is refused, never
// ignored: a token that asks to be bound and cannot be is not a bearer token.
#pragma once

#include <span>
#include <string>

#include "rcan/crypto/message_sig.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::cnf {

struct BoundKey {
  msgsig::Alg alg = msgsig::Alg::kEd25519;
  Bytes public_key;  // raw: 32 bytes (Ed25519) or 1952 bytes (ML-DSA-65)
  std::string kid;   // the kid a message signature by this key carries (message_sig.h)
};

// Parses the value of a `cnf` claim. Errors: kAuthInvalid, field "cnf" or "cnf.jwk…".
Result<BoundKey> parse(const json::Value& cnf);
// The `cnf` claim value that binds a token to `public_key`.
Result<json::Value> make(msgsig::Alg alg, std::span<const uint8_t> public_key);
// Verifies msg["sig"] against exactly this key. Errors as msgsig::verify: kAuthRequired (no
// sig), kSignatureInvalid (another key's kid, or a signature that does not verify).
Result<msgsig::SigBlock> verify(const json::Object& msg, const BoundKey& key);

}  // namespace rcan::cnf
