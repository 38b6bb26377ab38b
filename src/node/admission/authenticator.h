// Authenticator — who sent this? Verifies the bearer token (JWT, docs/CRYPTO.md) and the
// message signature when present, and applies the §8.5 sender-identity rules.
//
// There is no open mode: a message without a valid token is refused (DISCOVER and the
// public read-only routes are the only exceptions, decided by the router, not here).
#pragma once

#include <compare>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "rcan/crypto/cnf.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/message.h"
#include "rcan/result.h"
#include "rcan/roles.h"
#include "rcan/sender_identity.h"

namespace rcan::node {

struct Principal {
  bool authenticated = false;
  std::string issuer;
  std::string sub;
  Role role = Role::kGuest;
  std::vector<std::string> scopes;
  std::optional<int64_t> token_exp;  // unix seconds
  std::optional<int64_t> token_iat;  // unix seconds
  std::string jti;                   // the token's `jti` ("" when it has none)
  std::string kid;                   // the key id in the token's header ("" when none)
  TokenIdentity token_identity;
  // The token's `fleet` claim (a fleet JWT; already checked to list this robot). Shared: a
  // fleet token lists every member, and a Principal is copied once per message.
  std::shared_ptr<const std::vector<std::string>> fleet;
  // The key the token is bound to (its `cnf` claim, rcan/crypto/cnf.h): every message sent
  // with it must be signed by that key. Null for a plain bearer token.
  std::shared_ptr<const cnf::BoundKey> bound_key;

  // Stable key for rate limits and session ownership.
  std::string key() const { return issuer + "\x1f" + sub; }
  // What audit records show as `principal`.
  std::string display() const { return authenticated ? sub : "anonymous"; }
  bool has_scope(std::string_view s) const;
};

// A principal named by issuer and subject — whom an ownership transfer, a lease, a grant
// within it, a handoff or a consent request names. Two trusted issuers may both know a `sub`
// "alice": they are two principals, and only (issuer, subject) together name one.
struct PrincipalId {
  std::string iss;  // empty only in state files written before the issuer was kept: any issuer
  std::string sub;

  static PrincipalId of(const Principal& p) { return PrincipalId{p.issuer, p.sub}; }
  // Whether `p` is the principal named (a legacy entry without issuer: by subject alone).
  bool is(const Principal& p) const { return is(of(p)); }
  bool is(const PrincipalId& o) const { return sub == o.sub && (iss.empty() || iss == o.iss); }
  bool empty() const { return sub.empty(); }
  auto operator<=>(const PrincipalId&) const = default;
};

struct SignatureCheck {
  bool present = false;
  bool verified = false;
  bool robot_key = false;  // signed by a key configured as a peer robot's
  bool bound_key = false;  // signed by the key the token is bound to (cnf)
  std::string alg;
  std::string kid;
};

struct AuthOptions {
  jwt::TrustStore trust;
  jwt::VerifyOptions verify;
  // Keys whose signatures are accepted on messages; `robot` marks peer-robot keys.
  msgsig::TrustedKeys signer_keys;
  msgsig::TrustedKeys robot_keys;
  bool require_signature = false;
  // Verified tokens remembered (node/token_cache.h); 0 verifies every token every time.
  size_t token_cache_entries = 4096;
  // This robot's RRN. A token of the followed issuer (a registry, which serves many robots'
  // registrants) must name it: its `rrn` claim, or its `fleet` claim for a fleet token.
  std::string own_rrn;
};

class TokenCache;

class Authenticator {
 public:
  explicit Authenticator(AuthOptions opts);
  ~Authenticator();

  // Verifies a bearer token at unix time `now_s`. Errors: AUTH_REQUIRED (empty), AUTH_INVALID.
  Result<Principal> authenticate_token(std::string_view token, int64_t now_s) const;
  // Whether `token` is in the verified-token cache at `now_s` (a cheap look: no signature is
  // checked, and a miss says nothing about the token).
  bool is_cached(std::string_view token, int64_t now_s) const;
  // Verifies msg.sig over the received wire object. A token bound to a key (p.bound_key) needs
  // a signature by exactly that key; `need_bound_key` (a message from a shared channel such as
  // MQTT) refuses a token that is bound to no key. Otherwise the signature is checked when
  // present. Errors: SIGNATURE_INVALID; AUTH_REQUIRED when a signature is required and absent;
  // AUTH_INVALID when a bound token is required and this one is not.
  Result<SignatureCheck> check_signature(const Message& msg, const Principal& p,
                                         bool need_bound_key = false) const;
  // The key-binding part of check_signature over a raw wire object (a request that is not an
  // RCAN message, such as a swarm join): Ok(true) when signed by the token's bound key,
  // Ok(false) when the token is bound to nothing and none is needed; otherwise the error.
  Result<bool> check_bound_key(const json::Object& wire, const Principal& p,
                               bool need_bound_key) const;
  // §8.5: the sender identity the audit record carries.
  Result<SenderIdentity> sender(const Message& msg, const Principal& p,
                                const SignatureCheck& sig) const;

  const jwt::VerifyOptions& verify_options() const { return opts_.verify; }

  // The keys an issuer publishes and the node follows (rcand's registry link): tokens whose
  // `iss` is `issuer` verify with `keys`, next to the configured issuers; each call replaces
  // the previous set and empties the verified-token cache. Safe while other threads
  // authenticate: a verification in flight finishes with the keys it started with.
  void set_followed_issuer_keys(const std::string& issuer, std::vector<jwt::VerificationKey> keys)
      EXCLUDES(verifier_mu_);
  // Called on the authenticating thread when a token names `issuer` (the followed issuer) and
  // none of its keys has the token's kid. It must not block (it may only ask for a refresh or
  // an introspection, done elsewhere). Set before the node serves.
  using UnknownKey = std::function<void(const std::string& kid, std::string_view token)>;
  // The issuer's own word on such a token (RFC 7662 introspection, answered and cached off the
  // authenticating thread): the claims of an active answer, or nullopt (not asked yet, asked
  // and inactive, or failed). The claims are checked here as a verified token's are (exp, aud,
  // role, scopes, fleet); `iss` must be the followed issuer. Must not block.
  using Introspected = std::function<std::optional<json::Object>(std::string_view token)>;
  void on_unknown_followed_key(std::string issuer, UnknownKey fn, Introspected introspected = {});

 private:
  std::shared_ptr<const jwt::JwtVerifier> verifier() const EXCLUDES(verifier_mu_);
  // The principal of claims that passed verification (or the issuer's introspection).
  Result<Principal> principal_of(jwt::Claims&& claims) const;
  // A token of the followed issuer must name this robot exactly (docs/THREATS.md, T1): an
  // audience without a wildcard that matches its RURI (or its fleet's), and its RRN in the
  // `rrn` claim (or, for a fleet token, in the `fleet` claim). A registry's token authority
  // serves every registrant of the registry: no registrant's token may reach another's robot.
  Status check_followed_claims(const jwt::Claims& c) const;
  // A followed issuer's token its keys cannot verify: its introspected principal, or `e`.
  Result<Principal> unverifiable(std::string_view token, int64_t now_s, Error e) const;

  AuthOptions opts_;
  mutable Mutex verifier_mu_;
  std::shared_ptr<const jwt::JwtVerifier> verifier_ GUARDED_BY(verifier_mu_);
  std::unique_ptr<TokenCache> cache_;
  std::string followed_issuer_;
  UnknownKey on_unknown_key_;
  Introspected introspected_;
};

}  // namespace rcan::node
