// Message signatures: the `sig` block {alg, kid, value} carried by RCAN messages.
//
// Two pre-images, chosen by the message's shape:
//   * rcan-py shape (the message has a `cmd` member): rcan-py's
//     `_canonical_message_bytes` — Python json.dumps of {rcan, msg_id, timestamp, cmd, target,
//     params} with sort_keys, compact separators, ensure_ascii and Python float repr
//     (json::python_dumps), after rcan-py's own normalisation of the received fields:
//       - `target` is parsed as an rcan-py RobotURI: surrounding whitespace and one trailing
//         '/' are dropped; it must be the 5-segment SDK form;
//       - `rcan`/`rcan_version` sync: when `rcan` equals "3.2" (rcan-py's SPEC_VERSION) and
//         `rcan_version` differs, the pre-image carries `rcan_version`'s value;
//       - `params` defaults to {} when absent.
//     Only those six fields are covered; everything else in the envelope is unauthenticated.
//   * seed shape (anything else): rcan-canonical-json-v1 of the whole message without `sig`.
//
// Algorithms: "ml-dsa-65" (kid = first 8 hex of SHA-256 of the raw 1952-byte pk; value =
// base64url of the 3309-byte signature, padding optional on input, emitted with padding as
// rcan-py does) and "ed25519" (kid = first 8 hex of SHA-256 of the SPKI PEM, rcan-py's
// KeyPair; value = base64url of the 64-byte signature). `value: "pending"` is rejected.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::msgsig {

inline constexpr std::string_view kAlgMlDsa65 = "ml-dsa-65";
inline constexpr std::string_view kAlgEd25519 = "ed25519";
inline constexpr size_t kMaxSigValueChars = 8192;

enum class Alg { kMlDsa65, kEd25519 };
enum class Preimage { kRcanPy, kCanonical };

struct SigBlock {
  Alg alg = Alg::kMlDsa65;
  std::string kid;
  Bytes value;  // decoded signature bytes
};

// Parses and checks a `sig` member: an object with string alg ∈ {ml-dsa-65, ed25519},
// kid (8 lower-case hex), value (base64url, right length for alg). Errors:
// kSignatureInvalid with field "sig".
Result<SigBlock> parse_sig_block(const json::Value& sig);
// The `sig` JSON object {alg, kid, value} for a signature (value base64url with padding).
json::Value make_sig_block(Alg alg, std::string_view kid, std::span<const uint8_t> signature);

// Which pre-image a message uses (see the file comment).
Preimage preimage_kind(const json::Object& msg);
// rcan-py's `_canonical_message_bytes` for a received rcan-py-shape message.
// Errors: kSchemaValidationFailed naming the field (missing/mistyped rcan, msg_id, timestamp,
// cmd, target, params) or kInvalidRuri for a target rcan-py would not parse.
Result<std::string> rcanpy_preimage(const json::Object& msg);
// The pre-image for either shape.
Result<std::string> preimage(const json::Object& msg);

// Keys a verifier trusts, looked up by kid.
struct TrustedKeys {
  std::vector<Bytes> mldsa65;  // raw 1952-byte public keys
  std::vector<Bytes> ed25519;  // raw 32-byte public keys
};

// Verifies msg["sig"]. Errors: kAuthRequired (no sig), kSignatureInvalid (malformed block,
// unknown kid, bad signature), or the pre-image errors above.
Result<SigBlock> verify(const json::Object& msg, const TrustedKeys& trusted);

struct SignOptions {
  bool deterministic = false;  // ML-DSA rnd = 0^32 (reproducible; tests and vectors)
};
// Signs `msg` in place (any existing `sig` is replaced) with ML-DSA-65.
Status sign_mldsa65(json::Object& msg, std::span<const uint8_t> secret_key,
                    std::span<const uint8_t> public_key, const SignOptions& opts = {});
// Signs `msg` in place with Ed25519 (32-byte seed).
Status sign_ed25519(json::Object& msg, std::span<const uint8_t> seed);

}  // namespace rcan::msgsig
