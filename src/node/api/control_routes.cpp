// Node routes for control sessions, leases, ownership transfer and consent requests
// (docs/SESSIONS.md): each authenticates through route_principal() — the role always comes
// from the verified token (lowered for former owners), a refusal is audited — parses its
// fields and hands them to ControlService (node/control/control_service.h), whose policy
// decides, audits and announces. The route answers once the step's record is durable.
#include "node/api/node.h"
#include "rcan/errors.h"
#include "runtime/http_client.h"

namespace rcan::node {
namespace {

std::string str_field(const json::Value& body, const char* k, size_t max = 256) {
  return json::string_field(body, k).substr(0, max);
}

// Seconds from the body: a positive integer, or `def` when absent. -1 when malformed.
int64_t seconds_field(const json::Value& body, const char* k, int64_t def) {
  const json::Value* f = body.is_object() ? body.get(k) : nullptr;
  if (!f) return def;
  if (!f->is_int() || f->as_int() <= 0 || f->as_int() > int64_t{366} * 86400) return -1;
  return f->as_int();
}

Error schema(const std::string& message, const std::string& field, const std::string& reason = {}) {
  return Error(ErrorCode::kSchemaValidationFailed, message, field, reason);
}

}  // namespace

Result<Principal> Node::route_principal(const transport::HttpRequest& req, const json::Value& body,
                                        const std::string& route, const std::string& denied_event,
                                        Role min_role, std::string_view scope) {
  std::string token(req.bearer());
  Result<Principal> pr =
      Error(ErrorCode::kAuthRequired, "a bearer token is required", "authorization");
  if (token.empty() && !req.header("authorization").empty()) {
    pr = Error(ErrorCode::kAuthInvalid, "the Authorization header must be 'Bearer <token>'",
               "authorization");
  } else {
    if (token.empty()) token = str_field(body, "auth_token", 16384);
    if (!token.empty()) pr = svc_.authenticate(token, RefusalLedger::source_of(req.remote_addr));
  }
  auto refuse_audit = [&](const Error& err, const Principal* p) {
    if (!p && !svc_.trail.record_refusal(RefusalLedger::source_of(req.remote_addr), denied_event,
                                         err.code, route))
      return;  // counted into a REFUSALS_SUMMARY record (refusal_ledger.h)
    AuditRecord e = svc_.trail.record(denied_event, "blocked");
    if (p) e.by(*p);
    e.reason(std::string(error_name(err.code)));
    e.detail("route", route);
    e.write();
  };
  if (!pr.ok()) {
    refuse_audit(pr.error(), nullptr);
    return pr.error();
  }
  Principal p = std::move(pr).value();
  if (role_level(p.role) < role_level(min_role) || (!scope.empty() && !p.has_scope(scope))) {
    Error err(ErrorCode::kInsufficientPrivileges,
              std::string(role_name(p.role)) + " may not use " + route + " (needs " +
                  std::string(role_name(min_role)) +
                  (scope.empty() ? std::string() : " and scope " + std::string(scope)) + ")",
              "role");
    refuse_audit(err, &p);
    return err;
  }
  return p;
}

void Node::answer_control(Respond& respond, const std::string& route, ControlAnswer a) {
  if (a.error) return answer_error(respond, route, *a.error);
  json::Value body =
      a.envelope ? svc_.envelope(*a.envelope, std::move(a.body.as_object())) : std::move(a.body);
  if (!a.record) return answer_json(respond, route, a.status, std::move(body));
  a.record->write([this, respond, route, status = a.status,
                   body = std::move(body)](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, status, std::move(body));
  });
}

void Node::control_start() {
  // Every change to timed control state wakes the control tick (Node::pump sleeps while there
  // is none); cleared again in shutdown().
  auto wake = [this] { wake_pump(); };
  svc_.trail.refusals.on_change(wake);
  ControlService& c = svc_.control;
  c.start(wake);
  svc_.metrics.add_gauge(
      "rcan_partition_mode", "0 NORMAL, 1 OFFLINE_AUTONOMOUS, 2 LOCKDOWN.",
      [&c] { return static_cast<double>(static_cast<int>(c.partition().mode())); });
  svc_.metrics.add_gauge("rcan_control_queue", "Claimants waiting for control.",
                         [&c] { return static_cast<double>(c.sessions().queue_size()); });
  svc_.metrics.add_gauge("rcan_leases_active", "Running leases.", [this, &c] {
    return static_cast<double>(c.sessions().leases(svc_.clock.wall_ms()).size());
  });
  svc_.metrics.add_gauge(
      "rcan_transfer_pending", "1 while an ownership transfer is pending.", [this, &c] {
        return c.ownership().state(svc_.clock.wall_ms()) == OwnershipState::kTransferPending ? 1.0
                                                                                             : 0.0;
      });
}

void Node::control_tick() {
  svc_.trail.flush_refusals();
  svc_.control.tick(streamless_claimants());
}

// ---------------------------------------------------------------------------------------------

// GET /rcan/v1/auth/queue: the control queue. DELETE: leave it.
void Node::queue_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route) {
  auto pr = route_principal(req, body, route, "QUEUE_DENIED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (req.method == "DELETE") return answer_control(respond, route, svc_.control.leave_queue(*pr));
  answer_json(respond, route, 200, json::Object{{"queue", svc_.control.queue()}});
}

void Node::claim_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route) {
  auto pr = route_principal(req, body, route, "CLAIM_DENIED", Role::kUser, "control");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  ClaimRequest r;
  if (const json::Value* role = body.get("role"); role && role->is_string()) {
    r.role = role_from_name(role->as_string());
    if (!r.role) return answer_error(respond, route, schema("unknown role", "role"));
  }
  r.fleet_id = str_field(body, "fleet_id");
  r.rearm = json::bool_field(body, "rearm");
  answer_control(respond, route, svc_.control.claim(*pr, r));
}

void Node::renew_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route) {
  auto pr = route_principal(req, body, route, "RENEW_DENIED", Role::kUser, "control");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  RenewRequest r;
  r.session_id = str_field(body, "session_id");
  if (r.session_id.empty()) r.session_id = std::string(req.header("x-rcan-session")).substr(0, 256);
  r.rearm = json::bool_field(body, "rearm");
  r.udp_heartbeat = json::bool_field(body, "udp_heartbeat");
  answer_control(respond, route, svc_.control.renew(*pr, r));
}

void Node::release_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                         const std::string& route) {
  auto pr = route_principal(req, body, route, "RELEASE_DENIED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  answer_control(respond, route, svc_.control.release(*pr, str_field(body, "session_id")));
}

void Node::handoff_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                         const std::string& route) {
  auto pr = route_principal(req, body, route, "HANDOFF_DENIED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  HandoffRequest r;
  r.session_id = str_field(body, "session_id");
  // The target is a principal: issuer and subject (the holder's issuer unless `target_iss`).
  r.target = PrincipalId{str_field(body, "target_iss"), str_field(body, "target_user_id")};
  if (r.session_id.empty() || r.target.sub.empty())
    return answer_error(
        respond, route,
        schema("session_id and target_user_id are required",
               r.session_id.empty() ? "session_id" : "target_user_id", "missing_field"));
  if (std::string role = str_field(body, "target_role"); !role.empty()) {
    r.target_role = role_from_name(role);
    if (!r.target_role) {
      json::Value err = svc_.error(schema("unknown target_role", "target_role"));
      err.as_object().set("valid_roles",
                          json::Array{"CREATOR", "OWNER", "LEASEE", "USER", "GUEST"});
      return answer_json(respond, route, 400, std::move(err));
    }
  }
  r.reason = str_field(body, "reason", 512);
  answer_control(respond, route, svc_.control.handoff(*pr, std::move(r)));
}

// Leases: GET /rcan/v1/leases, POST /rcan/v1/leases {leasee, duration_s},
// POST /rcan/v1/leases/<id>/grants {user_id, role, duration_s}, DELETE /rcan/v1/leases/<id>.
// The route table (routes.cpp) has checked the method for the path.
void Node::lease_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route, const std::string& lease_id, bool grants) {
  const bool listing = lease_id.empty() && req.method == "GET";
  const bool owner = !listing && !grants;  // granting or revoking a lease
  auto pr = route_principal(req, body, route, "LEASE_DENIED", owner ? Role::kOwner : Role::kLeasee,
                            owner ? "config" : "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (listing)
    return answer_json(respond, route, 200, json::Object{{"leases", svc_.control.leases()}});
  if (!lease_id.empty() && !grants)
    return answer_control(respond, route, svc_.control.revoke_lease(*pr, lease_id));
  if (!grants) {
    int64_t dur = seconds_field(body, "duration_s", 3600);
    if (dur < 0)
      return answer_error(respond, route,
                          schema("duration_s must be 1 s .. 366 days", "duration_s"));
    PrincipalId leasee{str_field(body, "leasee_iss"), str_field(body, "leasee")};
    return answer_control(respond, route, svc_.control.grant_lease(*pr, leasee, dur));
  }
  auto role = role_from_name(str_field(body, "role").empty() ? "user" : str_field(body, "role"));
  if (!role) return answer_error(respond, route, schema("unknown role", "role"));
  int64_t dur = seconds_field(body, "duration_s", 3600);
  if (dur < 0)
    return answer_error(respond, route, schema("duration_s must be positive", "duration_s"));
  PrincipalId user{str_field(body, "user_iss"), str_field(body, "user_id")};
  answer_control(respond, route, svc_.control.grant_within_lease(*pr, lease_id, user, *role, dur));
}

// GET /rcan/v1/transfer: the ownership state. POST {action: request|accept|cancel, …}.
void Node::transfer_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                          const std::string& route) {
  if (req.method == "GET") {
    auto pr = route_principal(req, body, route, "TRANSFER_DENIED", Role::kGuest, "");
    if (!pr.ok()) return answer_error(respond, route, pr.error());
    return answer_json(respond, route, 200, svc_.control.transfer_state(*pr));
  }
  TransferRequest r;
  r.action = str_field(body, "action");
  if (r.action != "request" && r.action != "accept" && r.action != "cancel")
    return answer_error(respond, route,
                        schema("action must be request, accept or cancel", "action"));
  const bool request = r.action == "request";
  auto pr = route_principal(req, body, route, "TRANSFER_DENIED",
                            request ? Role::kOwner : Role::kGuest, request ? "config" : "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  r.new_owner = PrincipalId{str_field(body, "new_owner_iss"), str_field(body, "new_owner")};
  r.note = str_field(body, "note", 512);
  r.transfer_id = str_field(body, "transfer_id");
  r.agreement = str_field(body, "agreement", 512);
  answer_control(respond, route, svc_.control.transfer(*pr, r));
}

// GET /rcan/v1/consent: the pending requests (OWNER).
void Node::consent_list_route(transport::HttpRequest& req, Respond& respond,
                              const json::Value& body, const std::string& route) {
  auto pr = route_principal(req, body, route, "CONSENT_REFUSED", Role::kOwner, "config");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  answer_json(respond, route, 200, json::Object{{"requests", svc_.control.consent_requests()}});
}

// POST /rcan/v1/consent: a CONSENT_REQUEST message (its envelope filled in when missing),
// verified as any message is; recorded (202) and notified to the owner.
void Node::consent_request_route(transport::HttpRequest& req, Respond& respond,
                                 const json::Value& body, const std::string& route) {
  auto pr = route_principal(req, body, route, "CONSENT_REFUSED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  json::Value msg_body = body;
  json::Object& o = msg_body.as_object();
  if (!o.find("type")) o.set("type", "CONSENT_REQUEST");
  if (!o.find("version")) o.set("version", svc_.settings.rcan_version);
  if (!o.find("message_id")) o.set("message_id", new_uuid_v4());
  if (!o.find("timestamp_ms")) o.set("timestamp_ms", svc_.clock.wall_ms());
  if (!o.find("payload")) o.set("payload", json::Object{});
  auto refused = [&](const Error& err) {
    AuditRecord e = svc_.trail.record("CONSENT_REFUSED", "blocked");
    e.by(*pr).reason(std::string(error_name(err.code)));
    if (!err.field.empty()) e.detail("field", err.field.substr(0, 128));
    e.write();
    answer_error(respond, route, err);
  };
  auto msg = decode_message(msg_body, svc_.settings.codec);
  if (!msg.ok()) return refused(msg.error());
  if (msg->type != MessageType::kConsentRequest)
    return refused(schema("type must be CONSENT_REQUEST", "type"));
  auto sig = svc_.auth.check_signature(*msg, *pr);
  if (!sig.ok()) return refused(sig.error());
  auto sender = svc_.auth.sender(*msg, *pr, *sig);
  if (!sender.ok()) return refused(sender.error());
  ConsentRequest c;
  c.sender_type = std::string(sender_type_name(sender->sender_type));
  c.cloud_provider = sender->cloud_provider;
  c.function_name = sender->function_name;
  auto pstr = [&](const char* k, size_t max) {
    const json::Value* f = msg->payload.find(k);
    return f && f->is_string() ? f->as_string().substr(0, max) : std::string();
  };
  c.on_behalf_of = pstr("on_behalf_of", 128);
  c.reason = pstr("reason", 512);
  if (const json::Value* s = msg->payload.find("scopes"); s && s->is_array()) {
    for (const auto& x : s->as_array()) {
      if (!x.is_string() || !scope_min_role(x.as_string()))
        return answer_error(respond, route, schema("unknown scope", "payload.scopes"));
      if (c.scopes.size() < 16) c.scopes.push_back(x.as_string());
    }
  }
  if (c.scopes.empty())
    return answer_error(respond, route,
                        schema("payload.scopes is required", "payload.scopes", "missing_field"));
  if (const json::Value* d = msg->payload.find("duration_s")) {
    if (!d->is_int() || d->as_int() <= 0 || d->as_int() > 366 * 86400)
      return answer_error(respond, route,
                          schema("duration_s must be positive", "payload.duration_s"));
    c.duration_s = d->as_int();
  }
  ConsentRequest added;
  ControlAnswer a = svc_.control.request_consent(*pr, std::move(c), msg->message_id, &added);
  const bool notify = !a.error && !svc_.settings.consent_webhook.empty();
  json::Value note = notify ? *a.body.get("notification") : json::Value();
  answer_control(respond, route, std::move(a));
  if (notify) notify_consent_webhook(added, note);
}

void Node::notify_consent_webhook(const ConsentRequest& c, const json::Value& note) {
  std::string url = svc_.settings.consent_webhook;
  std::string text = json::dump(note);
  std::string cid = c.id;
  worker_.post([this, url, text, cid] {
    auto r = http_request("POST", url, text, 2000);
    AuditRecord we =
        svc_.trail.record("CONSENT_NOTIFIED", r.ok() && r->status < 300 ? "ok" : "error");
    we.by_system().message(cid).detail("consent_id", cid);
    we.detail("webhook_status",
              r.ok() ? json::Value(static_cast<int64_t>(r->status)) : json::Value());
    if (!r.ok()) we.reason(r.error().message);
    we.write();
  });
}

// POST /rcan/v1/consent/<id>/grant {kind: lease|grant, duration_s} or /<id>/deny {reason}
// (OWNER).
void Node::consent_decision_route(transport::HttpRequest& req, Respond& respond,
                                  const json::Value& body, const std::string& route,
                                  const std::string& id, const std::string& verb) {
  auto pr = route_principal(req, body, route, "CONSENT_REFUSED", Role::kOwner, "config");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  ConsentDecision d;
  d.grant = verb == "grant";
  d.kind = str_field(body, "kind");
  if (body.is_object() && body.get("duration_s"))
    d.duration_s = seconds_field(body, "duration_s", 0);
  d.reason = str_field(body, "reason", 512);
  answer_control(respond, route, svc_.control.decide_consent(*pr, id, d));
}

}  // namespace rcan::node
