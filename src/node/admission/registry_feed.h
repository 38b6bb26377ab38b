// What a robot reads from its registry's token authority (docs/SECURITY.md §Tokens from the
// registry): the signing keys it publishes (GET /.well-known/jwks.json) and the pages of its
// revocation feed (GET /api/v1/revocations?since=<seq>). Parsers only: the fetching, caching
// and applying is RegistryTrust's (registry_trust.h). Both refuse rather than guess: a
// document that is not what the contract says is an error, and the caller keeps what it had.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/crypto/jwt.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

inline constexpr size_t kMaxRegistryJwksBytes = 256 * 1024;
inline constexpr size_t kMaxRegistryKeys = 64;
inline constexpr size_t kRevocationPageSize = 500;  // the registry's page: a full page means more

struct RegistryKeySet {
  std::vector<jwt::VerificationKey> keys;  // each with its kid
  size_t skipped = 0;                      // entries that were not usable signing keys
};

// A JWKS {"keys":[…]}: the public signature keys (jwt::VerificationKey::from_jwk) that carry a
// `kid`; others are skipped. Errors (SCHEMA_VALIDATION_FAILED): not a JSON object with a
// `keys` array, too large, or no usable key at all.
Result<RegistryKeySet> parse_registry_jwks(std::string_view text);

struct RegistryRevocation {
  int64_t seq = 0;
  std::string jti;             // empty: none
  std::string sub;             // empty: none
  std::optional<int64_t> exp;  // unix s
  std::optional<int64_t> revoked_at_ms;
};

struct RevocationPage {
  std::vector<RegistryRevocation> entries;  // oldest first
  int64_t next_since = 0;
};

// One page answered for `since`. Every entry must have an integer `seq` above `since`, and a
// jti or a sub (strings of at most 512 bytes, or null); `next_since` must not go back. Errors:
// SCHEMA_VALIDATION_FAILED naming what is wrong.
Result<RevocationPage> parse_revocation_page(std::string_view text, int64_t since);

// "2026-11-27T05:35:00Z", with optional fraction and a Z or ±hh:mm offset → unix ms.
std::optional<int64_t> parse_iso8601_ms(std::string_view s);

// What rcand reads back from the registry when it introspects a token and registers itself
// (registry_trust.h; rcand's registry_join.h): answers straight off the network, parsed
// here so that they are fuzzed (fuzz/registry_answer_fuzz.cpp).
inline constexpr size_t kMaxRegistryAnswerBytes = 64 * 1024;

struct IntrospectionAnswer {
  std::optional<json::Object> claims;  // active: the token's claims, without "active"
  int64_t until_ms = 0;                // how long the answer may be used (wall ms)
};
// An RFC 7662 answer {"active": bool, …claims}. Active with an integer `exp`: its claims, good
// until the earlier of exp and now + active_ms. Inactive, or active without an integer exp:
// no claims, good until now + inactive_ms. Errors (SCHEMA_VALIDATION_FAILED): not a JSON object
// with a boolean `active`, or larger than kMaxRegistryAnswerBytes.
Result<IntrospectionAnswer> parse_introspection_answer(std::string_view body, int64_t now_ms,
                                                       int64_t active_ms, int64_t inactive_ms);

struct RegistryChallenge {
  std::string id, nonce;
};
// GET /api/v1/challenge: {"challenge_id", "nonce"}, both non-empty strings of at most 512 bytes.
Result<RegistryChallenge> parse_registry_challenge(std::string_view body);

struct RegistrationAnswer {
  std::string rrn;        // normalised (registry::normalize_rrn)
  std::string robot_key;  // the robot's own API key; empty when the registry sent none
};
// POST /api/v1/robots: {"rrn", "api_key"?}. Errors: not JSON, or no valid RRN.
Result<RegistrationAnswer> parse_registration_answer(std::string_view body);

// A refusal in one line: "the registry answered <status>", with its error body's `message`
// (else `error`) when it sent one, at most 512 bytes of it.
std::string registry_refusal(int status, std::string_view body);

}  // namespace rcan::node
