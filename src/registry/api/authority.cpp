// The token authority of seed §4.1–4.2 (docs/REGISTRY.md "Token authority"): signing keys and
// the JWKS, the OAuth 2.0 token endpoint (client credentials with a secret or private_key_jwt,
// RFC 7523; the device authorization grant, RFC 8628) and introspection (RFC 7662).
#include <algorithm>
#include <tuple>

#include "rcan/crypto/ed25519.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/ruri.h"
#include "registry/api/authority_internal.h"
#include "registry/api/impl.h"
#include "registry/api/oauth_form.h"

namespace rcan::registry::api {

HttpResponse oauth_error(int status, const std::string& error, const std::string& description) {
  HttpResponse r =
      json_response(status, json::Object{{"error", error}, {"error_description", description}});
  r.headers.emplace_back("Cache-Control", "no-store");
  r.headers.emplace_back("Pragma", "no-cache");
  return r;
}

std::string random_b64url(size_t bytes) {
  Bytes b(bytes);
  if (!random_bytes(b.data(), b.size())) return {};
  return base64url_encode(b);
}

std::string random_hex_id(size_t bytes) {
  Bytes b(bytes);
  if (!random_bytes(b.data(), b.size())) return {};
  return to_hex(b);
}

Result<std::vector<SigningKeyRecord>> RegistryApi::Impl::authority_keys(bool fresh) {
  int64_t now = now_ms();
  std::lock_guard lock(keys_mu);
  if (!fresh && keys_loaded_ms >= 0 && now - keys_loaded_ms < 1000 && !keys_cache.empty())
    return keys_cache;
  auto keys = store.signing_keys();
  if (!keys) return keys.error();
  // The signer: the newest key whose sign_from has come.
  const SigningKeyRecord* signer = nullptr;
  bool pending = false;
  for (const auto& k : *keys) {
    if (k.sign_from_ms <= now)
      signer = &k;
    else
      pending = true;
  }
  if (signer == nullptr && !pending) {
    auto k = new_signing_key(now, true);
    if (!k) return k.error();
    keys->push_back(*k);
  } else if (signer != nullptr && !pending &&
             now - signer->sign_from_ms >= o.key_lifetime_s * 1000) {
    auto k = new_signing_key(now, false);
    if (!k) return k.error();
    keys->push_back(*k);
  }
  // Retire keys no token can still need: a later key has signed for longer than a token lives.
  std::vector<SigningKeyRecord> live;
  for (size_t i = 0; i < keys->size(); ++i) {
    bool retired = false;
    for (size_t j = i + 1; j < keys->size(); ++j)
      if ((*keys)[j].sign_from_ms + (o.max_token_ttl_s + 60) * 1000 <= now) retired = true;
    if (retired) {
      (void)store.delete_signing_key((*keys)[i].kid);
      audit("REGISTRY_AUTHORITY_KEY_RETIRED", "registry", registry_ruri(),
            json::Object{{"kid", (*keys)[i].kid}});
    } else {
      live.push_back((*keys)[i]);
    }
  }
  keys_cache = live;
  keys_loaded_ms = now;
  return live;
}

Result<SigningKeyRecord> RegistryApi::Impl::new_signing_key(int64_t now, bool first) {
  SigningKeyRecord k;
  k.kid = random_hex_id(8);
  Bytes seed = ed25519::random_seed();
  if (k.kid.empty() || seed.size() != ed25519::kSeedBytes)
    return Error(ErrorCode::kInternal, "no randomness for a signing key");
  k.seed = base64url_encode(seed);
  secure_wipe(seed.data(), seed.size());
  k.created_ms = now;
  k.sign_from_ms = first ? now : now + o.key_overlap_s * 1000;
  if (Status s = store.put_signing_key(k); !s.ok()) return s.error();
  audit("REGISTRY_AUTHORITY_KEY_CREATED", "registry", registry_ruri(),
        json::Object{{"kid", k.kid}, {"sign_from", iso_utc(k.sign_from_ms)}});
  return k;
}

namespace {

std::optional<Bytes> pub_of(const SigningKeyRecord& k) {
  auto seed = base64url_decode(k.seed);
  if (!seed) return std::nullopt;
  auto pub = ed25519::public_key_from_seed(*seed);
  secure_wipe(seed->data(), seed->size());
  if (!pub.ok()) return std::nullopt;
  return *pub;
}

}  // namespace

HttpResponse RegistryApi::Impl::jwks() {
  auto keys = authority_keys();
  if (!keys) return store_error(keys.error());
  json::Array out;
  for (const auto& k : *keys) {
    auto pub = pub_of(k);
    if (!pub) continue;
    out.emplace_back(json::Object{{"kty", "OKP"},
                                  {"crv", "Ed25519"},
                                  {"x", base64url_encode(*pub)},
                                  {"kid", k.kid},
                                  {"use", "sig"},
                                  {"alg", "EdDSA"}});
  }
  HttpResponse r = json_response(200, json::Object{{"keys", std::move(out)}});
  r.content_type = "application/jwk-set+json";
  r.headers.emplace_back("Cache-Control", "public, max-age=" + std::to_string(o.jwks_max_age_s));
  return r;
}

Result<jwt::Claims> RegistryApi::Impl::check_own_token(std::string_view token) {
  auto d = jwt::decode(token);
  if (!d) return d.error();
  auto keys = authority_keys();
  if (!keys) return keys.error();
  bool known = std::any_of(keys->begin(), keys->end(),
                           [&](const SigningKeyRecord& k) { return k.kid == d->header.kid; });
  if (!known) {
    keys = authority_keys(true);  // another instance may have rotated
    if (!keys) return keys.error();
  }
  jwt::TrustStore trust;
  for (const auto& k : *keys) {
    if (k.kid != d->header.kid) continue;
    auto pub = pub_of(k);
    if (!pub) continue;
    auto vk = jwt::VerificationKey::ed25519_raw(*pub);
    if (vk.ok()) trust.add(o.public_url, std::move(*vk), k.kid);
  }
  if (trust.empty()) return Error(ErrorCode::kAuthInvalid, "unknown key id");
  jwt::VerifyOptions vo;
  vo.skip_audience = true;
  vo.skip_fleet = true;
  vo.leeway_s = 0;
  jwt::JwtVerifier v(std::move(trust), vo);
  auto c = v.verify(token, now_ms() / 1000);
  if (!c) return c.error();
  int64_t iat_ms = c->iat ? *c->iat * 1000 : 0;
  auto revoked = store.is_revoked(c->jti, c->sub, iat_ms);
  if (!revoked) return revoked.error();
  if (*revoked) return Error(ErrorCode::kAuthInvalid, "revoked");
  return c;
}

// ---- target resolution and issuance

Result<std::string> robot_audience(const Robot& r, const std::string& host) {
  auto refused = [&](std::string why) {
    return Error(ErrorCode::kInsufficientPrivileges,
                 (r.rrn.empty() ? std::string("this robot") : r.rrn) + ": " + std::move(why) +
                     ": the registry issues no token for it",
                 "resource", "unproven_robot");
  };
  if (r.ed25519_pub.empty() && r.mldsa65_pub.empty())
    return refused("the robot proved no key at its registration");
  std::string claimed = "rcan://" + host + "/" + r.manufacturer + "/" + r.model + "/" + r.device_id;
  auto meta = json::parse(r.metadata_json);
  if (meta.ok() && meta->is_object())
    if (const json::Value* ruri = meta->get("ruri"); ruri != nullptr) {
      if (!ruri->is_string()) return refused("metadata.ruri is not a string");
      claimed = ruri->as_string();
    }
  // parse_ruri refuses a wildcard: a RURI names one robot.
  auto p = parse_ruri(claimed);
  if (!p.ok()) return refused("its RURI " + claimed.substr(0, 128) + ": " + p.error().message);
  if (p->form == Ruri::Form::kDiscovered || !p->capability.empty() || p->port)
    return refused("its RURI names an address or a capability, not a robot");
  if (p->manufacturer != r.manufacturer || p->model != r.model || p->device_id != r.device_id ||
      (p->form == Ruri::Form::kSdk5 && p->version != r.version))
    return refused("its RURI " + p->base() + " is not the robot its proof named (" +
                   r.manufacturer + "/" + r.model + "/" + r.version + "/" + r.device_id + ")");
  return p->base();
}

Status RegistryApi::Impl::unique_audience(const Robot& r, const std::string& aud) {
  RobotQuery q;
  q.manufacturer = r.manufacturer;
  q.model = r.model;
  q.limit = 100;
  for (int64_t offset = 0;; offset += q.limit) {
    q.offset = offset;
    auto page = store.list_robots(q);
    if (!page) return page.error();
    for (const Robot& other : page->robots) {
      // A synced copy (no owner here) is a peer's to answer for, under its own host: it claims no
      // name of this registry's robots (a peer could otherwise keep them from their tokens).
      if (other.rrn == r.rrn || other.device_id != r.device_id || other.version == r.version ||
          other.owner_key_id.empty())
        continue;
      auto its = robot_audience(other, o.host);
      if (!its.ok() || *its != aud) continue;
      // The first registration keeps the name; a later one that claims it gets nothing.
      if (r.registered_at.empty() ||
          std::tie(other.registered_at, other.rrn) < std::tie(r.registered_at, r.rrn))
        return Error(ErrorCode::kInsufficientPrivileges,
                     aud + " is the RURI of " + other.rrn + ", registered before" +
                         (r.rrn.empty() ? std::string() : " " + r.rrn),
                     "resource", "ruri_taken");
    }
    if (static_cast<int64_t>(page->robots.size()) < q.limit) break;
  }
  return Status::Ok();
}

Result<Target> RegistryApi::Impl::resolve_target(const std::string& resource) {
  Target t;
  if (resource.rfind("fleet:", 0) == 0) {
    t.fleet = resource.substr(6);
    if (t.fleet.empty() || t.fleet.size() > 64 || slugify(t.fleet) != t.fleet)
      return Error(ErrorCode::kSchemaValidationFailed, "a fleet id is [a-z0-9-], at most 64");
    t.aud = "rcan://fleet/" + t.fleet;
    return t;
  }
  std::optional<Robot> robot;
  if (auto rrn = parse_rrn(resource)) {
    auto got = store.get_robot(rrn->rrn);
    if (!got) return got.error();
    robot = std::move(*got);
  } else if (resource.rfind("rcan://", 0) == 0 && resource.size() <= kMaxUrl) {
    auto got = store.find_robot_by_uri(resource);
    if (!got) return got.error();
    robot = std::move(*got);
    if (!robot) {
      // The 4-segment form rcand uses: rcan://host/mfr/model/device → the record's RURI (v1).
      auto r = parse_ruri(resource);
      if (r.ok()) {
        auto res = store.find_robot_by_uri("rcan://" + o.host + "/" + r->manufacturer + "/" +
                                           r->model + "/v1/" + r->device_id);
        if (!res) return res.error();
        robot = std::move(*res);
      }
    }
  }
  if (!robot)
    return Error(ErrorCode::kNotFound, "no robot registered here under that resource", "resource",
                 "unknown");
  t.rrn = robot->rrn;
  t.owner_key_id = robot->owner_key_id;
  auto aud = robot_audience(*robot, o.host);
  if (Status unique = aud.ok() ? unique_audience(*robot, *aud) : Status(aud.error()); unique.ok())
    t.aud = *aud;
  else
    t.refused = unique.error();
  return t;
}

bool grant_covers_target(const Grant& g, const Target& t) {
  if (!t.fleet.empty()) return g.fleet == t.fleet;
  return g.fleet.empty() && g.rrn == t.rrn;
}

Result<GrantChoice> RegistryApi::Impl::choose_grant(const std::string& principal, const Target& t,
                                                    const std::string& scope,
                                                    const std::string& role) {
  auto want = parse_scope(scope);
  if (!want)
    return Error(ErrorCode::kSchemaValidationFailed, "malformed scope", "scope", "invalid_scope");
  if (!role.empty() && (jwt::role_level(role) == 0 || role == "creator"))
    return Error(ErrorCode::kSchemaValidationFailed, "unknown role", "role", "invalid_scope");
  auto grants = store.grants_of(principal);
  if (!grants) return grants.error();
  bool any = false;
  for (const auto& g : *grants) {
    if (!grant_covers_target(g, t)) continue;
    any = true;
    auto have = parse_scope(g.scope).value_or(std::vector<std::string>{});
    bool ok = std::all_of(want->begin(), want->end(), [&](const std::string& s) {
      return std::find(have.begin(), have.end(), s) != have.end();
    });
    if (!role.empty() && jwt::role_level(role) > jwt::role_level(g.role)) ok = false;
    if (!ok) continue;
    GrantChoice c{g, want->empty() ? have : *want, role.empty() ? g.role : role};
    return c;
  }
  if (!any)
    return Error(ErrorCode::kInsufficientPrivileges, "no grant for this principal and resource",
                 "resource", "unauthorized_client");
  return Error(ErrorCode::kInsufficientPrivileges,
               "the requested scope or role is beyond the grant", "scope", "invalid_scope");
}

HttpResponse RegistryApi::Impl::issue_token(const std::string& sub, const Target& t,
                                            const GrantChoice& c) {
  if (t.refused) return oauth_error(400, "invalid_target", t.refused->message);
  auto keys = authority_keys();
  if (!keys) return store_error(keys.error());
  int64_t now = now_ms();
  const SigningKeyRecord* signer = nullptr;
  for (const auto& k : *keys)
    if (k.sign_from_ms <= now) signer = &k;
  if (signer == nullptr) return store_error(Error(ErrorCode::kInternal, "no signing key"));
  auto seed = base64url_decode(signer->seed);
  if (!seed) return store_error(Error(ErrorCode::kInternal, "a stored key does not decode"));
  auto key = jwt::SigningKey::ed25519_seed(*seed);
  secure_wipe(seed->data(), seed->size());
  if (!key) return store_error(key.error());
  int64_t ttl = std::min<int64_t>(c.grant.max_ttl_s, o.max_token_ttl_s);
  if (ttl <= 0) ttl = o.max_token_ttl_s;
  int64_t iat = now / 1000;
  std::string jti = new_uuid_v4();
  json::Object claims;
  claims.set("iss", o.public_url);
  claims.set("sub", sub);
  claims.set("aud", t.aud);
  claims.set("role", c.role);
  json::Array scopes;
  std::string scope_text;
  for (const auto& s : c.scopes) {
    scopes.emplace_back(s);
    scope_text += (scope_text.empty() ? "" : " ") + s;
  }
  claims.set("scope", std::move(scopes));
  if (t.fleet.empty()) {
    claims.set("rrn", t.rrn);  // which robot, for revocation by its owner
  } else {
    json::Array members;
    for (const auto& m : split_words(c.grant.rrn)) members.emplace_back(m);
    claims.set("fleet", std::move(members));
  }
  claims.set("iat", iat);
  claims.set("exp", iat + ttl);
  claims.set("jti", jti);
  auto tok = jwt::issue(claims, *key, signer->kid);
  if (!tok) return store_error(tok.error());
  audit("REGISTRY_TOKEN_ISSUED", sub, t.aud,
        json::Object{{"jti", jti},
                     {"sub", sub},
                     {"aud", t.aud},
                     {"role", c.role},
                     {"scope", scope_text},
                     {"kid", signer->kid},
                     {"grant_id", c.grant.id}});
  HttpResponse r = json_response(200, json::Object{{"access_token", *tok},
                                                   {"token_type", "Bearer"},
                                                   {"expires_in", ttl},
                                                   {"scope", scope_text}});
  r.headers.emplace_back("Cache-Control", "no-store");
  r.headers.emplace_back("Pragma", "no-cache");
  return r;
}

std::vector<std::string> split_words(const std::string& s) {
  return parse_scope(s).value_or(std::vector<std::string>{});
}

}  // namespace rcan::registry::api
