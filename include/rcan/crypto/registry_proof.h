// Proof of possession for the registry (docs/REGISTRY.md): a robot signs
// registry::proof_message() with both identity keys; the registry verifies both before it
// records the keys. Signatures and keys travel as base64url without padding.
#pragma once

#include <string>

#include "rcan/crypto/keys.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::registry {

struct Proof {
  std::string challenge_id;
  std::string ed25519_sig;  // 64 bytes
  std::string mldsa65_sig;  // 3309 bytes (pure ML-DSA-65, empty context)

  json::Value to_json() const;  // {"challenge_id", "ed25519_sig", "mldsa65_sig"}
  // Refuses a non-object, a missing or non-string member (error field names it).
  static Result<Proof> from_json(const json::Value& v);
};

// Signs `message` with both keys of `keys`.
Result<Proof> sign_proof(const keys::RobotKeys& keys, const std::string& challenge_id,
                         const std::string& message);

// Both signatures verify over `message` with the given public keys (base64url): Ok, or an
// error saying which key or signature is malformed or does not verify.
Status verify_proof(const std::string& ed25519_pub_b64url, const std::string& mldsa65_pub_b64url,
                    const std::string& message, const Proof& proof);

}  // namespace rcan::registry
