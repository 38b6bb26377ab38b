// JWT (JWS compact serialization, RFC 7515/7519) verification and issuing for RCAN tokens.
//
// Supported algorithms: EdDSA (Ed25519), ES256 (P-256, raw r‖s signatures), RS256 (RSA ≥ 2048
// bits, PKCS#1 v1.5) and HS256 — HS256 only with a key that the configuration explicitly
// names as a shared secret (VerificationKey::hs256_secret). `alg: none` and every other
// algorithm are rejected.
//
// Verification order (JwtVerifier::verify), each failure an Error with kAuthInvalid
// (kAuthRequired for an empty token):
//   1. size limit, three base64url segments (no padding, url alphabet only), header and claims
//      are JSON objects without duplicate keys; header `alg` is supported; `crit` is refused;
//   2. `iss` names a trusted issuer; the key is chosen by `kid` when the header has one;
//      the key's algorithm must equal the header's `alg` (no algorithm confusion: an HS256
//      token is never checked against a public key and vice versa);
//   3. the signature;
//   4. `exp` (required), `nbf`, `iat` (not in the future) with a configurable leeway;
//   5. `aud` (string or array) matches the robot RURI — wildcard segments `*` allowed;
//   6. §8.5: `sender_type` is one of human/robot/cloud_function/system, and
//      `cloud_function` requires a non-empty `cloud_provider`;
//   7. role: `role` (creator/owner/leasee/user/guest) or rcan-py numeric `rcan_role`
//      (1 GUEST, 2 and 2.5 USER, 3 OWNER, 5 CREATOR; anything else rejected); both must agree
//      when both are present;
//   8. scopes: `scope` (array or space-separated string), `scopes`, `rcan_scopes` (union);
//      when VerifyOptions::required_scope is set, the token must carry it and the role must be
//      at least the scope's minimum role (PROFILE.md §5);
//   9. `fleet`, when present, must contain one of VerifyOptions::fleet_ids.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/crypto/keys.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::jwt {

enum class Alg { kEdDSA, kES256, kRS256, kHS256 };
std::string_view alg_name(Alg alg);
std::optional<Alg> alg_from_name(std::string_view name);

inline constexpr size_t kDefaultMaxTokenBytes = 8192;
inline constexpr size_t kMinHs256SecretBytes = 32;

// A key that verifies signatures of one algorithm: a public key (EdDSA/ES256/RS256) or an
// HS256 shared secret. Cheap to copy (the OpenSSL key is shared; the secret is copied and
// wiped on destruction).
class VerificationKey {
 public:
  // SubjectPublicKeyInfo PEM ("-----BEGIN PUBLIC KEY-----") of an Ed25519, P-256 or RSA key.
  // Private keys are refused (a trust store holds no private material).
  static Result<VerificationKey> from_pem(std::string_view pem);
  // One JWK (RFC 7517): OKP/Ed25519, EC/P-256, RSA; `oct` only with allow_secret (HS256).
  // A JWK `alg`, when present, must agree with the key type; `use`, when present, must be "sig".
  static Result<VerificationKey> from_jwk(const json::Value& jwk, bool allow_secret = false);
  // HS256 shared secret, at least kMinHs256SecretBytes bytes.
  static Result<VerificationKey> hs256_secret(std::span<const uint8_t> secret);
  // Raw 32-byte Ed25519 public key.
  static Result<VerificationKey> ed25519_raw(std::span<const uint8_t> pk);

  VerificationKey(const VerificationKey& other);
  VerificationKey& operator=(const VerificationKey& other);
  VerificationKey(VerificationKey&&) noexcept;
  VerificationKey& operator=(VerificationKey&&) noexcept;
  ~VerificationKey();

  Alg alg() const { return alg_; }
  const std::string& kid() const { return kid_; }  // from a JWK, else empty
  void set_kid(std::string kid) { kid_ = std::move(kid); }

  // Verifies `sig` over `signing_input` with this key's algorithm. False on any error.
  bool verify(std::string_view signing_input, std::span<const uint8_t> sig) const;

  struct Impl;

 private:
  VerificationKey();
  Alg alg_ = Alg::kEdDSA;
  std::string kid_;
  std::shared_ptr<Impl> impl_;
};

// Loads verification keys from a file: a public-key PEM, a JWK, or a JWKS ({"keys":[…]}).
// With `hs256_secret`, the file is instead a shared secret: its bytes (minus one trailing
// "\n" or "\r\n") are the HMAC key; the file must not be group/world accessible.
Result<std::vector<VerificationKey>> load_verification_keys(const std::string& path,
                                                            bool hs256_secret = false);
// Parses a JWK or JWKS text (public keys only).
Result<std::vector<VerificationKey>> parse_jwk_set(std::string_view text);

// Trusted issuers and their keys.
class TrustStore {
 public:
  // Adds a key for `issuer`. `kid` (optional) overrides the key's own kid.
  void add(std::string issuer, VerificationKey key, std::string kid = {});
  bool empty() const { return entries_.empty(); }
  bool knows_issuer(std::string_view issuer) const;
  // Keys of `issuer`; when `kid` is non-empty only keys with that kid (keys without a kid
  // match any kid only when the issuer has no key with that kid).
  std::vector<const VerificationKey*> candidates(std::string_view issuer,
                                                 std::string_view kid) const;

  // One configured issuer: {issuer, key file, kind}. kind is "auto" (PEM/JWK/JWKS public
  // keys) or "hs256_secret" (shared-secret file).
  struct IssuerConfig {
    std::string issuer;
    std::string key_file;
    std::string kind = "auto";
    std::string kid;
  };
  static Result<TrustStore> from_config(const std::vector<IssuerConfig>& issuers);

 private:
  struct Entry {
    std::string issuer;
    std::string kid;
    VerificationKey key;
  };
  std::vector<Entry> entries_;
};

struct VerifyOptions {
  // Robot RURI every token's `aud` must match (required; empty → every token is rejected).
  std::string audience;
  // Identifiers of this device accepted in a `fleet` claim (device-id, RURI, RRN).
  std::vector<std::string> fleet_ids;
  // v1.5 fleet audiences ("rcan://fleet/<group>") of the fleets this device is in: such an
  // `aud` is accepted (exact match) only from a token that carries a `fleet` claim.
  std::vector<std::string> fleet_audiences;
  int64_t leeway_s = 60;
  size_t max_token_bytes = kDefaultMaxTokenBytes;
  bool require_iat = false;
  // When false, a token without `role`/`rcan_role` gets GUEST instead of being rejected.
  bool require_role = true;
  // When set, the token must carry this scope and its role must reach the scope's minimum.
  std::string required_scope;
  // Skip the audience / fleet checks (only for `rcan token inspect` without --aud/--device).
  bool skip_audience = false;
  bool skip_fleet = false;
};

struct Header {
  std::string alg;
  std::string kid;
  std::string typ;
  json::Object raw;
};

// The verified, interpreted claims. Role is expressed both as the seed role name and the
// level of PROFILE.md §5 (CREATOR 5, OWNER 4, LEASEE 3, USER 2, GUEST 1).
struct Claims {
  std::string iss;
  std::string sub;
  std::vector<std::string> aud;
  std::optional<int64_t> exp, nbf, iat;
  std::string jti;
  std::string kid;     // the header's key id (set by JwtVerifier::verify; "" when none)
  std::string role;    // "creator" | "owner" | "leasee" | "user" | "guest"
  int role_level = 0;  // 5..1
  std::vector<std::string> scopes;
  std::optional<std::vector<std::string>> fleet;
  std::string sender_type;  // as claimed; empty when absent
  std::string cloud_provider;
  std::string function_name;
  json::Object raw;  // every claim as received

  bool has_scope(std::string_view s) const;
};

struct Decoded {
  Header header;
  json::Object claims;
  std::string signing_input;  // "<b64 header>.<b64 claims>"
  Bytes signature;
};

// Splits and decodes a token without verifying anything but its syntax (for inspection and
// as step 1 of verification). Errors: kAuthInvalid (kAuthRequired when empty).
Result<Decoded> decode(std::string_view token, size_t max_token_bytes = kDefaultMaxTokenBytes);

// Interprets claims (steps 4–9 of the verification order) with `now` in unix seconds. The
// object ends up in Claims::raw (pass an rvalue to spare the copy).
Result<Claims> check_claims(json::Object claims, const VerifyOptions& opts, int64_t now);

// Seed role name ↔ level (rcan/roles.h). Level 0 / empty for unknown names/levels.
int role_level(std::string_view role_name);
std::string_view role_name(int level);
// rcan-py `rcan_role` → PROFILE level (1→1, 2 and 2.5→2, 3→4, 5→5); 0 when rejected.
int role_level_from_rcan_role(const json::Value& v);
// Minimum role level for a scope (rcan::scope_min_role); unknown scopes need USER (2).
int scope_min_level(std::string_view scope);

// `aud` pattern matching against the robot's RURI string: parses `ruri` (rcan::parse_ruri)
// and applies rcan::aud_matches (wildcard segments '*'). False when `ruri` does not parse.
bool aud_matches(std::string_view pattern, std::string_view ruri);

class JwtVerifier {
 public:
  JwtVerifier(TrustStore trust, VerifyOptions opts)
      : trust_(std::move(trust)), opts_(std::move(opts)) {}
  // Verifies `token` at unix time `now` (seconds).
  Result<Claims> verify(std::string_view token, int64_t now) const;
  // Same, with the system clock.
  Result<Claims> verify(std::string_view token) const;
  const VerifyOptions& options() const { return opts_; }
  VerifyOptions& mutable_options() { return opts_; }

 private:
  TrustStore trust_;
  VerifyOptions opts_;
};

// A key that signs tokens: a private key (Ed25519, P-256, RSA) or an HS256 secret.
class SigningKey {
 public:
  // PKCS#8 / traditional PEM private key of an Ed25519, P-256 or RSA (≥ 2048 bits) key.
  static Result<SigningKey> from_pem(std::string_view pem);
  // Raw 32-byte Ed25519 seed (a key directory's ed25519.seed).
  static Result<SigningKey> ed25519_seed(std::span<const uint8_t> seed);
  static Result<SigningKey> hs256_secret(std::span<const uint8_t> secret);
  // Loads a file: PEM private key, or a raw 32-byte Ed25519 seed, or (hs256) a secret file.
  // The file must not be group/world accessible.
  static Result<SigningKey> from_file(const std::string& path, bool hs256 = false);

  SigningKey(SigningKey&&) noexcept;
  SigningKey& operator=(SigningKey&&) noexcept;
  ~SigningKey();

  Alg alg() const { return alg_; }
  // The matching verification key (for HS256: the same secret).
  Result<VerificationKey> verification_key() const;
  Result<Bytes> sign(std::string_view signing_input) const;

  struct Impl;

 private:
  SigningKey();
  Alg alg_ = Alg::kEdDSA;
  std::unique_ptr<Impl> impl_;
};

// Builds and signs a token: header {"alg","typ":"JWT"[,"kid"]}, the given claims (in order).
Result<std::string> issue(const json::Object& claims, const SigningKey& key,
                          std::string_view kid = {});

// Parses a duration "90", "90s", "15m", "1h", "7d" into seconds (> 0, ≤ 10 years).
std::optional<int64_t> parse_duration(std::string_view s);

}  // namespace rcan::jwt
