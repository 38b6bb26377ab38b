// The token authority's management routes: clients, grants, revocations, key rotation and the
// approval of device requests (docs/REGISTRY.md "Token authority").
#include <algorithm>
#include <chrono>

#include "base/clock.h"
#include "rcan/hash.h"
#include "registry/api/authority_internal.h"

namespace rcan::registry::api {
namespace {

HttpResponse bad_request(const std::string& msg, const std::string& field) {
  return project_error(ErrorCode::kSchemaValidationFailed, msg, field, "invalid");
}
HttpResponse forbidden(const std::string& msg) {
  return project_error(ErrorCode::kInsufficientPrivileges, msg, "authorization", "role");
}

json::Object client_json(const Client& c) {
  return json::Object{
      {"client_id", c.id}, {"name", c.name}, {"auth", c.auth}, {"created_at", c.created_at}};
}

json::Object grant_json(const Grant& g) {
  json::Array scope;
  for (const auto& s : split_words(g.scope)) scope.emplace_back(s);
  json::Object o{{"id", g.id},
                 {"principal", g.principal},
                 {"role", g.role},
                 {"scope", std::move(scope)},
                 {"max_ttl_s", g.max_ttl_s},
                 {"created_at", g.created_at}};
  if (g.fleet.empty()) {
    o.set("robot", g.rrn);
  } else {
    o.set("fleet", g.fleet);
    json::Array m;
    for (const auto& r : split_words(g.rrn)) m.emplace_back(r);
    o.set("robots", std::move(m));
  }
  return o;
}

bool valid_name(const std::string& s, size_t max) {
  if (s.empty() || s.size() > max) return false;
  for (char c : s)
    if (static_cast<unsigned char>(c) < 0x20) return false;
  return true;
}

}  // namespace

HttpResponse RegistryApi::Impl::clients_route(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (caller->is("robot")) return forbidden("a robot key cannot manage clients");
  if (req.method == "GET") {
    auto all = store.list_clients();
    if (!all) return store_error(all.error());
    json::Array out;
    for (const auto& c : *all)
      if (caller->is("admin") || c.owner_key_id == caller->key.id) out.emplace_back(client_json(c));
    return json_response(200, json::Object{{"clients", std::move(out)}});
  }
  if (auto l = limit_key(caller->key.id)) return *l;
  auto body = json::parse(req.body);
  if (!body || !body->is_object())
    return project_error(ErrorCode::kMalformedJson, "the body must be a JSON object");
  Client c;
  c.name = json::string_field(*body, "name");
  c.auth = json::string_field(*body, "auth");
  if (c.auth.empty()) c.auth = "client_secret";
  if (!valid_name(c.name, 128)) return bad_request("name: 1..128 characters", "name");
  std::string secret;
  if (c.auth == "client_secret") {
    c.salt = random_hex_id(16);
    secret = random_b64url(32);
    if (c.salt.empty() || secret.empty())
      return store_error(Error(ErrorCode::kInternal, "no randomness"));
    c.hash = sha256_hex(c.salt + secret);
  } else if (c.auth == "private_key_jwt") {
    const json::Value* jwk = body->get("jwk");
    if (jwk == nullptr || !jwk->is_object())
      return bad_request("private_key_jwt needs jwk (an Ed25519 public JWK)", "jwk");
    auto vk = jwt::VerificationKey::from_jwk(*jwk);
    if (!vk || vk->alg() != jwt::Alg::kEdDSA)
      return bad_request("jwk must be an Ed25519 public key (kty OKP, crv Ed25519)", "jwk");
    json::Object pub{{"kty", "OKP"}, {"crv", "Ed25519"}, {"x", json::string_field(*jwk, "x")}};
    c.jwk = json::dump(json::Value(std::move(pub)));
  } else if (c.auth != "none") {  // "none": a public client, for the device flow only
    return bad_request("auth must be client_secret, private_key_jwt or none", "auth");
  }
  if (auto a = audit_unavailable()) return *a;
  c.id = "rcc_" + random_hex_id(12);
  c.owner_key_id = caller->key.id;
  c.created_at = now();
  if (Status s = store.put_client(c); !s.ok()) return store_error(s.error());
  audit("REGISTRY_CLIENT_CREATED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"client_id", c.id}, {"name", c.name}, {"auth", c.auth}});
  json::Object out = client_json(c);
  if (!secret.empty()) {
    out.set("client_secret", secret);
    out.set("message", "Store this secret now: it is not shown again");
  }
  return json_response(201, out);
}

HttpResponse RegistryApi::Impl::delete_client(const HttpRequest& req, const std::string& id) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (auto l = limit_key(caller->key.id)) return *l;
  auto c = store.get_client(id);
  if (!c) return store_error(c.error());
  if (!*c) return project_error(ErrorCode::kNotFound, "no such client", "id", "not_found");
  if (!caller->is("admin") && (*c)->owner_key_id != caller->key.id)
    return forbidden("only an admin or the client's creator deletes it");
  if (auto a = audit_unavailable()) return *a;
  auto done = store.delete_client(id);
  if (!done) return store_error(done.error());
  audit("REGISTRY_CLIENT_DELETED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"client_id", id}});
  return json_response(200, json::Object{{"client_id", id}, {"deleted", true}});
}

HttpResponse RegistryApi::Impl::grants_route(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (req.method == "GET") {
    auto all = store.list_grants();
    if (!all) return store_error(all.error());
    json::Array out;
    for (const auto& g : *all)
      if (caller->is("admin") || g.created_by == "apikey:" + caller->key.id)
        out.emplace_back(grant_json(g));
    return json_response(200, json::Object{{"grants", std::move(out)}});
  }
  if (auto l = limit_key(caller->key.id)) return *l;
  auto body = json::parse(req.body);
  if (!body || !body->is_object())
    return project_error(ErrorCode::kMalformedJson, "the body must be a JSON object");
  Grant g;
  g.principal = json::string_field(*body, "principal");
  g.role = json::string_field(*body, "role");
  if (g.principal.rfind("user:", 0) == 0) {
    if (!valid_name(g.principal, 128)) return bad_request("principal: too long", "principal");
  } else {
    auto c = store.get_client(g.principal);
    if (!c) return store_error(c.error());
    if (!*c) return bad_request("principal must be a client id or user:<API key id>", "principal");
  }
  if (g.role != "guest" && g.role != "user" && g.role != "leasee" && g.role != "owner")
    return bad_request("role must be guest, user, leasee or owner", "role");
  const json::Value* scope = body->get("scope");
  if (scope != nullptr) {
    if (!scope->is_array()) return bad_request("scope must be an array of strings", "scope");
    for (const auto& s : scope->as_array()) {
      if (!s.is_string() || !parse_scope(s.as_string()) || split_words(s.as_string()).size() != 1)
        return bad_request("scope must be an array of scope tokens", "scope");
      g.scope += (g.scope.empty() ? "" : " ") + s.as_string();
    }
  }
  if (!parse_scope(g.scope)) return bad_request("too many scopes", "scope");
  g.max_ttl_s = o.max_token_ttl_s;
  if (const json::Value* t = body->get("max_ttl_s")) {
    if (!t->is_int() || t->as_int() < 1 || t->as_int() > o.max_token_ttl_s)
      return bad_request("max_ttl_s: 1.." + std::to_string(o.max_token_ttl_s), "max_ttl_s");
    g.max_ttl_s = t->as_int();
  }
  // The robots it covers; the caller must own each (or be an admin).
  std::vector<std::string> rrns;
  std::string robot = json::string_field(*body, "robot"),
              fleet = json::string_field(*body, "fleet");
  if (robot.empty() == fleet.empty()) return bad_request("give robot or fleet", "robot");
  if (!robot.empty()) {
    rrns.push_back(robot);
  } else {
    g.fleet = fleet;
    if (fleet.size() > 64 || slugify(fleet) != fleet)
      return bad_request("fleet: [a-z0-9-], at most 64", "fleet");
    const json::Value* members = body->get("robots");
    if (members == nullptr || !members->is_array() || members->as_array().empty() ||
        members->as_array().size() > 256)
      return bad_request("a fleet grant lists its robots (1..256 RRNs)", "robots");
    for (const auto& m : members->as_array()) {
      if (!m.is_string()) return bad_request("robots are RRNs", "robots");
      rrns.push_back(m.as_string());
    }
  }
  std::string members;
  for (const auto& r : rrns) {
    auto p = parse_rrn(r);
    if (!p) return bad_request("not an RRN: " + r.substr(0, 64), "robot");
    auto got = store.get_robot(p->rrn);
    if (!got) return store_error(got.error());
    if (!*got)
      return project_error(ErrorCode::kNotFound, "no robot " + p->rrn, "robot", "not_found");
    if (!caller->is("admin") && (*got)->owner_key_id != caller->key.id)
      return forbidden("only an admin or the robot's owner grants access to it");
    members += (members.empty() ? "" : " ") + p->rrn;
  }
  g.rrn = members;
  if (auto a = audit_unavailable()) return *a;
  g.created_by = "apikey:" + caller->key.id;
  g.created_at = now();
  auto id = store.add_grant(g);
  if (!id) return store_error(id.error());
  g.id = *id;
  audit("REGISTRY_GRANT_CREATED", g.created_by, registry_ruri(),
        json::Object{{"grant_id", g.id},
                     {"principal", g.principal},
                     {"robot", g.fleet.empty() ? g.rrn : ""},
                     {"fleet", g.fleet},
                     {"role", g.role},
                     {"scope", g.scope}});
  return json_response(201, grant_json(g));
}

HttpResponse RegistryApi::Impl::delete_grant(const HttpRequest& req, const std::string& raw) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (auto l = limit_key(caller->key.id)) return *l;
  int64_t id = 0;
  if (raw.empty() || raw.size() > 18 ||
      !std::all_of(raw.begin(), raw.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return project_error(ErrorCode::kNotFound, "no such grant", "id", "not_found");
  id = std::stoll(raw);
  auto g = store.get_grant(id);
  if (!g) return store_error(g.error());
  if (!*g) return project_error(ErrorCode::kNotFound, "no such grant", "id", "not_found");
  if (!caller->is("admin") && (*g)->created_by != "apikey:" + caller->key.id)
    return forbidden("only an admin or the grant's creator deletes it");
  if (auto a = audit_unavailable()) return *a;
  auto done = store.delete_grant(id);
  if (!done) return store_error(done.error());
  audit("REGISTRY_GRANT_DELETED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"grant_id", id}});
  return json_response(200, json::Object{{"id", id}, {"deleted", true}});
}

HttpResponse RegistryApi::Impl::list_revocations(const HttpRequest& req) {
  int64_t since = 0;
  std::string s(req.query_value("since"));
  if (!s.empty()) {
    if (s.size() > 18 ||
        !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
      return bad_request("since must be a sequence number", "since");
    since = std::stoll(s);
  }
  auto page = store.revocations_since(since, 500);
  if (!page) return store_error(page.error());
  json::Array out;
  int64_t next = since;
  for (const auto& r : *page) {
    out.emplace_back(json::Object{{"seq", r.seq},
                                  {"jti", r.jti.empty() ? json::Value() : json::Value(r.jti)},
                                  {"sub", r.sub.empty() ? json::Value() : json::Value(r.sub)},
                                  {"exp", r.exp ? json::Value(*r.exp) : json::Value()},
                                  {"revoked_at", r.revoked_at}});
    next = r.seq;
  }
  HttpResponse resp =
      json_response(200, json::Object{{"revocations", std::move(out)}, {"next_since", next}});
  resp.headers.emplace_back("Cache-Control", "no-cache");
  return resp;
}

HttpResponse RegistryApi::Impl::revoke(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (auto l = limit_key(caller->key.id)) return *l;
  auto body = json::parse(req.body);
  if (!body || !body->is_object())
    return project_error(ErrorCode::kMalformedJson, "the body must be a JSON object");
  Revocation r;
  r.jti = json::string_field(*body, "jti");
  r.sub = json::string_field(*body, "sub");
  r.reason = json::string_field(*body, "reason");
  std::string token = json::string_field(*body, "token");
  if (r.reason.size() > kMaxTextField) return bad_request("reason: too long", "reason");
  if (!caller->is("admin")) {
    // The owner of the robot a token was for presents the token itself: its signature and aud
    // show which robot it names.
    if (token.empty())
      return forbidden("revoking needs an admin key, or the token and its robot's owner key");
    auto d = jwt::decode(token);
    auto c = check_own_token(token);
    if (!d || !c) return bad_request("the token is not an active token of this registry", "token");
    bool owner = false;
    std::vector<std::string> rrns;
    if (const json::Value* v = c->raw.find("rrn"); v != nullptr && v->is_string())
      rrns.push_back(v->as_string());
    if (c->fleet) rrns.insert(rrns.end(), c->fleet->begin(), c->fleet->end());
    for (const auto& rrn : rrns) {
      auto t = resolve_target(rrn);
      owner = owner || (t.ok() && t->owner_key_id == caller->key.id);
    }
    if (!owner) return forbidden("only an admin or the robot's owner revokes its tokens");
    r.jti = c->jti;
    r.sub.clear();
    r.exp = c->exp;
  } else if (!token.empty()) {
    auto d = jwt::decode(token);
    if (!d) return bad_request("token does not decode", "token");
    const json::Value* j = d->claims.find("jti");
    const json::Value* e = d->claims.find("exp");
    if (j == nullptr || !j->is_string()) return bad_request("the token has no jti", "token");
    r.jti = j->as_string();
    if (e != nullptr && e->is_int()) r.exp = e->as_int();
  }
  if (r.jti.empty() && r.sub.empty()) return bad_request("give jti or sub", "jti");
  if (r.jti.size() > 256 || r.sub.size() > 256) return bad_request("jti/sub: too long", "jti");
  if (!caller->is("admin")) {
    const int64_t now_us = steady_us();
    if (int64_t wait = revoke_by_key.take(caller->key.id, now_us); wait > 0) {
      HttpResponse limited = project_error(
          ErrorCode::kRateLimited,
          "this key has revoked " + std::to_string(static_cast<int>(kRevocationBurstPerKey)) +
              " tokens lately: every robot that trusts the registry keeps each revocation, so a "
              "key gets one a minute after that (an admin revokes more, or by sub)",
          "revocations", "revocation_rate");
      limited.headers.emplace_back("Retry-After", std::to_string(wait));
      return limited;
    }
  }
  if (auto a = audit_unavailable()) return *a;
  r.revoked_ms = now_ms();
  r.revoked_at = iso_utc(r.revoked_ms);
  r.revoked_by = "apikey:" + caller->key.id;
  auto seq = store.add_revocation(r);
  if (!seq) return store_error(seq.error());
  // The feed's seq is "revocation_seq" in the record: the audit log reserves "seq" (with
  // prev_hash and hmac) for its own chain.
  audit(
      "REGISTRY_TOKEN_REVOKED", r.revoked_by, registry_ruri(),
      json::Object{{"revocation_seq", *seq}, {"jti", r.jti}, {"sub", r.sub}, {"reason", r.reason}});
  return json_response(201,
                       json::Object{{"seq", *seq},
                                    {"jti", r.jti.empty() ? json::Value() : json::Value(r.jti)},
                                    {"sub", r.sub.empty() ? json::Value() : json::Value(r.sub)},
                                    {"revoked_at", r.revoked_at}});
}

HttpResponse RegistryApi::Impl::rotate_keys(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (!caller->is("admin")) return forbidden("rotating the authority's keys needs an admin key");
  if (auto a = audit_unavailable()) return *a;
  auto before = authority_keys(true);
  if (!before) return store_error(before.error());
  auto k = new_signing_key(now_ms(), false);
  if (!k) return store_error(k.error());
  audit("REGISTRY_AUTHORITY_KEY_ROTATED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"kid", k->kid}});
  {
    std::lock_guard lock(keys_mu);
    keys_loaded_ms = -1;
  }
  return json_response(201, json::Object{{"kid", k->kid},
                                         {"published_at", iso_utc(k->created_ms)},
                                         {"signs_from", iso_utc(k->sign_from_ms)}});
}

Result<json::Object> RegistryApi::Impl::device_request(const std::string& user_code) {
  auto none = [] {
    return Error(ErrorCode::kNotFound, "no pending request with that code", "user_code",
                 "not_found");
  };
  const std::string code = normalize_user_code(user_code);
  if (code.empty()) return none();
  auto d = store.device_by_user_code(code);
  if (!d) return d.error();
  if (!*d || (*d)->expires_ms <= now_ms() || (*d)->status != "pending") return none();
  auto c = store.get_client((*d)->client_id);
  if (!c) return c.error();
  if (!*c) return none();
  json::Object client = client_json(**c);
  client.set("created_by", (*c)->owner_key_id);
  auto maker = store.get_api_key((*c)->owner_key_id);
  client.set("created_by_label", maker.ok() && *maker ? (*maker)->label : std::string());
  json::Object target{{"resource", (*d)->resource}};
  if (auto t = resolve_target((*d)->resource); t.ok()) {
    if (!t->fleet.empty()) {
      target.set("fleet", t->fleet);
    } else {
      target.set("rrn", t->rrn);
      target.set("owner_key_id", t->owner_key_id);
      if (auto r = store.get_robot(t->rrn); r.ok() && *r) {
        target.set("rcan_uri", (*r)->rcan_uri);
        target.set("description", (*r)->description);
      }
    }
  }
  return json::Object{{"user_code", code},
                      {"client", std::move(client)},
                      {"target", std::move(target)},
                      {"scope", (*d)->scope},
                      {"expires_in", ((*d)->expires_ms - now_ms() + 999) / 1000}};
}

HttpResponse RegistryApi::Impl::device_request_route(const HttpRequest& req,
                                                     const std::string& user_code) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  auto shown = device_request(user_code);
  if (!shown) return from_error(shown.error());
  auto d = store.device_by_user_code(normalize_user_code(user_code));
  if (!d || !*d) return from_error(Error(ErrorCode::kNotFound, "no pending request", "user_code"));
  auto t = resolve_target((*d)->resource);
  // The role and scopes the caller's approval would give; only who could approve sees it.
  auto c = t ? choose_grant("user:" + caller->key.id, *t, (*d)->scope, "")
             : Result<GrantChoice>(t.error());
  if (!c && !caller->is("admin"))
    return project_error(ErrorCode::kNotFound, "no pending request with that code", "user_code",
                         "not_found");
  if (c) {
    json::Array scopes;
    for (const auto& sc : c->scopes) scopes.emplace_back(sc);
    shown->set("your_grant", json::Object{{"role", c->role}, {"scopes", std::move(scopes)}});
  } else {
    shown->set("your_grant", json::Value());
  }
  return json_response(200, *shown);
}

HttpResponse RegistryApi::Impl::device_approve(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (auto l = limit_key(caller->key.id)) return *l;
  auto body = json::parse(req.body);
  if (!body || !body->is_object())
    return project_error(ErrorCode::kMalformedJson, "the body must be a JSON object");
  std::string code = normalize_user_code(json::string_field(*body, "user_code"));
  std::string decision = json::string_field(*body, "decision");
  if (code.empty()) return bad_request("user_code: 8 letters like BCDF-GHJK", "user_code");
  if (decision != "approve" && decision != "deny")
    return bad_request("decision must be approve or deny", "decision");
  auto d = store.device_by_user_code(code);
  if (!d) return store_error(d.error());
  if (!*d || (*d)->expires_ms <= now_ms() || (*d)->status != "pending")
    return project_error(ErrorCode::kNotFound, "no pending request with that code", "user_code",
                         "not_found");
  std::string subject = "user:" + caller->key.id;
  if (decision == "approve") {
    auto t = resolve_target((*d)->resource);
    if (!t) return from_error(t.error());
    auto c = choose_grant(subject, *t, (*d)->scope, "");
    if (!c) return forbidden("you hold no grant for this resource and scope: " + c.error().message);
  }
  if (auto a = audit_unavailable()) return *a;
  auto done = store.decide_device(code, decision == "approve" ? "approved" : "denied", subject);
  if (!done) return store_error(done.error());
  if (!*done)
    return project_error(ErrorCode::kNotFound, "no pending request with that code", "user_code",
                         "not_found");
  audit(decision == "approve" ? "REGISTRY_DEVICE_APPROVED" : "REGISTRY_DEVICE_DENIED", subject,
        registry_ruri(),
        json::Object{
            {"user_code", code}, {"client_id", (*d)->client_id}, {"resource", (*d)->resource}});
  return json_response(200, json::Object{{"user_code", code}, {"decision", decision}});
}

}  // namespace rcan::registry::api
