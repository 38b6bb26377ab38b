// Config → the settings of each part rcand starts (settings.h).
#include "settings.h"

#include <cstdlib>

#include "node/control/sessions.h"
#include "rcan/errors.h"
#include "rcan/ruri.h"
#include "registry_join.h"

namespace rcan::rcand {

audit::AuditOptions audit_options(const config::NodeConfig& cfg, const std::string& secret) {
  audit::AuditOptions ao;
  ao.secret = secret;
  ao.sync_policy = cfg.security.audit.sync_policy;
  ao.sync_interval_ms = static_cast<int>(cfg.security.audit.sync_interval_ms);
  ao.max_segment_bytes = cfg.security.audit.max_segment_bytes;
  ao.retention_max_bytes = cfg.security.audit.retention_max_bytes;
  ao.retention_max_age_ms = int64_t{cfg.security.audit.retention_max_age_days} * 86'400'000;
  ao.robot_ruri = cfg.ruri;
  return ao;
}

node::SafetyConfig safety_config(const config::NodeConfig& cfg, const node::SimRobotConfig& sim) {
  node::SafetyConfig sc;
  sc.file = cfg.safety;
  // The limits the core enforces: the speed caps (under max_speed_override), the arm's speed,
  // the configured joints in order onto the arm's fixed joint slots, the workspace.
  sc.limits.max_linear_mps = cfg.safety.max_linear_speed_mps;
  sc.limits.max_angular_radps = cfg.safety.max_angular_speed_radps;
  if (cfg.safety.max_speed_override) {
    sc.limits.max_linear_mps *= *cfg.safety.max_speed_override;
    sc.limits.max_angular_radps *= *cfg.safety.max_speed_override;
  }
  sc.limits.max_joint_speed_radps = sim.max_joint_speed_radps;
  for (size_t i = 0; i < cfg.safety.joint_limits.size() && i < node::kArmJoints; ++i) {
    sc.limits.joint_min_rad[i] = cfg.safety.joint_limits[i].min_rad;
    sc.limits.joint_max_rad[i] = cfg.safety.joint_limits[i].max_rad;
  }
  sc.limits.workspace = cfg.safety.workspace;
  sc.tick_period_ms = cfg.driver.sim.tick_hz ? 1000 / cfg.driver.sim.tick_hz : 20;
  return sc;
}

node::NodeSettings node_settings(const config::NodeConfig& cfg, const keys::RobotKeys& robot) {
  node::NodeSettings ns;
  ns.ruri = cfg.ruri;
  ns.ruri_sdk = sdk_form(cfg.ruri_parts);
  ns.rrn = cfg.rrn;
  if (ns.rrn.empty()) ns.rrn = stored_registry_rrn(cfg.data_dir);  // registry_join.h
  if (ns.rrn.empty()) {
    // A stable local registration number from the robot's key id (digits only).
    std::string kid = robot.pub.kid();
    uint64_t v = std::strtoull(kid.c_str(), nullptr, 16) % 1'000'000'000'000ULL;
    ns.rrn = format_rrn(static_cast<int64_t>(v));
  }
  ns.name = cfg.robot.name.empty() ? "rcan-robot" : cfg.robot.name;
  ns.manufacturer =
      cfg.robot.manufacturer.empty() ? cfg.ruri_parts.manufacturer : cfg.robot.manufacturer;
  ns.model = cfg.robot.model.empty() ? cfg.ruri_parts.model : cfg.robot.model;
  if (!cfg.capabilities.empty()) ns.capabilities = cfg.capabilities;
  ns.port = cfg.server.port;
  ns.role_policy = cfg.rbac.policy;
  ns.rate_per_minute = {0,
                        cfg.rbac.rate_limits.guest,
                        cfg.rbac.rate_limits.user,
                        cfg.rbac.rate_limits.leasee,
                        cfg.rbac.rate_limits.owner,
                        cfg.rbac.rate_limits.creator};
  ns.replay.window_ms = int64_t{cfg.security.replay_window_s} * 1000;
  ns.replay.capacity = cfg.security.msg_id_cache_size;
  ns.failed_auth_per_address_per_minute = cfg.security.failed_auth_per_address_per_minute;
  ns.injection_patterns.clear();
  for (const auto& p : cfg.security.injection_patterns)
    ns.injection_patterns.push_back(node::InjectionRule{p.text, p.regex});
  ns.heartbeat_timeout_ms = cfg.safety.heartbeat_timeout_ms;
  ns.default_ttl_ms = cfg.safety.command_ttl_default_ms;
  ns.codec.max_body_bytes = cfg.server.limits.max_body_bytes;
  ns.telemetry_hz = static_cast<int>(cfg.driver.sim.telemetry_hz);
  ns.guest_limits = cfg.rbac.guest_limits.to_guest_limits();
  ns.handoff_window_ms = int64_t{cfg.control.handoff_window_s} * 1000;
  ns.state_dir = cfg.data_dir;
  ns.feed_revocations = cfg.registry.max_feed_revocations;
  ns.consent_webhook = cfg.control.consent_webhook;
  return ns;
}

namespace {

// Public keys named in the config: peer robots' (a robot signature changes the §8.5 verdict)
// and operators'/integrators' (human or software signers).
Status load_keys(const std::vector<config::TrustedRobotKey>& list, const char* what,
                 msgsig::TrustedKeys& into) {
  for (const auto& rk : list) {
    for (auto [file, found] : {std::pair{&rk.mldsa65_pub_file, &into.mldsa65},
                               std::pair{&rk.ed25519_pub_file, &into.ed25519}}) {
      if (file->empty()) continue;
      auto b = keys::read_public_file(*file);
      if (!b.ok())
        return Error(ErrorCode::kInternal,
                     std::string("security.") + what + " " + rk.name + ": " + b.error().message);
      found->push_back(*b);
    }
  }
  return Status::Ok();
}

}  // namespace

Result<node::AuthOptions> auth_options(const config::NodeConfig& cfg, jwt::TrustStore trust,
                                       const std::string& rrn) {
  node::AuthOptions auth;
  auth.trust = std::move(trust);
  auth.verify.audience = cfg.ruri;
  auth.verify.fleet_ids = {cfg.ruri_parts.device_id, cfg.ruri, rrn};
  auth.own_rrn = rrn;
  if (!cfg.fleet.fleet_id.empty()) {
    auth.verify.fleet_ids.push_back(cfg.fleet.member_id);
    // "fleet:<fleet_id>" in the claim names every member of the fleet: a token for a fleet of
    // 1,000 robots need not list them all (and would not fit the 8 KiB token limit if it did).
    auth.verify.fleet_ids.push_back("fleet:" + cfg.fleet.fleet_id);
    auth.verify.fleet_audiences.push_back("rcan://fleet/" + cfg.fleet.fleet_id);  // v1.5 fleet JWT
  }
  auth.verify.leeway_s = cfg.security.jwt.leeway_s;
  if (Status s = load_keys(cfg.security.trusted_robot_keys, "trusted_robot_keys", auth.robot_keys);
      !s.ok())
    return s.error();
  if (Status s =
          load_keys(cfg.security.trusted_signer_keys, "trusted_signer_keys", auth.signer_keys);
      !s.ok())
    return s.error();
  return auth;
}

void configure_control(node::NodeServices& services, const config::NodeConfig& cfg,
                       std::function<int64_t()> registry_keys_fetched_ms) {
  node::ControlOptions co;  // docs/SESSIONS.md
  co.handoff_window_ms = services.settings.handoff_window_ms;
  co.queue_max = cfg.control.queue_max;
  co.queue_wait_ms = int64_t{cfg.control.queue_wait_s} * 1000;
  co.queue_stream_grace_ms = int64_t{cfg.control.queue_stream_grace_s} * 1000;
  co.fleet_policy =
      node::fleet_policy_from_name(cfg.control.fleet_policy).value_or(node::FleetPolicy::kRole);
  co.guest_session_s = services.settings.guest_limits.session_seconds;
  co.max_session_ms = int64_t{cfg.control.max_session_s} * 1000;
  services.control.sessions().set_options(co);
  services.control.ownership().set_window_ms(int64_t{cfg.control.transfer_window_s} * 1000);
  services.control.consent().set_pending_ttl_ms(int64_t{cfg.control.consent_ttl_s} * 1000);
  node::PartitionOptions po;
  po.issuer_url = cfg.offline.issuer_url;
  po.poll_interval_ms = cfg.offline.issuer_poll_ms;
  po.timeout_ms = static_cast<int>(cfg.offline.issuer_timeout_ms);
  po.key_ttl_ms = int64_t{cfg.offline.max_key_ttl_s} * 1000;
  if (po.issuer_url.empty() && registry_keys_fetched_ms) {  // the registry is the issuer
    std::string base = cfg.registry_url;
    while (!base.empty() && base.back() == '/') base.pop_back();
    po.issuer_url = base + "/healthz";
    po.ca_file = cfg.registry.ca_file;
    po.key_ttl_ms = int64_t{cfg.registry.max_key_age_s} * 1000;
    po.keys_fetched_ms = std::move(registry_keys_fetched_ms);
  }
  services.control.partition().configure(po);
}

transport::ServerOptions server_options(const config::NodeConfig& cfg) {
  transport::ServerOptions so;
  so.bind_address = cfg.server.bind_address;
  so.port = cfg.server.port;
  so.io_threads = static_cast<int>(cfg.server.io_threads);
  so.max_body_bytes = cfg.server.limits.max_body_bytes;
  so.max_header_bytes = cfg.server.limits.max_header_bytes;
  so.read_timeout_ms = static_cast<int>(cfg.server.limits.read_timeout_ms);
  so.idle_timeout_ms = static_cast<int>(cfg.server.limits.idle_timeout_ms);
  so.max_connections = cfg.server.limits.max_connections;
  so.max_connections_per_address = cfg.server.limits.max_connections_per_address;
  so.reserved_connections = cfg.server.limits.reserved_connections;
  so.unauthenticated_idle_timeout_ms =
      static_cast<int>(cfg.server.limits.unauthenticated_idle_timeout_ms);
  so.ws_max_message_bytes = cfg.server.limits.max_body_bytes;
  so.tls = cfg.server.tls.enabled;
  so.cert_file = cfg.server.tls.cert_file;
  so.key_file = cfg.server.tls.key_file;
  return so;
}

}  // namespace rcan::rcand
