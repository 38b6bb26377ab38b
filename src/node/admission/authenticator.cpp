#include "node/admission/authenticator.h"

#include <algorithm>
#include <limits>

#include "node/admission/token_cache.h"

namespace rcan::node {

bool Principal::has_scope(std::string_view s) const {
  return std::find(scopes.begin(), scopes.end(), s) != scopes.end();
}

Authenticator::Authenticator(AuthOptions opts) : opts_(std::move(opts)) {
  verifier_ = std::make_shared<const jwt::JwtVerifier>(opts_.trust, opts_.verify);
  cache_ = std::make_unique<TokenCache>(opts_.token_cache_entries);
}

Authenticator::~Authenticator() = default;

std::shared_ptr<const jwt::JwtVerifier> Authenticator::verifier() const {
  MutexLock lock(verifier_mu_);
  return verifier_;
}

void Authenticator::set_followed_issuer_keys(const std::string& issuer,
                                             std::vector<jwt::VerificationKey> keys) {
  jwt::TrustStore trust = opts_.trust;  // the configured issuers, never changed
  for (auto& k : keys) {
    std::string kid = k.kid();
    trust.add(issuer, std::move(k), std::move(kid));
  }
  auto next = std::make_shared<const jwt::JwtVerifier>(std::move(trust), opts_.verify);
  {
    MutexLock lock(verifier_mu_);
    verifier_.swap(next);
  }
  // A token verified with a key that is no longer published must be verified afresh.
  cache_->clear();
}

void Authenticator::on_unknown_followed_key(std::string issuer, UnknownKey fn,
                                            Introspected introspected) {
  followed_issuer_ = std::move(issuer);
  on_unknown_key_ = std::move(fn);
  introspected_ = std::move(introspected);
}

Status Authenticator::check_followed_claims(const jwt::Claims& c) const {
  auto refused = [](std::string msg, const char* field, const char* reason) {
    return Error(ErrorCode::kAuthInvalid, std::move(msg), field, reason);
  };
  const jwt::VerifyOptions& v = opts_.verify;
  const bool fleet_token = c.fleet.has_value();
  const bool exact = std::any_of(c.aud.begin(), c.aud.end(), [&](const std::string& a) {
    if (a.find('*') != std::string::npos) return false;
    if (fleet_token &&
        std::find(v.fleet_audiences.begin(), v.fleet_audiences.end(), a) != v.fleet_audiences.end())
      return true;
    return jwt::aud_matches(a, v.audience);
  });
  if (!exact)
    return refused("a token of the registry (" + c.iss +
                       ") must name this robot in aud exactly, without a wildcard (" + v.audience +
                       ")",
                   "aud", "aud_not_exact");
  if (opts_.own_rrn.empty())
    return refused("this robot has no RRN to compare a registry token with", "rrn", "rrn_mismatch");
  if (fleet_token) {
    if (std::find(c.fleet->begin(), c.fleet->end(), opts_.own_rrn) == c.fleet->end())
      return refused("a fleet token of the registry must list this robot's RRN (" + opts_.own_rrn +
                         ") in its fleet claim",
                     "fleet", "fleet_mismatch");
    return Status::Ok();
  }
  const json::Value* rrn = c.raw.find("rrn");
  if (rrn == nullptr || !rrn->is_string() || rrn->as_string() != opts_.own_rrn)
    return refused("a token of the registry names another robot: its rrn is not this robot's (" +
                       opts_.own_rrn + ")",
                   "rrn", "rrn_mismatch");
  return Status::Ok();
}

Result<Principal> Authenticator::unverifiable(std::string_view token, int64_t now_s,
                                              Error e) const {
  auto d = jwt::decode(token, opts_.verify.max_token_bytes);
  const json::Value* iss = d.ok() ? d->claims.find("iss") : nullptr;
  if (!iss || !iss->is_string() || iss->as_string() != followed_issuer_) return e;
  if (introspected_) {
    if (auto answer = introspected_(token)) {
      auto claims = jwt::check_claims(std::move(*answer), opts_.verify, now_s);
      if (!claims.ok()) {
        Error ce = claims.error();
        if (ce.code != ErrorCode::kAuthRequired) ce.code = ErrorCode::kAuthInvalid;
        return ce;
      }
      if (claims->iss != followed_issuer_)
        return Error(ErrorCode::kAuthInvalid, "the introspected token names another issuer", "iss",
                     "untrusted_issuer");
      if (Status s = check_followed_claims(*claims); !s.ok()) return s.error();
      claims->kid = d->header.kid;
      return principal_of(std::move(claims).value());
    }
  }
  if (on_unknown_key_) on_unknown_key_(d->header.kid, token);
  return e;
}

Result<Principal> Authenticator::authenticate_token(std::string_view token, int64_t now_s) const {
  if (token.empty())
    return Error(ErrorCode::kAuthRequired, "a bearer token is required", "auth_token");
  if (auto hit = cache_->find(token, now_s)) return std::move(*hit);
  auto claims = verifier()->verify(token, now_s);
  if (!claims.ok()) {
    Error e = claims.error();
    if (e.code != ErrorCode::kAuthRequired) e.code = ErrorCode::kAuthInvalid;
    if (!followed_issuer_.empty() && (e.reason == "unknown_kid" || e.reason == "untrusted_issuer"))
      return unverifiable(token, now_s, std::move(e));
    return e;
  }
  if (!followed_issuer_.empty() && claims->iss == followed_issuer_)
    if (Status s = check_followed_claims(*claims); !s.ok()) return s.error();
  // The window in which jwt::check_claims' time checks pass (exp required; nbf, iat optional).
  const int64_t leeway = std::max<int64_t>(0, opts_.verify.leeway_s);
  int64_t from = std::numeric_limits<int64_t>::min();
  if (claims->nbf) from = std::max(from, *claims->nbf - leeway);
  if (claims->iat) from = std::max(from, *claims->iat - leeway);
  const std::optional<int64_t> exp = claims->exp;
  auto p = principal_of(std::move(claims).value());
  if (p.ok() && exp) cache_->insert(token, *p, from, *exp + leeway);
  return p;
}

Result<Principal> Authenticator::principal_of(jwt::Claims&& claims_in) const {
  jwt::Claims* claims = &claims_in;
  Principal p;
  p.authenticated = true;
  p.issuer = claims->iss;
  p.sub = claims->sub;
  auto role = role_from_name(claims->role);
  if (!role) return Error(ErrorCode::kAuthInvalid, "token role is not an RCAN role", "role");
  p.role = *role;
  p.scopes = claims->scopes;
  p.token_exp = claims->exp;
  p.token_iat = claims->iat;
  p.jti = claims->jti;
  p.kid = claims->kid;
  if (const json::Value* c = claims->raw.find("cnf")) {
    auto bound = cnf::parse(*c);
    if (!bound.ok()) return bound.error();
    p.bound_key = std::make_shared<const cnf::BoundKey>(std::move(bound).value());
  }
  if (claims->fleet)
    p.fleet = std::make_shared<const std::vector<std::string>>(std::move(*claims->fleet));
  p.token_identity.sub = claims->sub;
  if (!claims->sender_type.empty()) p.token_identity.sender_type = claims->sender_type;
  if (!claims->cloud_provider.empty()) p.token_identity.cloud_provider = claims->cloud_provider;
  if (!claims->function_name.empty()) p.token_identity.function_name = claims->function_name;
  if (Status s = check_token_sender_claims(p.token_identity); !s.ok()) return s.error();
  return p;
}

bool Authenticator::is_cached(std::string_view token, int64_t now_s) const {
  return !token.empty() && cache_->find(token, now_s).has_value();
}

Result<SignatureCheck> Authenticator::check_signature(const Message& msg, const Principal& p,
                                                      bool need_bound_key) const {
  SignatureCheck c;
  const json::Value* sig = msgsig::signature_member(msg.wire);
  if (p.bound_key || need_bound_key) {
    auto bound = check_bound_key(msg.wire, p, need_bound_key);
    if (!bound.ok()) return bound.error();
    c.present = c.verified = c.bound_key = true;  // a bound key exists: check_bound_key says so
    c.alg = std::string(msgsig::alg_name(p.bound_key->alg));
    c.kid = p.bound_key->kid;
    return c;
  }
  if (!sig || sig->is_null()) {
    if (opts_.require_signature)
      return Error(ErrorCode::kAuthRequired, "this node requires signed messages", "sig");
    return c;
  }
  c.present = true;
  // Peer-robot keys first: a robot signature changes the §8.5 verdict.
  if (!opts_.robot_keys.mldsa65.empty() || !opts_.robot_keys.ed25519.empty()) {
    auto r = msgsig::verify(msg.wire, opts_.robot_keys);
    if (r.ok()) {
      c.verified = true;
      c.robot_key = true;
      c.alg = std::string(msgsig::alg_name(r->alg));
      c.kid = r->kid;
      return c;
    }
  }
  auto r = msgsig::verify(msg.wire, opts_.signer_keys);
  if (!r.ok()) {
    Error e = r.error();
    if (e.code == ErrorCode::kAuthRequired) e.code = ErrorCode::kSignatureInvalid;
    if (e.code != ErrorCode::kSchemaValidationFailed && e.code != ErrorCode::kInvalidRuri)
      e.code = ErrorCode::kSignatureInvalid;
    return e;
  }
  c.verified = true;
  c.alg = std::string(msgsig::alg_name(r->alg));
  c.kid = r->kid;
  return c;
}

Result<bool> Authenticator::check_bound_key(const json::Object& wire, const Principal& p,
                                            bool need_bound_key) const {
  if (!p.bound_key) {
    if (!need_bound_key) return false;
    return Error(ErrorCode::kAuthInvalid,
                 "over this transport a token must be bound to a key (cnf) and the message "
                 "signed with it",
                 "cnf");
  }
  const json::Value* sig = wire.find("sig");
  if (!sig || sig->is_null())
    return Error(ErrorCode::kAuthRequired,
                 "the token is bound to a key (cnf): sign the message with that key", "sig");
  auto r = cnf::verify(wire, *p.bound_key);
  if (!r.ok()) {
    Error e = r.error();
    if (e.code != ErrorCode::kSchemaValidationFailed && e.code != ErrorCode::kInvalidRuri)
      e.code = ErrorCode::kSignatureInvalid;
    return e;
  }
  return true;
}

Result<SenderIdentity> Authenticator::sender(const Message& msg, const Principal& p,
                                             const SignatureCheck& sig) const {
  return resolve_sender(msg, p.token_identity, sig.robot_key, true);
}

}  // namespace rcan::node
