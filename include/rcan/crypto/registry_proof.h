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

  // {"challenge_id", "ed25519_sig", "mldsa65_sig"}; the registry reads it back with its
  // request parser (src/registry/api/body.h).
  json::Value to_json() const;
};

// Signs `message` with both keys of `keys`.
Result<Proof> sign_proof(const keys::RobotKeys& keys, const std::string& challenge_id,
                         const std::string& message);

// The keys (base64url; an empty string: that key is not registered) and the proof fit
// together: at least one key, each key well formed, a signature for each key. Errors are
// SCHEMA_VALIDATION_FAILED with reason no_keys, bad_key or missing_signature; `field` names
// the key or signature.
Status check_proof_shape(const std::string& ed25519_pub_b64url,
                         const std::string& mldsa65_pub_b64url, const Proof& proof);
// check_proof_shape, then the signature of every given key verifies over `message`: Ok, or
// SIGNATURE_INVALID with reason bad_signature and `field` the signature that failed.
Status verify_proof(const std::string& ed25519_pub_b64url, const std::string& mldsa65_pub_b64url,
                    const std::string& message, const Proof& proof);

// The X-RCAN-Signature of a signed update: "ed25519=<base64url signature of `message`>".
Result<std::string> sign_update(const keys::RobotKeys& keys, const std::string& message);
// Ok when `header` is such a signature of `message` by the key (base64url); else
// SIGNATURE_INVALID (reason bad_signature, or signature_malformed for a header in another form).
Status verify_update(const std::string& ed25519_pub_b64url, const std::string& message,
                     std::string_view header);

}  // namespace rcan::registry
