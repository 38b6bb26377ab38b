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
inline constexpr std::string_view kAlgHybrid = "hybrid-ed25519-ml-dsa-65";
inline constexpr size_t kMaxSigValueChars = 8192;

enum class Alg { kMlDsa65, kEd25519, kHybrid };
std::string_view alg_name(Alg alg);
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

// The message's signature member: `sig` (rcan-py block, or the hybrid `sign_body` block), or
// rcan-ts's `signature` {alg, kid, sig}; null when unsigned.
const json::Value* signature_member(const json::Object& msg);

// Verifies the message's signature, whichever form it takes:
//   * `sig` {alg, kid, value}: the rcan-py pre-image (or the seed's canonical one);
//   * `sig` {ml_dsa, ed25519, ed25519_pub} with top-level pq_signing_pub and pq_kid: a hybrid
//     signed body (rcan-py `hybrid.sign_body`, rcan-ts `signBody`; include/rcan/crypto/hybrid.h),
//     verified in strict mode: the ML-DSA-65 key is the trusted key whose kid is pq_kid, and
//     sig.ed25519_pub must be a trusted Ed25519 key; both signatures must verify (kid = pq_kid);
//   * rcan-ts `signature` {alg: "ml-dsa-65", kid, sig}: rcan-ts's signMessage pre-image
//     (rcants_preimage).
// Errors: kAuthRequired (unsigned), kSignatureInvalid (malformed block, unknown kid, bad
// signature), or the pre-image errors above.
Result<SigBlock> verify(const json::Object& msg, const TrustedKeys& trusted);
// The first form alone: `sig` {alg, kid, value}.
Result<SigBlock> verify_block(const json::Object& msg, const TrustedKeys& trusted);

// rcan-ts 3.4.2 signMessage's pre-image for a received rcan-ts message: JavaScript
// JSON.stringify of {cmd, msg_id: "", params, rcan, target, timestamp} (top-level keys sorted,
// nested members in wire order, raw UTF-8, JavaScript number formatting). rcan-ts always signs
// an empty msg_id (its messages carry none). Errors: kSchemaValidationFailed naming the field.
Result<std::string> rcants_preimage(const json::Object& msg);
// JavaScript's JSON.stringify of a value (members in stored order).
std::string js_stringify(const json::Value& v);

struct SignOptions {
  bool deterministic = false;  // ML-DSA rnd = 0^32 (reproducible; tests and vectors)
};
// Signs `msg` in place (any existing `sig` is replaced) with ML-DSA-65.
Status sign_mldsa65(json::Object& msg, std::span<const uint8_t> secret_key,
                    std::span<const uint8_t> public_key, const SignOptions& opts = {});
// Signs `msg` in place with Ed25519 (32-byte seed).
Status sign_ed25519(json::Object& msg, std::span<const uint8_t> seed);

}  // namespace rcan::msgsig
