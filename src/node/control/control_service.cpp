// ControlService: control sessions (claim, renew, release, handoff, the queue), revocation,
// the control tick and the control state file. Leases, transfer and consent:
// control_grants.cpp.
#include "node/control/control_service.h"

#include <utility>

#include "runtime/log.h"
#include "runtime/state_file.h"

namespace rcan::node {

ControlService::ControlService(ControlSettings settings, Clock& clock, AuditTrail& trail,
                               EventBus& events, Actuation& act)
    : settings_(std::move(settings)), clock_(clock), trail_(trail), events_(events), act_(act) {
  // seed §6.1 log_for_sync(): while partitioned, every record says it waits for a sync.
  trail_.set_sync_mode([this] {
    NetMode m = partition_.mode();
    return m == NetMode::kNormal ? std::string() : std::string(net_mode_name(m));
  });
  MutexLock lock(state_mu_);
  last_state_ = std::string(control_state_name(sessions_.state(clock_.mono_ms())));
}

ControlService::~ControlService() { trail_.set_sync_mode({}); }

json::Array ControlService::capabilities_of(Role r) const {
  json::Array caps;
  for (int i = 0; i < kCapabilityCount; ++i) {
    auto cap = static_cast<Capability>(i);
    if (role_allows(r, cap, settings_.role_policy))
      caps.emplace_back(std::string(capability_name(cap)));
  }
  return caps;
}

void ControlService::publish_to(const std::string& principal_key, json::Object ev) {
  events_.publish(json::Value(std::move(ev)), Audience::principal(principal_key));
}

void ControlService::publish(json::Object ev) { events_.publish(json::Value(std::move(ev))); }

void ControlService::publish_available(const std::string& released, int64_t now_wall) {
  if (sessions_.state(clock_.mono_ms()) != ControlState::kAvailable) return;
  publish(json::Object{{"type", "AVAILABLE"},
                       {"released_session", released},
                       {"window_ms", settings_.handoff_window_ms},
                       {"timestamp_ms", now_wall}});
}

// ---------------------------------------------------------------------------------------------
// The control state: loaded at start, saved on every change, announced by the tick.

void ControlService::start(std::function<void()> wake) {
  sessions_.on_change(wake);
  ownership_.on_change(wake);
  consent_.on_change(wake);
  if (!settings_.state_dir.empty()) {
    int64_t now = clock_.wall_ms();
    if (auto v = read_state_file(settings_.state_dir + "/leases.json"); v.ok())
      sessions_.load_json(*v, now);
    if (auto v = read_state_file(settings_.state_dir + "/ownership.json"); v.ok())
      ownership_.load_json(*v);
    if (auto v = read_state_file(settings_.state_dir + "/consent.json"); v.ok())
      consent_.load_json(*v);
    if (auto v = read_state_file(settings_.state_dir + "/credentials.json"); v.ok())
      partition_.load_json(*v, now);
  }
  partition_.start([this] { return clock_.wall_ms(); },
                   [this](NetMode old, NetMode now) { record_partition_mode(old, now); });
  MutexLock lock(state_mu_);
  last_state_ = std::string(control_state_name(sessions_.state(clock_.mono_ms())));
}

void ControlService::record_partition_mode(NetMode old, NetMode now) {
  trail_.record("PARTITION_MODE", "ok")
      .by_system()
      .reason(std::string(net_mode_name(now)))
      .detail("from", std::string(net_mode_name(old)))
      .detail("to", std::string(net_mode_name(now)))
      .write();
  publish(json::Object{{"type", "EVENT"},
                       {"event", "PARTITION_MODE"},
                       {"mode", std::string(net_mode_name(now))},
                       {"from", std::string(net_mode_name(old))},
                       {"timestamp_ms", clock_.wall_ms()}});
  save();
}

void ControlService::stop() {
  sessions_.on_change({});
  ownership_.on_change({});
  consent_.on_change({});
  partition_.stop();
  save();
}

void ControlService::save() {
  if (settings_.state_dir.empty()) return;
  MutexLock lock(save_mu_);
  uint64_t v[4] = {sessions_.version(), ownership_.version(), consent_.version(),
                   partition_.version()};
  const char* names[4] = {"leases.json", "ownership.json", "consent.json", "credentials.json"};
  for (int i = 0; i < 4; ++i) {
    if (v[i] == saved_versions_[i]) continue;
    json::Value doc = i == 0   ? sessions_.persist_json()
                      : i == 1 ? ownership_.persist_json()
                      : i == 2 ? consent_.persist_json()
                               : partition_.persist_json();
    Status s = write_state_file(settings_.state_dir + "/" + names[i], doc);
    if (s.ok())
      saved_versions_[i] = v[i];
    else
      log(LogLevel::kError, "state_write_failed",
          json::Object{{"file", names[i]}, {"error", s.error().message}});
  }
}

bool ControlService::quiet() { return sessions_.quiet() && ownership_.quiet() && consent_.quiet(); }

void ControlService::tick(const std::vector<std::string>& streamless) {
  int64_t now_wall = clock_.wall_ms();
  sessions_.tick(clock_.mono_ms(), now_wall);
  if (auto t = ownership_.expire(now_wall)) {
    trail_.record("TRANSFER_EXPIRED", "ok")
        .by_system()
        .detail("transfer_id", t->id)
        .detail("from", t->from.sub)
        .detail("to", t->to.sub)
        .detail("to_iss", t->to.iss)
        .write();
    publish(json::Object{{"type", "EVENT"},
                         {"event", "TRANSFER_EXPIRED"},
                         {"transfer_id", t->id},
                         {"timestamp_ms", now_wall}});
  }
  for (const auto& c : consent_.expire(now_wall)) {
    trail_.record("CONSENT_EXPIRED", "ok")
        .by_system()
        .detail("consent_id", c.id)
        .detail("requester", c.requester_sub)
        .write();
  }
  for (const auto& key : streamless) (void)sessions_.drop_queued(key, "stream_closed");
  announce();
}

void ControlService::announce_change(const ControlChange& c) {
  const Session& s = c.session;
  AuditRecord e = trail_.record("", "ok");
  e.by_system().message(s.id);
  if (!s.sub.empty()) e.entry().sub = s.sub;
  if (!c.reason.empty()) e.reason(c.reason);
  json::Object ev{{"type", "EVENT"}, {"timestamp_ms", clock_.wall_ms()}};
  if (c.event == ControlEvent::kExpire || c.event == ControlEvent::kRevoke) {
    act_.disarm_deadman(s.id);
    act_.stop("control session " + s.id + " ended");
    e.entry().event = c.event == ControlEvent::kExpire ? "SESSION_EXPIRED" : "SESSION_REVOKED";
    e.detail("role", std::string(role_name(s.role)));
    if (!c.lease_id.empty()) e.detail("lease_id", c.lease_id);
    ev.set("event", e.entry().event);
    ev.set("session_id", s.id);
    ev.set("reason", c.reason);
    publish_to(s.principal_key, std::move(ev));
  } else if (c.event == ControlEvent::kPromote) {
    act_.arm_deadman(s.id, settings_.heartbeat_timeout_ms);
    e.entry().event = "CLAIM_PROMOTED";
    e.detail("role", std::string(role_name(s.role)));
    ev.set("type", "GRANTED");
    ev.set("event", "PROMOTED");
    ev.set("session_id", s.id);
    ev.set("role", std::string(role_name(s.role)));
    ev.set("capabilities", capabilities_of(s.role));
    ev.set("expires_in", s.expires_mono_ms
                             ? json::Value((s.expires_mono_ms - clock_.mono_ms()) / 1000)
                             : json::Value());
    ev.set("heartbeat_timeout_ms", settings_.heartbeat_timeout_ms);
    // Secrets never travel in events: what a direct grant carries (the UDP heartbeat key) the
    // promoted holder fetches itself, authenticated, by renewing its session with
    // {"session_id", "udp_heartbeat": true} (renew()).
    if (on_grant_) ev.set("udp_heartbeat_on_renew", true);
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
    publish(std::move(ev));
  } else {
    return;
  }
  e.write();
}

void ControlService::announce() {
  for (auto& c : sessions_.take_changes()) announce_change(c);
  // The "control state changed" event (streams, and whatever else subscribes: mDNS status).
  std::string now_state(control_state_name(sessions_.state(clock_.mono_ms())));
  bool changed = false;
  {
    MutexLock lock(state_mu_);
    if (now_state != last_state_) {
      last_state_ = now_state;
      changed = true;
    }
  }
  if (changed) {
    json::Object ev{{"type", "EVENT"},
                    {"event", "CONTROL_STATE"},
                    {"state", now_state},
                    {"timestamp_ms", clock_.wall_ms()}};
    if (now_state == "AVAILABLE") ev.set("window_ms", settings_.handoff_window_ms);
    publish(std::move(ev));
  }
  save();
}

// ---------------------------------------------------------------------------------------------
// Control sessions

json::Value ControlService::queue() { return sessions_.queue_json(clock_.mono_ms()); }

ControlAnswer ControlService::leave_queue(const Principal& p) {
  if (!sessions_.leave_queue(p))
    return ControlAnswer::refused(Error(ErrorCode::kNotFound, "not in the control queue"));
  trail_.record("CLAIM_WITHDRAWN", "ok").by(p).write();
  ControlAnswer a;
  a.body = json::Object{{"left", true}};
  return a;
}

ControlAnswer ControlService::queued(const Principal& p, size_t position) {
  trail_.record("CLAIM_QUEUED", "blocked")
      .by(p)
      .reason("CONTROL_CONFLICT")
      .detail("queue_position", static_cast<int64_t>(position))
      .write();
  ControlAnswer a;
  a.status = 409;
  a.body = error_body(Error(ErrorCode::kControlConflict,
                            "the robot is controlled by another principal of the same role; "
                            "you are number " +
                                std::to_string(position) + " in the queue",
                            "session", "queued"),
                      {}, clock_.wall_ms());
  json::Object& payload = a.body.as_object().find("payload")->as_object();
  payload.set("queue_position", static_cast<int64_t>(position));
  payload.set("queued", true);
  return a;
}

void ControlService::preempt(const Session& displaced, const Principal& by, Role by_role,
                             int64_t now_wall) {
  // The displaced holder loses control now: its motion stops, its in-flight commands are
  // dropped at dispatch (their session is gone), and it is told on its stream.
  act_.disarm_deadman(displaced.id);
  act_.stop("pre-empted by " + by.display());
  publish_to(displaced.principal_key, json::Object{{"type", "EVENT"},
                                                   {"event", "PREEMPTED"},
                                                   {"session_id", displaced.id},
                                                   {"by_role", std::string(role_name(by_role))},
                                                   {"timestamp_ms", now_wall}});
  AuditRecord pe = trail_.record("SESSION_PREEMPTED", "ok");
  pe.by(by).message(displaced.id);
  pe.entry().sub = displaced.sub;
  pe.detail("by", by.sub);
  pe.detail("by_role", std::string(role_name(by_role)));
  pe.detail("role", std::string(role_name(displaced.role)));
  pe.write();
}

ControlAnswer ControlService::claim(const Principal& p, const ClaimRequest& r) {
  const bool fleet = !r.fleet_id.empty();
  int64_t now_mono = clock_.mono_ms(), now_wall = clock_.wall_ms();
  auto deny = [&](const Error& err, const std::string& reason) {
    trail_.record("CLAIM_DENIED", "blocked")
        .by(p)
        .reason(reason)
        .detail("error", err.message)
        .write();
    return ControlAnswer::refused(err);
  };
  // Network partition: no new sessions in LOCKDOWN; offline, only principals validated while
  // the issuer was reachable. A holder renewing its own session is not a new session.
  auto holder = sessions_.controller(now_mono);
  bool renewal = holder && holder->principal_key == p.key();
  NetMode mode = partition_.mode();
  if (!renewal && mode == NetMode::kLockdown)
    return deny(Error(ErrorCode::kLockdown,
                      "LOCKDOWN: the token issuer is unreachable and the credential cache has "
                      "expired; no new sessions"),
                "LOCKDOWN");
  if (!renewal && mode == NetMode::kOfflineAutonomous && !partition_.cached(p, now_wall))
    return deny(Error(ErrorCode::kLockdown,
                      "OFFLINE_AUTONOMOUS: this principal is not in the credential cache; "
                      "new principals cannot be authenticated while the issuer is unreachable"),
                "OFFLINE_UNCACHED");
  if (mode == NetMode::kNormal) partition_.note_validated(p, now_wall);
  ownership_.note_user(p.sub);
  auto c = sessions_.claim(p, r.role, fleet, now_mono, now_wall);
  if (!c.ok()) {
    ControlAnswer a = deny(c.error(), "CONTROL_CONFLICT");
    announce();
    return a;
  }
  if (c->outcome == ClaimOutcome::kQueued) {
    ControlAnswer a = queued(p, c->queue_position);
    announce();
    return a;
  }
  if (c->preempted) preempt(*c->preempted, p, c->session.role, now_wall);
  act_.arm_deadman(c->session.id, settings_.heartbeat_timeout_ms);
  const bool renewed = c->outcome == ClaimOutcome::kRenewed;
  ControlAnswer a;
  AuditRecord& e = a.record.emplace(trail_.record(renewed ? "CLAIM_RENEWED" : "CLAIM", "ok"));
  e.by(p).message(c->session.id);
  // A new session is armed; a renewing claim keeps its arming unless it asks (docs/NODE.md,
  // "Re-arm after ESTOP").
  const bool rearmed = r.rearm && act_.rearm(c->session.id).ok();
  if (rearmed) e.detail("rearmed", true);
  if (c->preempted) e.detail("preempted_session", c->preempted->id);
  if (!c->session.lease_id.empty()) e.detail("lease_id", c->session.lease_id);
  if (fleet) e.detail("fleet_id", r.fleet_id);
  json::Object payload{{"session_id", c->session.id},
                       {"role", std::string(role_name(c->session.role))},
                       {"capabilities", capabilities_of(c->session.role)},
                       {"heartbeat_timeout_ms", settings_.heartbeat_timeout_ms},
                       {"renewed", renewed}};
  if (rearmed) payload.set("rearmed", true);
  if (c->session.expires_mono_ms)
    payload.set("expires_in", (c->session.expires_mono_ms - now_mono) / 1000);
  else
    payload.set("expires_in", json::Value());
  if (!c->session.lease_id.empty()) payload.set("lease_id", c->session.lease_id);
  if (on_grant_) on_grant_(c->session.id, payload);  // e.g. udp_heartbeat
  announce();
  a.body = std::move(payload);
  a.envelope = MessageType::kGranted;
  return a;
}

ControlAnswer ControlService::renew(const Principal& p, const RenewRequest& req) {
  if (req.session_id.empty())
    return ControlAnswer::refused(Error(ErrorCode::kSchemaValidationFailed,
                                        "session_id is required", "session_id", "missing_field"));
  auto r = sessions_.renew(req.session_id, p, clock_.mono_ms(), clock_.wall_ms());
  if (!r.ok()) {
    trail_.record("RENEW_DENIED", "blocked")
        .by(p)
        .message(req.session_id)
        .reason(std::string(error_name(r.error().code)))
        .write();
    announce();
    return ControlAnswer::refused(r.error());
  }
  act_.feed_deadman(r->id);
  ControlAnswer a;
  AuditRecord& e = a.record.emplace(trail_.record("CLAIM_RENEWED", "ok"));
  e.by(p).message(r->id);
  json::Object payload{
      {"session_id", r->id}, {"role", std::string(role_name(r->role))}, {"renewed", true}};
  if (req.rearm && act_.rearm(r->id).ok()) {  // docs/NODE.md, "Re-arm"
    e.detail("rearmed", true);
    payload.set("rearmed", true);
  }
  payload.set("expires_in", r->expires_mono_ms
                                ? json::Value((r->expires_mono_ms - clock_.mono_ms()) / 1000)
                                : json::Value());
  // The holder asks for its session's UDP heartbeat key (a fresh one; the previous key stops
  // working): how a holder promoted from the queue gets it, since events carry no secrets.
  if (req.udp_heartbeat && on_grant_) {
    on_grant_(r->id, payload);
    e.detail("udp_heartbeat", "issued");
  }
  a.body = std::move(payload);
  a.envelope = MessageType::kGranted;
  return a;
}

ControlAnswer ControlService::release(const Principal& p, std::string session_id) {
  if (session_id.empty()) {
    auto holder = sessions_.controller(clock_.mono_ms());
    if (holder && holder->principal_key == p.key()) session_id = holder->id;
  }
  if (session_id.empty())
    return ControlAnswer::refused(Error(ErrorCode::kSchemaValidationFailed,
                                        "session_id is required", "session_id", "missing_field"));
  auto r = sessions_.release(session_id, p, clock_.mono_ms(), clock_.wall_ms());
  if (!r.ok()) return ControlAnswer::refused(r.error());
  act_.disarm_deadman(session_id);
  trail_.record("RELEASE", "ok").by(p).message(session_id).write();
  publish_available(session_id, clock_.wall_ms());
  announce();
  ControlAnswer a;
  a.body = json::Object{{"session_id", session_id}};
  a.envelope = MessageType::kReleased;
  return a;
}

ControlAnswer ControlService::handoff(const Principal& p, HandoffRequest req) {
  if (req.target.iss.empty()) req.target.iss = p.issuer;
  const int64_t window = settings_.handoff_window_ms;
  auto r =
      sessions_.handoff(req.session_id, p, req.target, req.target_role, window, clock_.mono_ms());
  if (!r.ok()) return ControlAnswer::refused(r.error());
  act_.disarm_deadman(req.session_id);
  publish(json::Object{{"type", "AVAILABLE"},
                       {"released_session", req.session_id},
                       {"reserved_for", req.target.sub},
                       {"window_ms", window},
                       {"timestamp_ms", clock_.wall_ms()}});
  ControlAnswer a;
  AuditRecord& e = a.record.emplace(trail_.record("HANDOFF", "ok"));
  e.by(p)
      .message(req.session_id)
      .detail("target_user_id", req.target.sub)
      .detail("target_iss", req.target.iss);
  if (req.target_role) e.detail("target_role", std::string(role_name(*req.target_role)));
  if (!req.reason.empty()) e.reason(req.reason);
  announce();
  a.body = json::Object{
      {"session_id", req.session_id}, {"target_user_id", req.target.sub}, {"window_ms", window}};
  a.envelope = MessageType::kAvailable;
  return a;
}

void ControlService::end_revoked(const RevocationList& revocations) {
  bool changed = false;
  for (const QueuedClaim& q : sessions_.queued())
    if (revocations.revoked(q.as_principal()))
      changed = sessions_.drop_queued(q.principal_key, "token_revoked") || changed;
  const int64_t mono = clock_.mono_ms(), wall = clock_.wall_ms();
  auto holder = sessions_.controller(mono);
  const Principal p = holder ? holder->as_principal() : Principal{};
  const auto why = holder ? revocations.revoked(p) : std::nullopt;
  if (why && sessions_.release(holder->id, p, mono, wall).ok()) {
    // Nothing the revoked token commanded outlives it, as with a pre-empted holder
    // (Revocation.ATokensJti… drives, then revokes).
    act_.disarm_deadman(holder->id);
    act_.stop("token revoked: " + p.display());
    trail_.record("RELEASE", "ok")
        .by(p)
        .message(holder->id)
        .reason("token_revoked")
        .detail("revoked_by", *why)
        .write();
    publish_available(holder->id, wall);
    changed = true;
  }
  if (changed) announce();
}

}  // namespace rcan::node
