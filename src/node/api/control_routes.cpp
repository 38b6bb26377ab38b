// Node routes for control sessions, leases, ownership transfer and consent requests, and the
// control tick that announces expiries, promotions and revocations (docs/SESSIONS.md).
// Every route authenticates through route_principal(): the role always comes from the
// verified token (lowered for former owners), and every refusal and every step is audited.
#include <algorithm>

#include "node/api/node.h"
#include "rcan/errors.h"
#include "runtime/http_client.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

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

json::Array capabilities_of(Role r, const RolePolicy& policy) {
  json::Array caps;
  for (int i = 0; i < kCapabilityCount; ++i) {
    auto cap = static_cast<Capability>(i);
    if (role_allows(r, cap, policy)) caps.emplace_back(std::string(capability_name(cap)));
  }
  return caps;
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
    if (!p && !svc_.record_refusal(RefusalLedger::source_of(req.remote_addr), denied_event,
                                   err.code, route))
      return;  // counted into a REFUSALS_SUMMARY record (refusal_ledger.h)
    AuditRecord e = svc_.record(denied_event, "blocked");
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

void Node::publish_to(const std::string& principal_key, json::Object ev) {
  svc_.events.publish(json::Value(std::move(ev)), Audience::principal(principal_key));
}

void Node::control_start() {
  // Every change to timed control state wakes the control tick (Node::pump sleeps while there
  // is none); cleared again in shutdown().
  auto wake = [this] { wake_pump(); };
  svc_.sessions.on_change(wake);
  svc_.ownership.on_change(wake);
  svc_.consent.on_change(wake);
  svc_.refusals.on_change(wake);
  if (!svc_.settings.state_dir.empty()) {
    int64_t now = svc_.clock.wall_ms();
    if (auto v = read_state_file(svc_.settings.state_dir + "/leases.json"); v.ok())
      svc_.sessions.load_json(*v, now);
    if (auto v = read_state_file(svc_.settings.state_dir + "/ownership.json"); v.ok())
      svc_.ownership.load_json(*v);
    if (auto v = read_state_file(svc_.settings.state_dir + "/consent.json"); v.ok())
      svc_.consent.load_json(*v);
    if (auto v = read_state_file(svc_.settings.state_dir + "/credentials.json"); v.ok())
      svc_.partition.load_json(*v, now);
  }
  svc_.metrics.add_gauge(
      "rcan_partition_mode", "0 NORMAL, 1 OFFLINE_AUTONOMOUS, 2 LOCKDOWN.",
      [this] { return static_cast<double>(static_cast<int>(svc_.partition.mode())); });
  svc_.metrics.add_gauge("rcan_control_queue", "Claimants waiting for control.",
                         [this] { return static_cast<double>(svc_.sessions.queue_size()); });
  svc_.metrics.add_gauge("rcan_leases_active", "Running leases.", [this] {
    return static_cast<double>(svc_.sessions.leases(svc_.clock.wall_ms()).size());
  });
  svc_.metrics.add_gauge(
      "rcan_transfer_pending", "1 while an ownership transfer is pending.", [this] {
        return svc_.ownership.state(svc_.clock.wall_ms()) == OwnershipState::kTransferPending ? 1.0
                                                                                              : 0.0;
      });
  svc_.partition.start(
      [this] { return svc_.clock.wall_ms(); },
      [this](NetMode old, NetMode now) {
        svc_.record("PARTITION_MODE", "ok")
            .by_system()
            .reason(std::string(net_mode_name(now)))
            .detail("from", std::string(net_mode_name(old)))
            .detail("to", std::string(net_mode_name(now)))
            .write();
        svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                                     {"event", "PARTITION_MODE"},
                                                     {"mode", std::string(net_mode_name(now))},
                                                     {"from", std::string(net_mode_name(old))},
                                                     {"timestamp_ms", svc_.clock.wall_ms()}}));
        save_control_state();
      });
  MutexLock lock(control_mu_);
  last_control_state_ = std::string(control_state_name(svc_.sessions.state(svc_.clock.mono_ms())));
}

void Node::save_control_state() {
  if (svc_.settings.state_dir.empty()) return;
  MutexLock lock(save_mu_);
  uint64_t v[4] = {svc_.sessions.version(), svc_.ownership.version(), svc_.consent.version(),
                   svc_.partition.version()};
  const char* names[4] = {"leases.json", "ownership.json", "consent.json", "credentials.json"};
  for (int i = 0; i < 4; ++i) {
    if (v[i] == saved_versions_[i]) continue;
    json::Value doc = i == 0   ? svc_.sessions.persist_json()
                      : i == 1 ? svc_.ownership.persist_json()
                      : i == 2 ? svc_.consent.persist_json()
                               : svc_.partition.persist_json();
    Status s = write_state_file(svc_.settings.state_dir + "/" + names[i], doc);
    if (s.ok())
      saved_versions_[i] = v[i];
    else
      log(LogLevel::kError, "state_write_failed",
          json::Object{{"file", names[i]}, {"error", s.error().message}});
  }
}

void Node::control_tick() {
  int64_t now_wall = svc_.clock.wall_ms();
  svc_.flush_refusals();
  svc_.sessions.tick(svc_.clock.mono_ms(), now_wall);
  if (auto t = svc_.ownership.expire(now_wall)) {
    svc_.record("TRANSFER_EXPIRED", "ok")
        .by_system()
        .detail("transfer_id", t->id)
        .detail("from", t->from.sub)
        .detail("to", t->to.sub)
        .detail("to_iss", t->to.iss)
        .write();
    svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                                 {"event", "TRANSFER_EXPIRED"},
                                                 {"transfer_id", t->id},
                                                 {"timestamp_ms", now_wall}}));
  }
  for (const auto& c : svc_.consent.expire(now_wall)) {
    svc_.record("CONSENT_EXPIRED", "ok")
        .by_system()
        .detail("consent_id", c.id)
        .detail("requester", c.requester_sub)
        .write();
  }
  drop_streamless_claims();
  announce_control_changes();
}

void Node::announce_control_changes() {
  for (auto& c : svc_.sessions.take_changes()) {
    const Session& s = c.session;
    AuditRecord e = svc_.record("", "ok");
    e.by_system().message(s.id);
    if (!s.sub.empty()) e.entry().sub = s.sub;
    if (!c.reason.empty()) e.reason(c.reason);
    json::Object ev{{"type", "EVENT"}, {"timestamp_ms", svc_.clock.wall_ms()}};
    if (c.event == ControlEvent::kExpire || c.event == ControlEvent::kRevoke) {
      svc_.act.disarm_deadman(s.id);
      svc_.act.stop("control session " + s.id + " ended");
      e.entry().event = c.event == ControlEvent::kExpire ? "SESSION_EXPIRED" : "SESSION_REVOKED";
      e.detail("role", std::string(role_name(s.role)));
      if (!c.lease_id.empty()) e.detail("lease_id", c.lease_id);
      ev.set("event", e.entry().event);
      ev.set("session_id", s.id);
      ev.set("reason", c.reason);
      publish_to(s.principal_key, std::move(ev));
    } else if (c.event == ControlEvent::kPromote) {
      svc_.act.arm_deadman(s.id, svc_.settings.heartbeat_timeout_ms);
      e.entry().event = "CLAIM_PROMOTED";
      e.detail("role", std::string(role_name(s.role)));
      ev.set("type", "GRANTED");
      ev.set("event", "PROMOTED");
      ev.set("session_id", s.id);
      ev.set("role", std::string(role_name(s.role)));
      ev.set("capabilities", capabilities_of(s.role, svc_.settings.role_policy));
      ev.set("expires_in", s.expires_mono_ms
                               ? json::Value((s.expires_mono_ms - svc_.clock.mono_ms()) / 1000)
                               : json::Value());
      ev.set("heartbeat_timeout_ms", svc_.settings.heartbeat_timeout_ms);
      // Secrets never travel in events: what a direct grant carries (the UDP heartbeat key) the
      // promoted holder fetches itself, authenticated, by renewing its session with
      // {"session_id", "udp_heartbeat": true} (renew_route).
      if (svc_.on_grant) ev.set("udp_heartbeat_on_renew", true);
      publish_to(s.principal_key, std::move(ev));
    } else if (c.event == ControlEvent::kQueueDrop) {
      e.entry().event = "CLAIM_DROPPED";
      e.entry().sub = c.queued.sub;
      ev.set("event", "CLAIM_DROPPED");
      ev.set("reason", c.reason);
      publish_to(c.queued.principal_key, std::move(ev));
    } else if (c.event == ControlEvent::kWindowClose) {
      e.entry().event = "HANDOFF_WINDOW_CLOSED";
    } else if (c.event == ControlEvent::kLeaseEnd) {
      e.entry().event = "LEASE_ENDED";
      e.detail("lease_id", c.lease_id);
      ev.set("event", "LEASE_ENDED");
      ev.set("lease_id", c.lease_id);
      ev.set("reason", c.reason);
      svc_.events.publish(json::Value(std::move(ev)));
    } else {
      continue;
    }
    e.write();
  }
  // The "control state changed" event (streams, and whatever else subscribes: mDNS status).
  std::string now_state(control_state_name(svc_.sessions.state(svc_.clock.mono_ms())));
  bool changed = false;
  {
    MutexLock lock(control_mu_);
    if (now_state != last_control_state_) {
      last_control_state_ = now_state;
      changed = true;
    }
  }
  if (changed) {
    json::Object ev{{"type", "EVENT"},
                    {"event", "CONTROL_STATE"},
                    {"state", now_state},
                    {"timestamp_ms", svc_.clock.wall_ms()}};
    if (now_state == "AVAILABLE") ev.set("window_ms", svc_.settings.handoff_window_ms);
    svc_.events.publish(json::Value(std::move(ev)));
  }
  save_control_state();
}

// ---------------------------------------------------------------------------------------------

// GET /rcan/v1/auth/queue: the control queue. DELETE: leave it.
void Node::queue_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route) {
  const std::string& m = req.method;
  auto pr = route_principal(req, body, route, "QUEUE_DENIED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (m == "DELETE") {
    bool left = svc_.sessions.leave_queue(*pr);
    if (left) {
      svc_.record("CLAIM_WITHDRAWN", "ok").by(*pr).write();
    }
    answer_json(respond, route, left ? 200 : 404,
                left ? json::Value(json::Object{{"left", true}})
                     : svc_.error(Error(ErrorCode::kNotFound, "not in the control queue")));
  } else {
    answer_json(respond, route, 200,
                json::Object{{"queue", svc_.sessions.queue_json(svc_.clock.mono_ms())}});
  }
}

void Node::claim_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route) {
  auto pr = route_principal(req, body, route, "CLAIM_DENIED", Role::kUser, "control");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  std::optional<Role> requested;
  if (const json::Value* r = body.get("role"); r && r->is_string()) {
    requested = role_from_name(r->as_string());
    if (!requested)
      return answer_error(respond, route,
                          Error(ErrorCode::kSchemaValidationFailed, "unknown role", "role"));
  }
  bool fleet = !str_field(body, "fleet_id").empty();
  int64_t now_mono = svc_.clock.mono_ms(), now_wall = svc_.clock.wall_ms();
  auto deny = [&](const Error& err, const std::string& reason) {
    svc_.record("CLAIM_DENIED", "blocked")
        .by(*pr)
        .reason(reason)
        .detail("error", err.message)
        .write();
    answer_error(respond, route, err);
  };
  // Network partition: no new sessions in LOCKDOWN; offline, only principals validated while
  // the issuer was reachable. A holder renewing its own session is not a new session.
  auto holder = svc_.sessions.controller(now_mono);
  bool renewal = holder && holder->principal_key == pr->key();
  NetMode mode = svc_.partition.mode();
  if (!renewal && mode == NetMode::kLockdown)
    return deny(Error(ErrorCode::kLockdown,
                      "LOCKDOWN: the token issuer is unreachable and the credential cache has "
                      "expired; no new sessions"),
                "LOCKDOWN");
  if (!renewal && mode == NetMode::kOfflineAutonomous && !svc_.partition.cached(*pr, now_wall))
    return deny(Error(ErrorCode::kLockdown,
                      "OFFLINE_AUTONOMOUS: this principal is not in the credential cache; "
                      "new principals cannot be authenticated while the issuer is unreachable"),
                "OFFLINE_UNCACHED");
  if (mode == NetMode::kNormal) svc_.partition.note_validated(*pr, now_wall);
  svc_.ownership.note_user(pr->sub);
  auto c = svc_.sessions.claim(*pr, requested, fleet, now_mono, now_wall);
  if (!c.ok()) {
    deny(c.error(), "CONTROL_CONFLICT");
    return announce_control_changes();
  }
  if (c->outcome == ClaimOutcome::kQueued) {
    svc_.record("CLAIM_QUEUED", "blocked")
        .by(*pr)
        .reason("CONTROL_CONFLICT")
        .detail("queue_position", static_cast<int64_t>(c->queue_position))
        .write();
    json::Value err =
        svc_.error(Error(ErrorCode::kControlConflict,
                         "the robot is controlled by another principal of the same role; you are "
                         "number " +
                             std::to_string(c->queue_position) + " in the queue",
                         "session", "queued"));
    err.as_object().find("payload")->as_object().set("queue_position",
                                                     static_cast<int64_t>(c->queue_position));
    err.as_object().find("payload")->as_object().set("queued", true);
    answer_json(respond, route, 409, std::move(err));
    return announce_control_changes();
  }
  if (c->preempted) {
    // The displaced holder loses control now: its motion stops, its in-flight commands are
    // dropped at dispatch (their session is gone), and it is told on its stream.
    svc_.act.disarm_deadman(c->preempted->id);
    svc_.act.stop("pre-empted by " + pr->display());
    publish_to(c->preempted->principal_key,
               json::Object{{"type", "EVENT"},
                            {"event", "PREEMPTED"},
                            {"session_id", c->preempted->id},
                            {"by_role", std::string(role_name(c->session.role))},
                            {"timestamp_ms", now_wall}});
    AuditRecord pe = svc_.record("SESSION_PREEMPTED", "ok");
    pe.by(*pr).message(c->preempted->id);
    pe.entry().sub = c->preempted->sub;
    pe.detail("by", pr->sub);
    pe.detail("by_role", std::string(role_name(c->session.role)));
    pe.detail("role", std::string(role_name(c->preempted->role)));
    pe.write();
  }
  svc_.act.arm_deadman(c->session.id, svc_.settings.heartbeat_timeout_ms);
  bool renewed = c->outcome == ClaimOutcome::kRenewed;
  AuditRecord e = svc_.record(renewed ? "CLAIM_RENEWED" : "CLAIM", "ok");
  e.by(*pr).message(c->session.id);
  // A new session is armed; a renewing claim keeps its arming unless it asks (docs/NODE.md,
  // "Re-arm after ESTOP").
  const bool rearmed = json::bool_field(body, "rearm") && svc_.act.rearm(c->session.id).ok();
  if (rearmed) e.detail("rearmed", true);
  if (c->preempted) e.detail("preempted_session", c->preempted->id);
  if (!c->session.lease_id.empty()) e.detail("lease_id", c->session.lease_id);
  if (fleet) e.detail("fleet_id", str_field(body, "fleet_id"));
  json::Object payload{
      {"session_id", c->session.id},
      {"role", std::string(role_name(c->session.role))},
      {"capabilities", capabilities_of(c->session.role, svc_.settings.role_policy)},
      {"heartbeat_timeout_ms", svc_.settings.heartbeat_timeout_ms},
      {"renewed", renewed}};
  if (rearmed) payload.set("rearmed", true);
  if (c->session.expires_mono_ms)
    payload.set("expires_in", (c->session.expires_mono_ms - now_mono) / 1000);
  else
    payload.set("expires_in", json::Value());
  if (!c->session.lease_id.empty()) payload.set("lease_id", c->session.lease_id);
  if (svc_.on_grant)
    svc_.on_grant(c->session.id, payload);  // e.g. udp_heartbeat (src/node/bindings/udp_service.h)
  announce_control_changes();
  e.write([this, respond, route, payload](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 200, svc_.envelope(MessageType::kGranted, payload));
  });
}

void Node::renew_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route) {
  auto pr = route_principal(req, body, route, "RENEW_DENIED", Role::kUser, "control");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  std::string session_id = str_field(body, "session_id");
  if (session_id.empty()) session_id = std::string(req.header("x-rcan-session")).substr(0, 256);
  if (session_id.empty())
    return answer_error(respond, route,
                        Error(ErrorCode::kSchemaValidationFailed, "session_id is required",
                              "session_id", "missing_field"));
  auto r = svc_.sessions.renew(session_id, *pr, svc_.clock.mono_ms(), svc_.clock.wall_ms());
  if (!r.ok()) {
    svc_.record("RENEW_DENIED", "blocked")
        .by(*pr)
        .message(session_id)
        .reason(std::string(error_name(r.error().code)))
        .write();
    announce_control_changes();
    return answer_error(respond, route, r.error());
  }
  svc_.act.feed_deadman(r->id);
  AuditRecord e = svc_.record("CLAIM_RENEWED", "ok");
  e.by(*pr).message(r->id);
  json::Object payload{
      {"session_id", r->id}, {"role", std::string(role_name(r->role))}, {"renewed", true}};
  if (json::bool_field(body, "rearm") && svc_.act.rearm(r->id).ok()) {  // docs/NODE.md, "Re-arm"
    e.detail("rearmed", true);
    payload.set("rearmed", true);
  }
  payload.set("expires_in", r->expires_mono_ms
                                ? json::Value((r->expires_mono_ms - svc_.clock.mono_ms()) / 1000)
                                : json::Value());
  // The holder asks for its session's UDP heartbeat key (a fresh one; the previous key stops
  // working): how a holder promoted from the queue gets it, since events carry no secrets.
  if (json::bool_field(body, "udp_heartbeat") && svc_.on_grant) {
    svc_.on_grant(r->id, payload);
    e.detail("udp_heartbeat", "issued");
  }
  e.write([this, respond, route, payload](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 200, svc_.envelope(MessageType::kGranted, payload));
  });
}

void Node::release_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                         const std::string& route) {
  auto pr = route_principal(req, body, route, "RELEASE_DENIED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  std::string session_id = str_field(body, "session_id");
  if (session_id.empty()) {
    auto holder = svc_.sessions.controller(svc_.clock.mono_ms());
    if (holder && holder->principal_key == pr->key()) session_id = holder->id;
  }
  if (session_id.empty())
    return answer_error(respond, route,
                        Error(ErrorCode::kSchemaValidationFailed, "session_id is required",
                              "session_id", "missing_field"));
  auto r = svc_.sessions.release(session_id, *pr, svc_.clock.mono_ms(), svc_.clock.wall_ms());
  if (!r.ok()) return answer_error(respond, route, r.error());
  svc_.act.disarm_deadman(session_id);
  svc_.record("RELEASE", "ok").by(*pr).message(session_id).write();
  if (svc_.sessions.state(svc_.clock.mono_ms()) == ControlState::kAvailable)
    svc_.events.publish(json::Value(json::Object{{"type", "AVAILABLE"},
                                                 {"released_session", session_id},
                                                 {"window_ms", svc_.settings.handoff_window_ms},
                                                 {"timestamp_ms", svc_.clock.wall_ms()}}));
  announce_control_changes();
  answer_json(respond, route, 200,
              svc_.envelope(MessageType::kReleased, json::Object{{"session_id", session_id}}));
}

void Node::handoff_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                         const std::string& route) {
  auto pr = route_principal(req, body, route, "HANDOFF_DENIED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  std::string session_id = str_field(body, "session_id");
  std::string target = str_field(body, "target_user_id");
  // The target is a principal: issuer and subject (the holder's issuer unless `target_iss`).
  PrincipalId target_id{str_field(body, "target_iss"), target};
  if (target_id.iss.empty()) target_id.iss = pr->issuer;
  if (session_id.empty() || target.empty())
    return answer_error(
        respond, route,
        Error(ErrorCode::kSchemaValidationFailed, "session_id and target_user_id are required",
              session_id.empty() ? "session_id" : "target_user_id", "missing_field"));
  std::optional<Role> target_role;
  if (std::string r = str_field(body, "target_role"); !r.empty()) {
    target_role = role_from_name(r);
    if (!target_role) {
      json::Value err = svc_.error(
          Error(ErrorCode::kSchemaValidationFailed, "unknown target_role", "target_role"));
      err.as_object().set("valid_roles",
                          json::Array{"CREATOR", "OWNER", "LEASEE", "USER", "GUEST"});
      return answer_json(respond, route, 400, std::move(err));
    }
  }
  int64_t window = svc_.settings.handoff_window_ms;
  auto r =
      svc_.sessions.handoff(session_id, *pr, target_id, target_role, window, svc_.clock.mono_ms());
  if (!r.ok()) return answer_error(respond, route, r.error());
  svc_.act.disarm_deadman(session_id);
  svc_.events.publish(json::Value(json::Object{{"type", "AVAILABLE"},
                                               {"released_session", session_id},
                                               {"reserved_for", target},
                                               {"window_ms", window},
                                               {"timestamp_ms", svc_.clock.wall_ms()}}));
  AuditRecord e = svc_.record("HANDOFF", "ok");
  e.by(*pr)
      .message(session_id)
      .detail("target_user_id", target)
      .detail("target_iss", target_id.iss);
  if (target_role) e.detail("target_role", std::string(role_name(*target_role)));
  if (std::string reason = str_field(body, "reason", 512); !reason.empty()) e.reason(reason);
  announce_control_changes();
  json::Object payload{
      {"session_id", session_id}, {"target_user_id", target}, {"window_ms", window}};
  e.write([this, respond, route, payload](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 200, svc_.envelope(MessageType::kAvailable, payload));
  });
}

// Leases: GET /rcan/v1/leases, POST /rcan/v1/leases {leasee, duration_s},
// POST /rcan/v1/leases/<id>/grants {user_id, role, duration_s}, DELETE /rcan/v1/leases/<id>.
// The route table (routes.cpp) has checked the method for the path.
void Node::lease_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                       const std::string& route, const std::string& lease_id, bool grants) {
  const std::string& m = req.method;
  int64_t now_wall = svc_.clock.wall_ms();
  if (lease_id.empty()) {
    if (m == "GET") {
      auto pr = route_principal(req, body, route, "LEASE_DENIED", Role::kLeasee, "");
      if (!pr.ok()) return answer_error(respond, route, pr.error());
      return answer_json(respond, route, 200,
                         json::Object{{"leases", svc_.sessions.leases_json(now_wall)}});
    }
    auto pr = route_principal(req, body, route, "LEASE_DENIED", Role::kOwner, "config");
    if (!pr.ok()) return answer_error(respond, route, pr.error());
    int64_t dur = seconds_field(body, "duration_s", 3600);
    if (dur < 0)
      return answer_error(respond, route,
                          Error(ErrorCode::kSchemaValidationFailed,
                                "duration_s must be 1 s .. 366 days", "duration_s"));
    auto l = svc_.sessions.grant_lease(
        *pr, PrincipalId{str_field(body, "leasee_iss"), str_field(body, "leasee")}, dur * 1000,
        now_wall, svc_.clock.mono_ms());
    if (!l.ok()) return answer_error(respond, route, l.error());
    AuditRecord e = svc_.record("LEASE_GRANTED", "ok");
    e.by(*pr)
        .message(l->id)
        .detail("lease_id", l->id)
        .detail("leasee", l->leasee.sub)
        .detail("leasee_iss", l->leasee.iss)
        .detail("end_ms", l->end_wall_ms);
    svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                                 {"event", "LEASE_GRANTED"},
                                                 {"lease_id", l->id},
                                                 {"leasee", l->leasee.sub},
                                                 {"end_ms", l->end_wall_ms},
                                                 {"timestamp_ms", now_wall}}));
    announce_control_changes();
    json::Value answer = l->to_json(now_wall);
    return e.write([this, respond, route, answer](rcan::Result<audit::Receipt>) mutable {
      answer_json(respond, route, 201, std::move(answer));
    });
  }
  if (grants) {
    auto pr = route_principal(req, body, route, "LEASE_DENIED", Role::kLeasee, "");
    if (!pr.ok()) return answer_error(respond, route, pr.error());
    auto role = role_from_name(str_field(body, "role").empty() ? "user" : str_field(body, "role"));
    if (!role)
      return answer_error(respond, route,
                          Error(ErrorCode::kSchemaValidationFailed, "unknown role", "role"));
    int64_t dur = seconds_field(body, "duration_s", 3600);
    if (dur < 0)
      return answer_error(
          respond, route,
          Error(ErrorCode::kSchemaValidationFailed, "duration_s must be positive", "duration_s"));
    std::string sub = str_field(body, "user_id");
    auto l = svc_.sessions.grant_within_lease(*pr, lease_id,
                                              PrincipalId{str_field(body, "user_iss"), sub}, *role,
                                              dur * 1000, now_wall, svc_.clock.mono_ms());
    if (!l.ok()) return answer_error(respond, route, l.error());
    AuditRecord e = svc_.record("LEASE_ACCESS_GRANTED", "ok");
    e.by(*pr)
        .message(lease_id)
        .detail("lease_id", lease_id)
        .detail("user_id", sub)
        .detail("role", std::string(role_name(*role)));
    announce_control_changes();
    json::Value answer = l->to_json(now_wall);
    return e.write([this, respond, route, answer](rcan::Result<audit::Receipt>) mutable {
      answer_json(respond, route, 200, std::move(answer));
    });
  }
  auto pr = route_principal(req, body, route, "LEASE_DENIED", Role::kOwner, "config");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  auto l = svc_.sessions.revoke_lease(*pr, lease_id, svc_.clock.mono_ms(), now_wall);
  if (!l.ok()) return answer_error(respond, route, l.error());
  AuditRecord e = svc_.record("LEASE_REVOKED", "ok");
  e.by(*pr).message(lease_id).detail("lease_id", lease_id);
  announce_control_changes();
  json::Value answer = json::Object{{"lease_id", lease_id}, {"revoked", true}};
  e.write([this, respond, route, answer](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 200, std::move(answer));
  });
}

// GET /rcan/v1/transfer: the ownership state. POST {action: request|accept|cancel, …}.
void Node::transfer_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                          const std::string& route) {
  int64_t now_wall = svc_.clock.wall_ms();
  if (req.method == "GET") {
    auto pr = route_principal(req, body, route, "TRANSFER_DENIED", Role::kGuest, "");
    if (!pr.ok()) return answer_error(respond, route, pr.error());
    return answer_json(
        respond, route, 200,
        svc_.ownership.to_json(now_wall, role_level(pr->role) >= role_level(Role::kOwner)));
  }
  std::string action = str_field(body, "action");
  if (action != "request" && action != "accept" && action != "cancel")
    return answer_error(respond, route,
                        Error(ErrorCode::kSchemaValidationFailed,
                              "action must be request, accept or cancel", "action"));
  auto pr = route_principal(req, body, route, "TRANSFER_DENIED",
                            action == "request" ? Role::kOwner : Role::kGuest,
                            action == "request" ? "config" : "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  Result<PendingTransfer> r = Error(ErrorCode::kInternal, "unreachable");
  std::string event;
  if (action == "request") {
    r = svc_.ownership.request(
        *pr, PrincipalId{str_field(body, "new_owner_iss"), str_field(body, "new_owner")},
        str_field(body, "note", 512), now_wall);
    event = "TRANSFER_REQUEST";
  } else if (action == "accept") {
    r = svc_.ownership.accept(*pr, str_field(body, "transfer_id"),
                              str_field(body, "agreement", 512), now_wall);
    event = "TRANSFER_ACCEPT";
  } else {
    r = svc_.ownership.cancel(*pr, now_wall);
    event = "TRANSFER_CANCEL";
  }
  if (!r.ok()) {
    svc_.record("TRANSFER_DENIED", "blocked")
        .by(*pr)
        .reason(std::string(error_name(r.error().code)))
        .detail("action", action)
        .write();
    if (r.error().code == ErrorCode::kSessionExpired) control_tick();  // record the expiry now
    return answer_error(respond, route, r.error());
  }
  AuditRecord e = svc_.record(event, "ok");
  e.by(*pr)
      .message(r->id)
      .detail("transfer_id", r->id)
      .detail("from", r->from.sub)
      .detail("from_iss", r->from.iss)
      .detail("to", r->to.sub)
      .detail("to_iss", r->to.iss)
      .detail("expires_ms", r->expires_ms);
  if (action == "accept") {
    e.detail("agreement", str_field(body, "agreement", 512));
    // Personal data goes; the audit chain and skills stay.
    svc_.sessions.revoke_all("ownership transferred to " + r->to.sub, svc_.clock.mono_ms());
    svc_.consent.clear();
    svc_.ownership.run_clear_hooks();
    e.detail("cleared", json::Array{"sessions", "leases", "users", "consent", "thought_log"});
  }
  json::Value answer = svc_.ownership.to_json(now_wall, true);
  answer.as_object().set("transfer_id", r->id);
  answer.as_object().set("step", event);
  std::string id = r->id;
  svc_.events.publish(json::Value(json::Object{
      {"type", "EVENT"}, {"event", event}, {"transfer_id", id}, {"timestamp_ms", now_wall}}));
  announce_control_changes();
  e.write([this, respond, route, answer](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 200, std::move(answer));
  });
}

// GET /rcan/v1/consent: the pending requests (OWNER).
void Node::consent_list_route(transport::HttpRequest& req, Respond& respond,
                              const json::Value& body, const std::string& route) {
  auto pr = route_principal(req, body, route, "CONSENT_REFUSED", Role::kOwner, "config");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  svc_.consent.expire(svc_.clock.wall_ms());
  json::Array a;
  for (const auto& c : svc_.consent.list()) a.push_back(c.to_json());
  answer_json(respond, route, 200, json::Object{{"requests", a}});
}

// POST /rcan/v1/consent: records a CONSENT_REQUEST (202) and notifies the owner.
void Node::consent_request_route(transport::HttpRequest& req, Respond& respond,
                                 const json::Value& body, const std::string& route) {
  int64_t now_wall = svc_.clock.wall_ms();
  auto pr = route_principal(req, body, route, "CONSENT_REFUSED", Role::kGuest, "");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  json::Value msg_body = body;
  if (!msg_body.get("type")) msg_body.as_object().set("type", "CONSENT_REQUEST");
  if (!msg_body.get("version")) msg_body.as_object().set("version", svc_.settings.rcan_version);
  if (!msg_body.get("message_id")) msg_body.as_object().set("message_id", new_uuid_v4());
  if (!msg_body.get("timestamp_ms")) msg_body.as_object().set("timestamp_ms", now_wall);
  if (!msg_body.get("payload")) msg_body.as_object().set("payload", json::Object{});
  auto refused = [&](const Error& err) {
    AuditRecord e = svc_.record("CONSENT_REFUSED", "blocked");
    e.by(*pr).reason(std::string(error_name(err.code)));
    if (!err.field.empty()) e.detail("field", err.field.substr(0, 128));
    e.write();
    answer_error(respond, route, err);
  };
  auto msg = decode_message(msg_body, svc_.settings.codec);
  if (!msg.ok()) return refused(msg.error());
  if (msg->type != MessageType::kConsentRequest)
    return refused(
        Error(ErrorCode::kSchemaValidationFailed, "type must be CONSENT_REQUEST", "type"));
  auto sig = svc_.auth.check_signature(*msg, *pr);
  if (!sig.ok()) return refused(sig.error());
  auto sender = svc_.auth.sender(*msg, *pr, *sig);
  if (!sender.ok()) return refused(sender.error());
  ConsentRequest c;
  c.requester_sub = pr->sub;
  c.requester_iss = pr->issuer;
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
        return answer_error(
            respond, route,
            Error(ErrorCode::kSchemaValidationFailed, "unknown scope", "payload.scopes"));
      if (c.scopes.size() < 16) c.scopes.push_back(x.as_string());
    }
  }
  if (c.scopes.empty())
    return answer_error(respond, route,
                        Error(ErrorCode::kSchemaValidationFailed, "payload.scopes is required",
                              "payload.scopes", "missing_field"));
  if (const json::Value* d = msg->payload.find("duration_s")) {
    if (!d->is_int() || d->as_int() <= 0 || d->as_int() > 366 * 86400)
      return answer_error(respond, route,
                          Error(ErrorCode::kSchemaValidationFailed, "duration_s must be positive",
                                "payload.duration_s"));
    c.duration_s = d->as_int();
  }
  auto added = svc_.consent.add(c, now_wall);
  if (!added.ok()) return answer_error(respond, route, added.error());
  json::Value note = consent_notification(*added, svc_.settings.name);
  AuditRecord e = svc_.record("CONSENT_REQUEST", "ok");
  e.by(*pr).message(msg->message_id);
  e.entry().sender_type = added->sender_type;
  if (!added->cloud_provider.empty()) e.entry().cloud_provider = added->cloud_provider;
  if (!added->function_name.empty()) e.entry().function_name = added->function_name;
  e.detail("consent_id", added->id);
  e.detail("scopes",
           added->to_json().get("scopes") ? *added->to_json().get("scopes") : json::Value());
  e.detail("notification", note);
  json::Value answer = added->to_json();
  answer.as_object().set("notification", note);
  e.write([this, respond, route, answer](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 202, std::move(answer));
  });
  svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                               {"event", "CONSENT_REQUEST"},
                                               {"consent_id", added->id},
                                               {"notification", note},
                                               {"timestamp_ms", now_wall}}));
  if (!svc_.settings.consent_webhook.empty()) {
    std::string url = svc_.settings.consent_webhook;
    std::string text = json::dump(note);
    std::string cid = added->id;
    worker_.post([this, url, text, cid] {
      auto r = http_request("POST", url, text, 2000);
      AuditRecord we = svc_.record("CONSENT_NOTIFIED", r.ok() && r->status < 300 ? "ok" : "error");
      we.by_system().message(cid).detail("consent_id", cid);
      we.detail("webhook_status",
                r.ok() ? json::Value(static_cast<int64_t>(r->status)) : json::Value());
      if (!r.ok()) we.reason(r.error().message);
      we.write();
    });
  }
  save_control_state();
}

// POST /rcan/v1/consent/<id>/grant {kind: lease|grant, duration_s} or /<id>/deny {reason} (OWNER).
void Node::consent_decision_route(transport::HttpRequest& req, Respond& respond,
                                  const json::Value& body, const std::string& route,
                                  const std::string& id, const std::string& verb) {
  int64_t now_wall = svc_.clock.wall_ms();
  auto pr = route_principal(req, body, route, "CONSENT_REFUSED", Role::kOwner, "config");
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  auto pending = svc_.consent.get(id);
  if (!pending.ok()) return answer_error(respond, route, pending.error());
  std::string kind, lease_id;
  if (verb == "grant") {
    kind = str_field(body, "kind").empty() ? "lease" : str_field(body, "kind");
    int64_t dur = seconds_field(body, "duration_s", pending->duration_s);
    if (dur < 0 || (kind != "lease" && kind != "grant"))
      return answer_error(respond, route,
                          Error(ErrorCode::kSchemaValidationFailed,
                                "kind must be lease or grant; duration_s positive", "kind"));
    if (pending->status != "PENDING" || now_wall >= pending->expires_ms) {
      auto d = svc_.consent.decide(id, true, pr->sub, kind, "", now_wall);
      return answer_error(respond, route,
                          d.ok() ? Error(ErrorCode::kInternal, "unexpected") : d.error());
    }
    if (kind == "lease") {
      auto l = svc_.sessions.grant_lease(*pr, pending->requester(), dur * 1000, now_wall,
                                         svc_.clock.mono_ms());
      if (!l.ok()) return answer_error(respond, route, l.error());
      lease_id = l->id;
    } else {
      bool control = std::find(pending->scopes.begin(), pending->scopes.end(), "control") !=
                     pending->scopes.end();
      auto running = svc_.sessions.leases(now_wall);
      if (running.empty())
        return answer_error(respond, route,
                            Error(ErrorCode::kControlConflict,
                                  "kind grant needs a running lease; use kind lease", "kind"));
      auto l = svc_.sessions.grant_within_lease(*pr, running.front().id, pending->requester(),
                                                control ? Role::kUser : Role::kGuest, dur * 1000,
                                                now_wall, svc_.clock.mono_ms());
      if (!l.ok()) return answer_error(respond, route, l.error());
      lease_id = l->id;
    }
  }
  auto d = svc_.consent.decide(id, verb == "grant", pr->sub, kind, lease_id, now_wall);
  if (!d.ok()) return answer_error(respond, route, d.error());
  AuditRecord e = svc_.record(verb == "grant" ? "CONSENT_GRANTED" : "CONSENT_DENIED", "ok");
  e.by(*pr).message(id);
  e.entry().sender_type = "human";
  e.detail("consent_id", id);
  e.detail("requester", d->requester_sub);
  e.detail("requester_sender_type", d->sender_type);
  if (!d->function_name.empty()) e.detail("requester_function", d->function_name);
  if (!lease_id.empty()) e.detail("lease_id", lease_id);
  if (std::string reason = str_field(body, "reason", 512); !reason.empty()) e.reason(reason);
  svc_.events.publish(
      json::Value(json::Object{{"type", "EVENT"},
                               {"event", verb == "grant" ? "CONSENT_GRANTED" : "CONSENT_DENIED"},
                               {"consent_id", id},
                               {"timestamp_ms", now_wall}}));
  announce_control_changes();
  json::Value answer = d->to_json();
  e.write([this, respond, route, answer](rcan::Result<audit::Receipt>) mutable {
    answer_json(respond, route, 200, std::move(answer));
  });
}

}  // namespace rcan::node
