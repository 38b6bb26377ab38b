// JWT verification for RCAN tokens: JwtVerifier runs the order of include/rcan/crypto/jwt.h —
// decode (jws.cpp), algorithm and issuer checks, key choice from the trust store (jwt_keys.cpp),
// the signature, then the RCAN claim policy (jwt_claims.cpp).
//
// Contract: a token is accepted only when a trusted issuer's key of the header's own algorithm
// verifies it (`alg: none`, `crit` and algorithm confusion are refused before any signature
// work) and its claims pass check_claims(); every refusal is an Error with kAuthInvalid
// (kAuthRequired for an empty token, kInsufficientPrivileges for a missing scope).
#include "rcan/crypto/jwt.h"

#include <chrono>

#include "base/clock.h"
#include "base/strings.h"
#include "crypto/jwt_internal.h"

namespace rcan::jwt {

using detail::auth_invalid;

namespace {}  // namespace

// ---------------------------------------------------------------------------------------
// JwtVerifier

Result<Claims> JwtVerifier::verify(std::string_view token, int64_t now) const {
  auto d = decode(token, opts_.max_token_bytes);
  if (!d.ok()) return d.error();
  const std::string& alg_s = d->header.alg;
  if (ascii_lower(alg_s) == "none")
    return auth_invalid("alg none is not accepted", "alg", "alg_none");
  auto alg = alg_from_name(alg_s);
  if (!alg) return auth_invalid("unsupported alg \"" + alg_s + "\"", "alg", "bad_alg");
  if (d->header.raw.find("crit"))
    return auth_invalid("crit header parameters are not supported", "crit", "crit");

  const json::Value* iss = d->claims.find("iss");
  if (!iss || !iss->is_string() || iss->as_string().empty())
    return auth_invalid("iss is missing", "iss", "missing_claim");
  if (!trust_.knows_issuer(iss->as_string()))
    return auth_invalid("issuer \"" + iss->as_string() + "\" is not trusted", "iss",
                        "untrusted_issuer");
  auto cands = trust_.candidates(iss->as_string(), d->header.kid);
  if (cands.empty())
    return auth_invalid("issuer has no key with kid \"" + d->header.kid + "\"", "kid",
                        "unknown_kid");
  bool any_alg = false, verified = false;
  for (const VerificationKey* k : cands) {
    if (k->alg() != *alg) continue;
    any_alg = true;
    if (k->verify(d->signing_input, d->signature)) {
      verified = true;
      break;
    }
  }
  if (!any_alg)
    return auth_invalid(
        "alg " + alg_s + " does not match the issuer's key type (algorithm confusion refused)",
        "alg", "alg_mismatch");
  if (!verified) return auth_invalid("signature does not verify", "signature", "bad_signature");
  auto claims = check_claims(std::move(d->claims), opts_, now);
  if (claims.ok()) claims->kid = d->header.kid;
  return claims;
}

Result<Claims> JwtVerifier::verify(std::string_view token) const {
  return verify(token, unix_seconds());
}

}  // namespace rcan::jwt
