#include "node/services/node_services.h"

#include <optional>

#include "rcan/errors.h"
#include "rcan/version.h"
#include "transport/http_api.h"

namespace rcan::node {

NodeServices::NodeServices(NodeSettings s, Clock& c, AuthOptions a, Actuation& actuation,
                           audit::AuditLog& log)
    : settings(std::move(s)),
      clock(c),
      auth(std::move(a)),
      revocations(
          settings.state_dir.empty() ? std::string() : settings.state_dir + "/revocations.json",
          RevocationList::kDefaultCapacity, auth.verify_options().leeway_s, nullptr,
          settings.feed_revocations),
      replay(settings.replay),
      injection(settings.injection_patterns),
      act(actuation),
      audit(log),
      trail(settings.ruri, clock, log, metrics, settings.state_dir),
      control(ControlSettings{.robot_name = settings.name,
                              .state_dir = settings.state_dir,
                              .role_policy = settings.role_policy,
                              .heartbeat_timeout_ms = settings.heartbeat_timeout_ms,
                              .handoff_window_ms = settings.handoff_window_ms},
              clock, trail, events, actuation) {}

Result<Principal> NodeServices::authenticate(std::string_view token,
                                             const std::string& source) const {
  const int64_t now_s = clock.wall_ms() / 1000;
  const uint32_t budget = settings.failed_auth_per_address_per_minute;
  const bool limited = !source.empty() && budget > 0 && !token.empty();
  if (limited && !auth.is_cached(token, now_s)) {
    if (auto d = failed_auth.peek(source, budget, clock.mono_ms()); !d.allowed)
      return Error(ErrorCode::kRateLimited,
                   "too many failed authentications from this address; retry in " +
                       std::to_string((d.retry_after_ms + 999) / 1000) + " s",
                   "authorization", "failed_auth_rate");
  }
  auto p = auth.authenticate_token(token, now_s);
  if (!p.ok()) {
    if (limited) (void)failed_auth.take(source, budget, clock.mono_ms());
    return p;
  }
  if (Status s = check_revoked(*p); !s.ok()) return s.error();
  control.ownership().cap(*p);
  return p;
}

Status NodeServices::check_revoked(const Principal& p) const {
  auto why = revocations.revoked(p);
  if (!why) return Status::Ok();
  return Error(ErrorCode::kAuthInvalid, "token revoked (by " + *why + ")", "authorization",
               "token_revoked");
}

Result<Principal> NodeServices::authenticate_header(std::string_view authorization,
                                                    const std::string& source) const {
  std::string_view token = transport::bearer_token(authorization);
  if (token.empty() && !authorization.empty())
    return Error(ErrorCode::kAuthInvalid, "the Authorization header must be 'Bearer <token>'",
                 "authorization");
  return authenticate(token, source);
}

json::Value NodeServices::discovery_info() const {
  json::Object o;
  o.set("ruri", settings.ruri);
  if (!settings.ruri_sdk.empty()) o.set("ruri_sdk", settings.ruri_sdk);
  if (!settings.rrn.empty()) o.set("rrn", settings.rrn);
  o.set("name", settings.name);
  o.set("model", settings.model);
  o.set("manufacturer", settings.manufacturer);
  json::Array caps;
  for (const auto& c : settings.capabilities) caps.emplace_back(c);
  o.set("caps", caps);
  o.set("roles", json::Array{"creator", "owner", "leasee", "user", "guest"});
  o.set("version", settings.rcan_version);
  o.set("rcan_version", settings.rcan_version);
  json::Array ext;
  for (const auto& e : settings.extensions) ext.emplace_back(e);
  o.set("extensions", ext);
  o.set("port", static_cast<int64_t>(settings.port));
  return o;
}

json::Value NodeServices::status(bool detailed) {
  int64_t now = clock.mono_ms();
  json::Object o;
  o.set("ruri", settings.ruri);
  if (!settings.ruri_sdk.empty()) o.set("ruri_sdk", settings.ruri_sdk);
  o.set("rrn", settings.rrn);
  o.set("name", settings.name);
  o.set("rcan_version", settings.rcan_version);
  json::Array ext;
  for (const auto& e : settings.extensions) ext.emplace_back(e);
  o.set("extensions", ext);
  o.set("estop_active", act.estop_active());
  SessionTable& sessions = control.sessions();
  o.set("mode", std::string(net_mode_name(control.partition().mode())));
  o.set("control", std::string(control_state_name(sessions.state(now))));
  if (detailed) {
    o.set("software", json::Object{{"name", "rcand"}, {"version", std::string(kSoftwareVersion)}});
    o.set("partition", control.partition().status_json(clock.wall_ms()));
    if (registry_status) o.set("registry", registry_status());
    o.set("ownership", control.ownership().to_json(clock.wall_ms(), false));
    o.set("control_queue", sessions.queue_json(now));
  }
  o.set("audit_available", audit.available());
  if (detailed) {
    o.set("audit_stop_backlog", trail.stop_backlog.to_json());
    o.set("refusals_coalesced", static_cast<int64_t>(trail.refusals.suppressed_total()));
  }
  json::Value session_list = sessions.to_json(now, detailed);
  o.set("active_sessions", static_cast<int64_t>(session_list.as_array().size()));
  o.set("sessions", session_list);
  json::Array caps;
  for (const auto& c : settings.capabilities) caps.emplace_back(c);
  o.set("capabilities", caps);
  o.set("discovery", discovery_info());
  if (detailed) o.set("robot", act.status());
  return o;
}

json::Value NodeServices::envelope(MessageType type, json::Object payload,
                                   const std::string& reply_to) const {
  json::Object o;
  o.set("version", settings.rcan_version);
  o.set("message_id", new_uuid_v4());
  o.set("source_ruri", settings.ruri);
  o.set("type", std::string(message_type_name(type)));
  o.set("message_type", std::string(message_type_name(type)));
  o.set("reply_to", reply_to.empty() ? json::Value() : json::Value(reply_to));
  o.set("timestamp_ms", clock.wall_ms());
  o.set("payload", std::move(payload));
  return o;
}

json::Value NodeServices::error(const Error& err, const std::string& reply_to) const {
  return error_body(err, reply_to, clock.wall_ms());
}

}  // namespace rcan::node
