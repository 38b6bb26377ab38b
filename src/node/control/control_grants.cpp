// ControlService: what is granted for a time — leases, ownership transfer, consent requests.
#include <algorithm>
#include <utility>

#include "node/control/control_service.h"

namespace rcan::node {

json::Value ControlService::leases() { return sessions_.leases_json(clock_.wall_ms()); }

ControlAnswer ControlService::grant_lease(const Principal& owner, const PrincipalId& leasee,
                                          int64_t duration_s) {
  const int64_t now_wall = clock_.wall_ms();
  auto l = sessions_.grant_lease(owner, leasee, duration_s * 1000, now_wall, clock_.mono_ms());
  if (!l.ok()) return ControlAnswer::refused(l.error());
  ControlAnswer a;
  a.record.emplace(trail_.record("LEASE_GRANTED", "ok"))
      .by(owner)
      .message(l->id)
      .detail("lease_id", l->id)
      .detail("leasee", l->leasee.sub)
      .detail("leasee_iss", l->leasee.iss)
      .detail("end_ms", l->end_wall_ms);
  publish(json::Object{{"type", "EVENT"},
                       {"event", "LEASE_GRANTED"},
                       {"lease_id", l->id},
                       {"leasee", l->leasee.sub},
                       {"end_ms", l->end_wall_ms},
                       {"timestamp_ms", now_wall}});
  announce();
  a.status = 201;
  a.body = l->to_json(now_wall);
  return a;
}

ControlAnswer ControlService::grant_within_lease(const Principal& leasee,
                                                 const std::string& lease_id,
                                                 const PrincipalId& user, Role role,
                                                 int64_t duration_s) {
  const int64_t now_wall = clock_.wall_ms();
  auto l = sessions_.grant_within_lease(leasee, lease_id, user, role, duration_s * 1000, now_wall,
                                        clock_.mono_ms());
  if (!l.ok()) return ControlAnswer::refused(l.error());
  ControlAnswer a;
  a.record.emplace(trail_.record("LEASE_ACCESS_GRANTED", "ok"))
      .by(leasee)
      .message(lease_id)
      .detail("lease_id", lease_id)
      .detail("user_id", user.sub)
      .detail("role", std::string(role_name(role)));
  announce();
  a.body = l->to_json(now_wall);
  return a;
}

ControlAnswer ControlService::revoke_lease(const Principal& owner, const std::string& lease_id) {
  auto l = sessions_.revoke_lease(owner, lease_id, clock_.mono_ms(), clock_.wall_ms());
  if (!l.ok()) return ControlAnswer::refused(l.error());
  ControlAnswer a;
  a.record.emplace(trail_.record("LEASE_REVOKED", "ok"))
      .by(owner)
      .message(lease_id)
      .detail("lease_id", lease_id);
  announce();
  a.body = json::Object{{"lease_id", lease_id}, {"revoked", true}};
  return a;
}

// ---------------------------------------------------------------------------------------------
// Ownership transfer

json::Value ControlService::transfer_state(const Principal& p) {
  return ownership_.to_json(clock_.wall_ms(), role_level(p.role) >= role_level(Role::kOwner));
}

ControlAnswer ControlService::transfer(const Principal& p, const TransferRequest& r) {
  const int64_t now_wall = clock_.wall_ms();
  Result<PendingTransfer> t = Error(ErrorCode::kInternal, "unreachable");
  std::string event;
  if (r.action == "request") {
    t = ownership_.request(p, r.new_owner, r.note, now_wall);
    event = "TRANSFER_REQUEST";
  } else if (r.action == "accept") {
    t = ownership_.accept(p, r.transfer_id, r.agreement, now_wall);
    event = "TRANSFER_ACCEPT";
  } else if (r.action == "cancel") {
    t = ownership_.cancel(p, now_wall);
    event = "TRANSFER_CANCEL";
  } else {
    return ControlAnswer::refused(Error(ErrorCode::kSchemaValidationFailed,
                                        "action must be request, accept or cancel", "action"));
  }
  if (!t.ok()) {
    trail_.record("TRANSFER_DENIED", "blocked")
        .by(p)
        .reason(std::string(error_name(t.error().code)))
        .detail("action", r.action)
        .write();
    if (t.error().code == ErrorCode::kSessionExpired) tick();  // record the expiry now
    return ControlAnswer::refused(t.error());
  }
  ControlAnswer a;
  AuditRecord& e = a.record.emplace(trail_.record(event, "ok"));
  e.by(p)
      .message(t->id)
      .detail("transfer_id", t->id)
      .detail("from", t->from.sub)
      .detail("from_iss", t->from.iss)
      .detail("to", t->to.sub)
      .detail("to_iss", t->to.iss)
      .detail("expires_ms", t->expires_ms);
  if (r.action == "accept") {
    e.detail("agreement", r.agreement);
    // Personal data goes; the audit chain and skills stay.
    sessions_.revoke_all("ownership transferred to " + t->to.sub, clock_.mono_ms());
    consent_.clear();
    ownership_.run_clear_hooks();
    e.detail("cleared", json::Array{"sessions", "leases", "users", "consent", "thought_log"});
  }
  a.body = ownership_.to_json(now_wall, true);
  a.body.as_object().set("transfer_id", t->id);
  a.body.as_object().set("step", event);
  publish(json::Object{
      {"type", "EVENT"}, {"event", event}, {"transfer_id", t->id}, {"timestamp_ms", now_wall}});
  announce();
  return a;
}

// ---------------------------------------------------------------------------------------------
// Consent requests

json::Value ControlService::consent_requests() {
  consent_.expire(clock_.wall_ms());
  json::Array a;
  for (const auto& c : consent_.list()) a.push_back(c.to_json());
  return a;
}

ControlAnswer ControlService::request_consent(const Principal& p, ConsentRequest c,
                                              const std::string& message_id,
                                              ConsentRequest* added_out) {
  const int64_t now_wall = clock_.wall_ms();
  c.requester_sub = p.sub;
  c.requester_iss = p.issuer;
  auto added = consent_.add(std::move(c), now_wall);
  if (!added.ok()) return ControlAnswer::refused(added.error());
  json::Value note = consent_notification(*added, settings_.robot_name);
  ControlAnswer a;
  AuditRecord& e = a.record.emplace(trail_.record("CONSENT_REQUEST", "ok"));
  e.by(p).message(message_id);
  e.entry().sender_type = added->sender_type;
  if (!added->cloud_provider.empty()) e.entry().cloud_provider = added->cloud_provider;
  if (!added->function_name.empty()) e.entry().function_name = added->function_name;
  e.detail("consent_id", added->id);
  e.detail("scopes",
           added->to_json().get("scopes") ? *added->to_json().get("scopes") : json::Value());
  e.detail("notification", note);
  a.status = 202;
  a.body = added->to_json();
  a.body.as_object().set("notification", note);
  publish(json::Object{{"type", "EVENT"},
                       {"event", "CONSENT_REQUEST"},
                       {"consent_id", added->id},
                       {"notification", note},
                       {"timestamp_ms", now_wall}});
  if (added_out) *added_out = *added;
  save();
  return a;
}

ControlAnswer ControlService::decide_consent(const Principal& p, const std::string& id,
                                             const ConsentDecision& d) {
  const int64_t now_wall = clock_.wall_ms();
  auto pending = consent_.get(id);
  if (!pending.ok()) return ControlAnswer::refused(pending.error());
  std::string kind, lease_id;
  if (d.grant) {
    kind = d.kind.empty() ? "lease" : d.kind;
    int64_t dur = d.duration_s.value_or(pending->duration_s);
    if (dur < 0 || (kind != "lease" && kind != "grant"))
      return ControlAnswer::refused(Error(ErrorCode::kSchemaValidationFailed,
                                          "kind must be lease or grant; duration_s positive",
                                          "kind"));
    if (pending->status != "PENDING" || now_wall >= pending->expires_ms) {
      auto late = consent_.decide(id, true, p.sub, kind, "", now_wall);
      return ControlAnswer::refused(late.ok() ? Error(ErrorCode::kInternal, "unexpected")
                                              : late.error());
    }
    Result<Lease> l = Error(ErrorCode::kInternal, "unreachable");
    if (kind == "lease") {
      l = sessions_.grant_lease(p, pending->requester(), dur * 1000, now_wall, clock_.mono_ms());
    } else {
      bool control = std::find(pending->scopes.begin(), pending->scopes.end(), "control") !=
                     pending->scopes.end();
      auto running = sessions_.leases(now_wall);
      if (running.empty())
        return ControlAnswer::refused(Error(ErrorCode::kControlConflict,
                                            "kind grant needs a running lease; use kind lease",
                                            "kind"));
      l = sessions_.grant_within_lease(p, running.front().id, pending->requester(),
                                       control ? Role::kUser : Role::kGuest, dur * 1000, now_wall,
                                       clock_.mono_ms());
    }
    if (!l.ok()) return ControlAnswer::refused(l.error());
    lease_id = l->id;
  }
  auto decided = consent_.decide(id, d.grant, p.sub, kind, lease_id, now_wall);
  if (!decided.ok()) return ControlAnswer::refused(decided.error());
  const char* event = d.grant ? "CONSENT_GRANTED" : "CONSENT_DENIED";
  ControlAnswer a;
  AuditRecord& e = a.record.emplace(trail_.record(event, "ok"));
  e.by(p).message(id);
  e.entry().sender_type = "human";
  e.detail("consent_id", id);
  e.detail("requester", decided->requester_sub);
  e.detail("requester_sender_type", decided->sender_type);
  if (!decided->function_name.empty()) e.detail("requester_function", decided->function_name);
  if (!lease_id.empty()) e.detail("lease_id", lease_id);
  if (!d.reason.empty()) e.reason(d.reason);
  publish(json::Object{
      {"type", "EVENT"}, {"event", event}, {"consent_id", id}, {"timestamp_ms", now_wall}});
  announce();
  a.body = decided->to_json();
  return a;
}

}  // namespace rcan::node
