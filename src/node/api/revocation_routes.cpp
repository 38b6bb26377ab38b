// Token revocation routes (docs/NODE.md, docs/SESSIONS.md): OWNER only.
//
//   GET  /rcan/v1/revocations   {"revocations":[…], "count", "capacity"}
//   POST /rcan/v1/revocations   one of {token} | {jti[, iss, exp]} | {sub[, iss]} | {kid[, iss]},
//                               optional "reason": 201 with the entry (200 when already in force)
//
// A revocation is in force once the list's file holds it (revocation.h); it is then recorded
// (TOKEN_REVOKED, with the kind and the jti/sub/kid — never the token itself), the open streams
// it names are closed, and the answer waits for the record.
#include "node/api/node.h"
#include "rcan/crypto/jwt.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

Error bad(const std::string& msg, const std::string& field) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field);
}

Result<std::string> field(const json::Value& body, const char* k) {
  const json::Value* v = body.get(k);
  if (!v || v->is_null()) return std::string();
  if (!v->is_string() || v->as_string().size() > RevocationList::kMaxFieldBytes)
    return bad(std::string(k) + " must be a string of at most 512 bytes", k);
  return v->as_string();
}

// The revocation a POST body asks for (who and when are the caller's to set).
Result<Revocation> requested(const json::Value& body) {
  Revocation r;
  int given = 0;
  for (const char* k : {"token", "jti", "sub", "kid"})
    if (const json::Value* v = body.get(k); v && !v->is_null()) ++given;
  if (given != 1) return bad("give exactly one of token, jti, sub or kid", "token");
  auto iss = field(body, "iss");
  if (!iss.ok()) return iss.error();
  r.iss = *iss;
  auto reason = field(body, "reason");
  if (!reason.ok()) return reason.error();
  r.reason = *reason;
  if (const json::Value* tok = body.get("token"); tok && !tok->is_null()) {
    if (!tok->is_string()) return bad("token must be a string", "token");
    // Decoded, not verified: the OWNER names a token to refuse, expired or foreign alike.
    auto d = jwt::decode(tok->as_string());
    if (!d.ok()) return bad("token is not a JWT: " + d.error().message, "token");
    const json::Value* jti = d->claims.find("jti");
    if (!jti || !jti->is_string() || jti->as_string().empty() ||
        jti->as_string().size() > RevocationList::kMaxFieldBytes)
      return bad("the token has no jti: revoke its subject instead ({sub, iss})", "token");
    r.kind = Revocation::Kind::kJti;
    r.value = jti->as_string();
    if (const json::Value* i = d->claims.find("iss"); i && i->is_string()) r.iss = i->as_string();
    if (const json::Value* e = d->claims.find("exp"); e && e->is_int()) r.exp = e->as_int();
    return r;
  }
  const char* key = body.get("jti") ? "jti" : body.get("sub") ? "sub" : "kid";
  auto value = field(body, key);
  if (!value.ok()) return value.error();
  if (value->empty()) return bad(std::string(key) + " must not be empty", key);
  r.value = *value;
  r.kind = key[0] == 'j'   ? Revocation::Kind::kJti
           : key[0] == 's' ? Revocation::Kind::kSubject
                           : Revocation::Kind::kKid;
  if (r.kind == Revocation::Kind::kJti) {
    if (const json::Value* e = body.get("exp"); e && !e->is_null()) {
      if (!e->is_int()) return bad("exp must be an integer (unix seconds)", "exp");
      r.exp = e->as_int();
    }
  }
  return r;
}

}  // namespace

// A revocation also ends the control session of the token it names, and drops its queued
// claim (ControlService::end_revoked, called by the node on every revocation).
void Node::add_revocation_routes() {
  const BodyLimits limits{.max_bytes = 0, .max_depth = 16};
  for (const char* method : {"GET", "POST"})
    routes_.add(
        method, "/rcan/v1/revocations", Body::kObjectOrEmpty,
        [this](RouteCall& c) { revocations_route(c.req, c.respond, c.body, c.route); }, limits);
}

void Node::revocations_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                             const std::string& route) {
  auto pr = route_principal(req, body, route, "REVOCATION_DENIED", Role::kOwner, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (req.method == "GET") {
    json::Array list;
    for (const Revocation& r : svc_.revocations.list()) list.push_back(r.to_json());
    const auto count = static_cast<int64_t>(list.size());
    return answer_json(
        respond, route, 200,
        json::Object{{"revocations", std::move(list)},
                     {"count", count},
                     {"capacity", static_cast<int64_t>(svc_.revocations.capacity())}});
  }
  auto r = requested(body);
  if (!r.ok()) return answer_error(respond, route, r.error());
  r->at_ms = svc_.clock.wall_ms();
  r->by = PrincipalId::of(*pr);
  json::Value entry = r->to_json();
  auto added = svc_.revocations.add(*r, r->at_ms / 1000);  // closes the streams it names
  if (!added.ok()) {
    svc_.trail.record("TOKEN_REVOKED", "failed")
        .by(*pr)
        .reason(added.error().reason.empty() ? std::string(error_name(added.error().code))
                                             : added.error().reason)
        .detail("kind", std::string(revocation_kind_name(r->kind)))
        .write();
    return answer_error(respond, route, added.error());
  }
  AuditRecord e = svc_.trail.record("TOKEN_REVOKED", *added ? "ok" : "unchanged");
  e.by(*pr)
      .detail("kind", std::string(revocation_kind_name(r->kind)))
      .detail(std::string(revocation_kind_name(r->kind)), r->value)
      .detail("iss", r->iss);
  if (r->exp) e.detail("exp", *r->exp);
  if (!r->reason.empty()) e.detail("reason", r->reason);
  const int status = *added ? 201 : 200;
  json::Object answer{{"revocation", std::move(entry)}, {"in_force", true}};
  if (!*added) answer.set("already", true);
  e.write([this, respond, route, status, answer](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, status, json::Value(std::move(answer)));
  });
}

}  // namespace rcan::node
