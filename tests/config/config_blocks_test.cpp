// Node configuration, block by block: the default of every key (the block left out, and given
// empty), the keys of the node's own blocks read into their members, every rule between keys
// with its path and message, and the order in which a file with several faults reports them.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "config/config.h"
#include "rcan/roles.h"
#include "transport/mqtt_client.h"

namespace rcan::config {
namespace {

constexpr const char* kHead =
    "rcan_version: \"1.2\"\nruri: rcan://local.rcan/rcan/sim-rover/0a1b2c3d\n";

Result<NodeConfig> parse(const std::string& body) {
  ConfigOptions o;
  o.default_data_dir = "/var/lib/rcand-test";
  o.base_dir = "/etc/rcand";
  return parse_config_text(std::string(kHead) + body, o);
}

// ------------------------------------------------------------------------------------------
// Defaults

void expect_server_defaults(const NodeConfig& c) {
  EXPECT_EQ(c.data_dir, "/var/lib/rcand-test");
  EXPECT_EQ(c.log_level, "info");
  EXPECT_EQ(c.server.port, 8080);
  EXPECT_EQ(c.server.bind_address, "127.0.0.1");
  EXPECT_EQ(c.server.io_threads, 2u);
  EXPECT_FALSE(c.server.enable_mdns);
  EXPECT_FALSE(c.server.tls.enabled);
  EXPECT_EQ(c.server.tls.cert_file, "");
  EXPECT_EQ(c.server.limits.max_body_bytes, 65536u);
  EXPECT_EQ(c.server.limits.max_header_bytes, 8192u);
  EXPECT_EQ(c.server.limits.read_timeout_ms, 10000u);
  EXPECT_EQ(c.server.limits.idle_timeout_ms, 60000u);
  EXPECT_EQ(c.server.limits.max_connections, 1024u);
  EXPECT_FALSE(c.grpc.enabled);
  EXPECT_EQ(c.grpc.port, 8081);
  EXPECT_EQ(c.grpc.bind_address, "127.0.0.1");
  EXPECT_EQ(c.grpc.max_streams, 64u);
  EXPECT_EQ(c.grpc.module, "");
  EXPECT_FALSE(c.grpc.tls.enabled);
  EXPECT_EQ(c.grpc.client_ca_file, "");
  EXPECT_FALSE(c.udp.enabled);
  EXPECT_EQ(c.udp.port, 8082);
  EXPECT_EQ(c.udp.bind_address, "127.0.0.1");
  EXPECT_TRUE(c.udp.heartbeat);
  EXPECT_TRUE(c.udp.discovery);
  EXPECT_EQ(c.udp.discovery_per_source_per_min, 30u);
  EXPECT_TRUE(c.dashboard.robots.empty());
  EXPECT_EQ(c.dashboard.ca_file, "");
  EXPECT_EQ(c.dashboard.poll_ms, 2000u);
  EXPECT_EQ(c.dashboard.stop_timeout_ms, 3000u);
}

void expect_security_defaults(const NodeConfig& c) {
  const SecurityConfig& s = c.security;
  EXPECT_EQ(s.key_dir, "/var/lib/rcand-test/keys");
  EXPECT_EQ(s.audit.dir, "/var/lib/rcand-test/audit");
  EXPECT_EQ(s.audit.chain_secret_file, "/var/lib/rcand-test/audit.secret");
  EXPECT_FALSE(c.explicit_paths.key_dir || c.explicit_paths.audit_dir ||
               c.explicit_paths.chain_secret_file);
  EXPECT_EQ(s.audit.sync_policy, audit::SyncPolicy::kPerGroup);
  EXPECT_EQ(s.audit.sync_interval_ms, 2u);
  EXPECT_EQ(s.audit.max_segment_bytes, 16ull << 20);
  EXPECT_EQ(s.audit.retention_max_bytes, 0u);
  EXPECT_EQ(s.audit.retention_max_age_days, 0u);
  EXPECT_TRUE(s.jwt.issuers.empty());
  EXPECT_EQ(s.jwt.leeway_s, 60);
  EXPECT_EQ(s.replay_window_s, 30u);
  EXPECT_EQ(s.msg_id_cache_size, 10000u);
  EXPECT_TRUE(s.trusted_robot_keys.empty());
  EXPECT_TRUE(s.trusted_signer_keys.empty());
  ASSERT_EQ(s.injection_patterns.size(), default_injection_patterns().size());
  EXPECT_EQ(s.injection_patterns[0].text, default_injection_patterns()[0]);
  EXPECT_FALSE(s.injection_patterns[0].regex);
  EXPECT_FALSE(s.commitment.enabled);
  EXPECT_EQ(s.commitment.key_mode, "classical");
  EXPECT_FALSE(s.commitment.qber_threshold.has_value());
}

void expect_rbac_defaults(const NodeConfig& c) {
  const RbacConfig& r = c.rbac;
  EXPECT_FALSE(r.policy.user_arm || r.policy.user_record || r.policy.leasee_training ||
               r.policy.leasee_diagnostics || r.policy.owner_safety_config);
  EXPECT_EQ(r.rate_limits.guest, 10u);
  EXPECT_EQ(r.rate_limits.user, 100u);
  EXPECT_EQ(r.rate_limits.leasee, 500u);
  EXPECT_EQ(r.rate_limits.owner, 1000u);
  EXPECT_EQ(r.rate_limits.creator, 0u);
  // The seed §6.3 values, which are also rcan::GuestLimits's.
  const GuestLimits seed;
  GuestLimits g = r.guest_limits.to_guest_limits();
  EXPECT_EQ(g.chat_per_minute, 10u);
  EXPECT_EQ(g.query_per_minute, 30u);
  EXPECT_EQ(g.session_seconds, 900u);
  EXPECT_EQ(g.concurrent_sessions, 3u);
  EXPECT_EQ(g.capabilities, seed.capabilities);
  EXPECT_EQ(g.blocked, seed.blocked);
  EXPECT_EQ(r.guest_limits.chat_rate.window_s, 60u);
}

void expect_safety_defaults(const NodeConfig& c) {
  const SafetyConfig& s = c.safety;
  EXPECT_TRUE(s.local_safety_wins);
  EXPECT_DOUBLE_EQ(s.max_linear_speed_mps, 0.5);
  EXPECT_DOUBLE_EQ(s.max_angular_speed_radps, 1.0);
  EXPECT_FALSE(s.max_speed_override || s.estop_distance_m || s.collision_monitor_stop_m ||
               s.collision_monitor_slowdown_m || s.obstacle_stop_cm);
  ASSERT_EQ(s.joint_limits.size(), 6u);
  EXPECT_EQ(s.joint_limits[0].name, "joint1");
  EXPECT_EQ(s.joint_limits[5].name, "joint6");
  EXPECT_DOUBLE_EQ(s.joint_limits[3].min_rad, -3.14);
  EXPECT_DOUBLE_EQ(s.joint_limits[3].max_rad, 3.14);
  EXPECT_TRUE(s.workspace.enabled);
  EXPECT_DOUBLE_EQ(s.workspace.x_min, -5);
  EXPECT_DOUBLE_EQ(s.workspace.x_max, 5);
  EXPECT_DOUBLE_EQ(s.workspace.y_min, -5);
  EXPECT_DOUBLE_EQ(s.workspace.y_max, 5);
  EXPECT_FALSE(s.workspace.z_min || s.workspace.z_max);
  EXPECT_EQ(s.speed_policy, LimitPolicy::kClamp);
  EXPECT_EQ(s.joint_policy, LimitPolicy::kReject);
  EXPECT_EQ(s.workspace_policy, LimitPolicy::kReject);
  EXPECT_FALSE(s.estop_on_startup);
  EXPECT_FALSE(s.estop_clear_requires_presence);
  EXPECT_EQ(s.heartbeat_timeout_ms, 2000u);
  EXPECT_EQ(s.heartbeat_timeout_ms, kDefaultHeartbeatTimeoutMs);
  EXPECT_EQ(s.command_ttl_default_ms, 0u);
  EXPECT_TRUE(s.watchdog.enabled);
  EXPECT_EQ(s.watchdog.timeout_s, 10u);
  EXPECT_FALSE(s.max_walk_speed_mps || s.max_tcp_speed_mm_s || s.max_tcp_force_n ||
               s.collision_threshold_scale || s.protective_stop_distance_mm ||
               s.estop_heartbeat_interval_ms || s.estop_timeout_ms || s.fri_heartbeat_timeout_ms);
  EXPECT_TRUE(s.max_joint_torques_nm.empty());
}

void expect_agent_and_driver_defaults(const NodeConfig& c) {
  EXPECT_EQ(c.agent.provider, "");
  EXPECT_EQ(c.agent.model, "");
  EXPECT_FALSE(c.agent.latency_budget_ms.has_value());
  EXPECT_TRUE(c.agent.safety_stop);
  EXPECT_FALSE(c.agent.min_obstacle_m.has_value());
  EXPECT_TRUE(c.agent.confidence_gates.empty());
  EXPECT_TRUE(c.agent.hitl_gates.empty());
  EXPECT_FALSE(c.agent.reactive_layer || c.agent.fast_layer || c.agent.planner_layer);
  EXPECT_EQ(c.brain.provider, "");
  EXPECT_FALSE(c.brain.max_tokens || c.brain.temperature);
  EXPECT_EQ(c.driver.type, "sim");
  EXPECT_DOUBLE_EQ(c.driver.sim.wheel_base_m, 0.3);
  EXPECT_DOUBLE_EQ(c.driver.sim.max_accel_mps2, 1.0);
  EXPECT_DOUBLE_EQ(c.driver.sim.max_angular_accel_radps2, 2.0);
  EXPECT_EQ(c.driver.sim.tick_hz, 50u);
  EXPECT_EQ(c.driver.sim.telemetry_hz, 5u);
  EXPECT_EQ(c.driver.sim.arm_joints, 6u);
}

void expect_session_defaults(const NodeConfig& c) {
  EXPECT_EQ(c.offline.grace_period_s, 86400u);
  EXPECT_EQ(c.offline.cross_owner_grace_s, 3600u);
  EXPECT_EQ(c.offline.max_key_ttl_s, 86400u);
  EXPECT_EQ(c.offline.issuer_url, "");
  EXPECT_EQ(c.offline.issuer_poll_ms, 5000u);
  EXPECT_EQ(c.offline.issuer_timeout_ms, 1000u);
  EXPECT_EQ(c.control.fleet_policy, "role");
  EXPECT_EQ(c.control.handoff_window_s, 30u);
  EXPECT_EQ(c.control.queue_max, 16u);
  EXPECT_EQ(c.control.queue_wait_s, 300u);
  EXPECT_EQ(c.control.max_session_s, 0u);
  EXPECT_EQ(c.control.transfer_window_s, 86400u);
  EXPECT_EQ(c.control.consent_ttl_s, 86400u);
  EXPECT_EQ(c.control.consent_webhook, "");
  EXPECT_EQ(c.qos.ack_timeout_ms, 500u);
  EXPECT_EQ(c.qos.max_retries, 3u);
  EXPECT_EQ(c.qos.backoff_base_ms, 100u);
}

void expect_fleet_defaults(const NodeConfig& c) {
  EXPECT_FALSE(c.mqtt.enabled);
  EXPECT_EQ(c.mqtt.broker, "mqtt://127.0.0.1:1883");
  EXPECT_EQ(c.mqtt.client_id, "");
  EXPECT_EQ(c.mqtt.topic_prefix, "rcan");
  EXPECT_EQ(c.mqtt.keepalive_s, 10u);
  EXPECT_EQ(c.mqtt.username, "");
  EXPECT_EQ(c.mqtt.password_file, "");
  EXPECT_EQ(c.mqtt.ca_file, "");
  EXPECT_EQ(c.mqtt.reconnect_min_s, 1u);
  EXPECT_EQ(c.mqtt.reconnect_max_s, 30u);
  EXPECT_EQ(c.mqtt.telemetry_hz, 1u);
  EXPECT_TRUE(c.mqtt.publish_audit);
  EXPECT_EQ(c.mqtt.estop_qos, 1);
  // The MQTT client's own defaults are the same numbers.
  const transport::MqttOptions client;
  EXPECT_EQ(c.mqtt.broker, client.url);
  EXPECT_EQ(static_cast<int>(c.mqtt.keepalive_s), client.keepalive_s);
  EXPECT_EQ(static_cast<int>(c.mqtt.reconnect_min_s), client.reconnect_min_s);
  EXPECT_EQ(static_cast<int>(c.mqtt.reconnect_max_s), client.reconnect_max_s);
  EXPECT_EQ(c.fleet.fleet_id, "");
  EXPECT_EQ(c.fleet.member_id, "");
  EXPECT_TRUE(c.fleet.robots.empty());
  EXPECT_EQ(c.fleet.access_mode, "coordinated");
  EXPECT_TRUE(c.fleet.broadcast && c.fleet.individual && c.fleet.choreographed);
  EXPECT_EQ(c.swarm.swarm_id, "");
  EXPECT_EQ(c.swarm.member_id, "");
  EXPECT_TRUE(c.swarm.members.empty());
  EXPECT_EQ(c.swarm.formation, "follow-leader");
  EXPECT_EQ(c.swarm.join_policy, "closed");
  EXPECT_EQ(c.swarm.heartbeat_ms, 500u);
  EXPECT_EQ(c.swarm.leader_timeout_ms, 2000u);
}

void expect_identity_defaults(const NodeConfig& c) {
  EXPECT_EQ(c.rrn, "");
  EXPECT_EQ(c.registry_url, "");
  EXPECT_EQ(c.robot.name, "");
  EXPECT_EQ(c.robot.type, "");
  EXPECT_FALSE(c.robot.dof || c.robot.payload_kg || c.robot.reach_mm);
  EXPECT_TRUE(c.robot.tags.empty());
  EXPECT_EQ(c.capabilities, (std::vector<std::string>{"status", "chat"}));  // from robot.type
  EXPECT_TRUE(c.hardware_capabilities.motion.empty());
  EXPECT_EQ(c.channel_admin_scope, "");
  EXPECT_FALSE(c.enable_jwt_false_ignored);
  EXPECT_TRUE(c.warnings.empty());
  EXPECT_TRUE(c.kept.empty());
}

void expect_all_defaults(const NodeConfig& c) {
  {
    SCOPED_TRACE("identity");
    expect_identity_defaults(c);
  }
  {
    SCOPED_TRACE("node, server, grpc, udp");
    expect_server_defaults(c);
  }
  {
    SCOPED_TRACE("security");
    expect_security_defaults(c);
  }
  {
    SCOPED_TRACE("rbac");
    expect_rbac_defaults(c);
  }
  {
    SCOPED_TRACE("safety, watchdog");
    expect_safety_defaults(c);
  }
  {
    SCOPED_TRACE("agent, brain, driver");
    expect_agent_and_driver_defaults(c);
  }
  {
    SCOPED_TRACE("offline, control, qos");
    expect_session_defaults(c);
  }
  {
    SCOPED_TRACE("mqtt, fleet, swarm");
    expect_fleet_defaults(c);
  }
}

TEST(ConfigBlockDefaults, EveryBlockLeftOut) {
  auto r = parse("");
  ASSERT_TRUE(r.ok()) << r.error().message;
  expect_all_defaults(*r);
}

TEST(ConfigBlockDefaults, EveryBlockGivenEmpty) {
  // Each mapping present but empty reads like the block left out.
  auto r = parse(
      "robot: {}\nregistry: {}\nrcan_protocol: {}\nnode: {}\n"
      "server: {tls: {}, limits: {}}\ngrpc: {tls: {}}\nudp: {}\n"
      "security: {audit: {retention: {}}, jwt: {}, injection: {}, commitment: {}}\n"
      "rbac: {grants: {}, rate_limits: {}, guest_limits: {}}\n"
      "safety: {}\nwatchdog: {}\nagent: {layers: {}}\nbrain: {}\ndriver: {sim: {}}\n"
      "offline: {}\ncontrol: {}\nqos: {}\nmqtt: {tls: {}, reconnect: {}}\ndashboard: {}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  expect_all_defaults(*r);
}

TEST(ConfigBlockDefaults, MetadataAndSwarmKeptWithoutTheirReadKeys) {
  auto r = parse("metadata: {author: a}\nswarm: {enabled: true}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  expect_fleet_defaults(*r);  // no swarm_id: the seed keys are not read
  EXPECT_NE(r->kept.find("metadata"), nullptr);
  EXPECT_NE(r->kept.find("swarm"), nullptr);
}

// ------------------------------------------------------------------------------------------
// Keys of the node's own blocks, each read into its member

TEST(ConfigBlockKeys, TransportsSessionsAndFleet) {
  auto r = parse(
      "grpc: {enabled: true, port: 9001, bind: 0.0.0.0, max_streams: 8, module: lib/g.so,\n"
      "  tls: {enabled: true, cert_file: c.pem, key_file: /k.pem, client_ca_file: ca.pem}}\n"
      "udp: {enabled: true, port: 0, bind: 0.0.0.0, heartbeat: false, discovery: true,\n"
      "  discovery_per_source_per_min: 60}\n"
      "control: {fleet_policy: fleet_wins, handoff_window_s: 10, queue_max: 0, queue_wait_s: 60,\n"
      "  max_session_s: 3600, transfer_window_s: 600, consent_ttl_s: 120,\n"
      "  consent_webhook: 'http://owner.example/hook'}\n"
      "offline: {issuer_url: 'http://issuer.example/jwks', issuer_poll_ms: 100,\n"
      "  issuer_timeout_ms: 50}\n"
      "mqtt: {enabled: true, broker: 'mqtts://broker.example:8884', client_id: robot-1,\n"
      "  topic_prefix: fleet/a, keepalive_s: 60, username: u, password_file: pw,\n"
      "  tls: {ca_file: ca.pem, cert_file: c.pem, key_file: k.pem},\n"
      "  reconnect: {min_s: 2, max_s: 20}, telemetry_hz: 0, publish_audit: false, estop_qos: 2}\n"
      "fleet: {fleet_id: yard, robots: [r1, r2], member_id: r2, access_mode: independent,\n"
      "  commands: {broadcast: false, individual: true, choreographed: false}}\n"
      "swarm: {swarm_id: s1, members: [r3, r1], leader: r3, formation: line,\n"
      "  join_policy: open, heartbeat_ms: 100, leader_timeout_ms: 200, secret_file: sw.key}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const NodeConfig& c = *r;
  EXPECT_TRUE(c.grpc.enabled);
  EXPECT_EQ(c.grpc.port, 9001);
  EXPECT_EQ(c.grpc.bind_address, "0.0.0.0");
  EXPECT_EQ(c.grpc.max_streams, 8u);
  EXPECT_EQ(c.grpc.module, "/etc/rcand/lib/g.so");
  EXPECT_TRUE(c.grpc.tls.enabled);
  EXPECT_EQ(c.grpc.tls.cert_file, "/etc/rcand/c.pem");
  EXPECT_EQ(c.grpc.tls.key_file, "/k.pem");
  EXPECT_EQ(c.grpc.client_ca_file, "/etc/rcand/ca.pem");
  EXPECT_TRUE(c.udp.enabled);
  EXPECT_EQ(c.udp.port, 0);
  EXPECT_EQ(c.udp.bind_address, "0.0.0.0");
  EXPECT_FALSE(c.udp.heartbeat);
  EXPECT_TRUE(c.udp.discovery);
  EXPECT_EQ(c.udp.discovery_per_source_per_min, 60u);
  EXPECT_EQ(c.control.fleet_policy, "fleet_wins");
  EXPECT_EQ(c.control.handoff_window_s, 10u);
  EXPECT_EQ(c.control.queue_max, 0u);
  EXPECT_EQ(c.control.queue_wait_s, 60u);
  EXPECT_EQ(c.control.max_session_s, 3600u);
  EXPECT_EQ(c.control.transfer_window_s, 600u);
  EXPECT_EQ(c.control.consent_ttl_s, 120u);
  EXPECT_EQ(c.control.consent_webhook, "http://owner.example/hook");
  EXPECT_EQ(c.offline.issuer_url, "http://issuer.example/jwks");
  EXPECT_EQ(c.offline.issuer_poll_ms, 100u);
  EXPECT_EQ(c.offline.issuer_timeout_ms, 50u);
  EXPECT_EQ(c.mqtt.broker, "mqtts://broker.example:8884");
  EXPECT_EQ(c.mqtt.client_id, "robot-1");
  EXPECT_EQ(c.mqtt.topic_prefix, "fleet/a");
  EXPECT_EQ(c.mqtt.keepalive_s, 60u);
  EXPECT_EQ(c.mqtt.username, "u");
  EXPECT_EQ(c.mqtt.password_file, "/etc/rcand/pw");
  EXPECT_EQ(c.mqtt.ca_file, "/etc/rcand/ca.pem");
  EXPECT_EQ(c.mqtt.cert_file, "/etc/rcand/c.pem");
  EXPECT_EQ(c.mqtt.key_file, "/etc/rcand/k.pem");
  EXPECT_EQ(c.mqtt.reconnect_min_s, 2u);
  EXPECT_EQ(c.mqtt.reconnect_max_s, 20u);
  EXPECT_EQ(c.mqtt.telemetry_hz, 0u);
  EXPECT_FALSE(c.mqtt.publish_audit);
  EXPECT_EQ(c.mqtt.estop_qos, 2);
  EXPECT_EQ(c.fleet.fleet_id, "yard");
  EXPECT_EQ(c.fleet.robots, (std::vector<std::string>{"r1", "r2"}));
  EXPECT_EQ(c.fleet.member_id, "r2");
  EXPECT_EQ(c.fleet.access_mode, "independent");
  EXPECT_FALSE(c.fleet.broadcast);
  EXPECT_TRUE(c.fleet.individual);
  EXPECT_FALSE(c.fleet.choreographed);
  EXPECT_EQ(c.swarm.swarm_id, "s1");
  EXPECT_EQ(c.swarm.member_id, "r2");                                        // the fleet member id
  EXPECT_EQ(c.swarm.members, (std::vector<std::string>{"r1", "r2", "r3"}));  // sorted, with it
  EXPECT_EQ(c.swarm.leader, "r3");
  EXPECT_EQ(c.swarm.formation, "line");
  EXPECT_EQ(c.swarm.join_policy, "open");
  EXPECT_EQ(c.swarm.heartbeat_ms, 100u);
  EXPECT_EQ(c.swarm.leader_timeout_ms, 200u);
  EXPECT_EQ(std::filesystem::path(c.swarm.secret_file).filename(), "sw.key");
}

TEST(ConfigBlockKeys, DashboardRobots) {
  auto r = parse(
      "dashboard: {robots: ['http://10.0.0.12:8080', 'https://rover-2.example'], ca_file: ca.pem,\n"
      "  poll_ms: 500, stop_timeout_ms: 1000}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->dashboard.robots,
            (std::vector<std::string>{"http://10.0.0.12:8080", "https://rover-2.example"}));
  EXPECT_EQ(r->dashboard.ca_file, "/etc/rcand/ca.pem");
  EXPECT_EQ(r->dashboard.poll_ms, 500u);
  EXPECT_EQ(r->dashboard.stop_timeout_ms, 1000u);
}

TEST(ConfigBlockKeys, ComputedDefaultsAndAliases) {
  // The member ids default to the RURI device id; the swarm leader to the first member.
  auto r = parse(
      "mqtt: {enabled: true}\nfleet: {fleet_id: f, robots: [0a1b2c3d, zz]}\n"
      "swarm: {swarm_id: s, members: [zz], secret_file: sw.key}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->fleet.member_id, "0a1b2c3d");
  EXPECT_EQ(r->swarm.member_id, "0a1b2c3d");
  EXPECT_EQ(r->swarm.leader, "0a1b2c3d");
  // The heartbeat timeout: twice the latency budget, within 100..600000 ms.
  r = parse("agent: {latency_budget_ms: 20}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->safety.heartbeat_timeout_ms, 100u);
  r = parse("agent: {latency_budget_ms: 0}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->safety.heartbeat_timeout_ms, kDefaultHeartbeatTimeoutMs);
  r = parse("agent: {latency_budget_ms: 400}\nsafety: {heartbeat_timeout_ms: 700}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->safety.heartbeat_timeout_ms, 700u);
  // Aliases in the other published style, and the unit conversion of estop_distance_mm.
  r = parse(
      "rcan_protocol: {port: 8000, enable_mdns: true, registry: 'https://r', channel_admin_scope: "
      "adm, capabilities: [status]}\nsafety: {max_linear_x: 0.7, max_angular_z: 0.9, "
      "estop_distance_mm: 250}\nreactive: {min_obstacle_m: 0.4}\nphysics: {type: ackermann, "
      "dof: 4}\nmetadata: {robot_name: n, manufacturer: m, model: x, description: d, tags: [t], "
      "robot_uuid: 123E4567-E89B-12D3-A456-426614174000}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->server.port, 8000);
  EXPECT_TRUE(r->server.enable_mdns);
  EXPECT_EQ(r->registry_url, "https://r");
  EXPECT_EQ(r->channel_admin_scope, "adm");
  EXPECT_EQ(r->capabilities, (std::vector<std::string>{"status"}));
  EXPECT_DOUBLE_EQ(r->safety.max_linear_speed_mps, 0.7);
  EXPECT_DOUBLE_EQ(r->safety.max_angular_speed_radps, 0.9);
  EXPECT_DOUBLE_EQ(*r->safety.estop_distance_m, 0.25);
  EXPECT_DOUBLE_EQ(*r->agent.min_obstacle_m, 0.4);
  EXPECT_EQ(r->robot.type, "ackermann");
  EXPECT_EQ(r->robot.dof, 4u);
  EXPECT_EQ(r->robot.name, "n");
  EXPECT_EQ(r->robot.manufacturer, "m");
  EXPECT_EQ(r->robot.model, "x");
  EXPECT_EQ(r->robot.description, "d");
  EXPECT_EQ(r->robot.tags, (std::vector<std::string>{"t"}));
  EXPECT_EQ(r->robot.robot_uuid, "123E4567-E89B-12D3-A456-426614174000");
  // Robot keys only the profile style has, and the vendor safety keys.
  r = parse(
      "robot: {payload_kg: 5, reach_mm: 850, serial_pattern: 'SN-{device_id}'}\n"
      "safety: {max_joint_torques_nm: [1, 2.5], estop_timeout_ms: 7,\n"
      "  estop_clear_requires_presence: true}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_DOUBLE_EQ(*r->robot.payload_kg, 5);
  EXPECT_DOUBLE_EQ(*r->robot.reach_mm, 850);
  EXPECT_EQ(r->robot.serial_pattern, "SN-{device_id}");
  EXPECT_EQ(r->safety.max_joint_torques_nm, (std::vector<double>{1, 2.5}));
  EXPECT_EQ(r->safety.estop_timeout_ms, 7u);
  EXPECT_TRUE(r->safety.estop_clear_requires_presence);
}

// The registry whose tokens the robot trusts: defaults, the issuer, the intervals.
TEST(ConfigBlocks, RegistryTrustTokens) {
  auto r = parse("registry: {registry_url: 'https://reg.example'}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->registry.trust_tokens);
  EXPECT_EQ(r->registry.jwks_refresh_s, 300u);
  EXPECT_EQ(r->registry.revocations_refresh_s, 30u);
  EXPECT_EQ(r->registry.max_key_age_s, 86400u);
  r = parse("registry: {registry_url: 'https://reg.example', trust_tokens: true}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_TRUE(r->registry.trust_tokens);
  EXPECT_EQ(r->registry.issuer, "https://reg.example");  // the registry's URL by default
  r = parse(
      "registry: {registry_url: 'https://reg.example', trust_tokens: true, issuer: "
      "'https://id.example', jwks_refresh_s: 60, revocations_refresh_s: 5, max_key_age_s: 3600}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->registry.issuer, "https://id.example");
  EXPECT_EQ(r->registry.jwks_refresh_s, 60u);
  EXPECT_EQ(r->registry.revocations_refresh_s, 5u);
  EXPECT_EQ(r->registry.max_key_age_s, 3600u);
  // Trusting the registry's tokens needs its URL.
  r = parse("registry: {trust_tokens: true}\n");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "registry.trust_tokens");
  r = parse("registry: {registry_url: 'https://reg.example', jwks_refresh_s: 0}\n");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "registry.jwks_refresh_s");
}

// ------------------------------------------------------------------------------------------
// Rules between keys: each with its path, reason and message

struct Rule {
  const char* body;
  const char* field;
  const char* reason;
  const char* message;  // the whole text after "<field>: ", without the position
};

void expect_rule(const Rule& rule) {
  SCOPED_TRACE(rule.body);
  auto r = parse(rule.body);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, rule.field);
  EXPECT_EQ(r.error().reason, rule.reason);
  const std::string text = std::string(rule.field) + ": " + rule.message;
  EXPECT_EQ(r.error().message.substr(0, text.size()), text) << r.error().message;
}

TEST(ConfigBlockRules, IdentityServerAndSecurity) {
  const Rule rules[] = {
      {"rrn: RRN-000000000001\nregistry: {rrn: RRN-000000000002}\n", "registry.rrn",
       "invalid_value", "conflicts with rrn (give one of them)"},
      {"robot: {name: a}\nmetadata: {robot_name: b}\n", "metadata.robot_name", "invalid_value",
       "conflicts with robot.name (give one of them)"},
      {"capabilities: [chat]\nrcan_protocol: {capabilities: [chat]}\n",
       "rcan_protocol.capabilities", "invalid_value",
       "capabilities are given twice (capabilities and rcan_protocol.capabilities)"},
      {"node: {data_dir: ''}\n", "node.data_dir", "invalid_value", "must not be empty"},
      {"server: {enable_mdns: true}\nrcan_protocol: {enable_mdns: false}\n",
       "rcan_protocol.enable_mdns", "invalid_value",
       "conflicts with server.enable_mdns (give one of them)"},
      {"grpc: {bind: 'a b'}\n", "grpc.bind", "invalid_value",
       "expected an IP address or host name"},
      {"grpc: {tls: {enabled: true, cert_file: c}}\n", "grpc.tls.key_file", "missing_key",
       "required when tls.enabled is true"},
      {"grpc: {tls: {client_ca_file: ca.pem}}\n", "grpc.tls.client_ca_file", "invalid_value",
       "needs tls.enabled: true"},
      {"grpc: {enabled: true, port: 8080}\n", "grpc.port", "invalid_value",
       "must differ from server.port (8080)"},
      {"udp: {bind: 'a b'}\n", "udp.bind", "invalid_value", "expected an IP address"},
      {"dashboard: {robots: ['ftp://r']}\n", "dashboard.robots[0]", "invalid_value",
       "expected http://host[:port] or https://host[:port] (no path), got \"ftp://r\""},
      {"dashboard: {robots: ['http://a:1', 'http://a:1/api']}\n", "dashboard.robots[1]",
       "invalid_value",
       "expected http://host[:port] or https://host[:port] (no path), got \"http://a:1/api\""},
      {"dashboard: {robots: ['http://a:1', 'https://b', 'http://a:1']}\n", "dashboard.robots[2]",
       "invalid_value", "listed twice"},
      {"udp: {enabled: true, heartbeat: false, discovery: false}\n", "udp.enabled", "invalid_value",
       "udp is enabled but both heartbeat and discovery are off"},
      {"security: {key_dir: ''}\n", "security.key_dir", "invalid_value", "must not be empty"},
      {"security: {audit: {chain_secret_file: ''}}\n", "security.audit.chain_secret_file",
       "invalid_value", "must not be empty"},
      {"security: {jwt: {issuers: [{issuer: '', key_file: k}]}}\n",
       "security.jwt.issuers[0].issuer", "invalid_value", "must not be empty"},
      {"security: {trusted_robot_keys: [{name: a, ed25519_pub_file: x}, {name: a, "
       "ed25519_pub_file: y}]}\n",
       "security.trusted_robot_keys[1].name", "invalid_value", "duplicate trusted key name \"a\""},
      {"security: {injection: {patterns: ['']}}\n", "security.injection.patterns[0]",
       "invalid_value", "empty pattern"},
      // v1.5 blocks rcand does not implement are refused, never parsed and ignored (R7).
      {"security: {key_rotation: {auto_rotate: true}}\n", "security.key_rotation", "not_supported",
       "security.key_rotation is not implemented by rcand"},
      {"security: {key_rotation: {}}\n", "security.key_rotation", "not_supported",
       "security.key_rotation is not implemented by rcand; add the new key beside the old one"},
      {"security: {revocation: {check_on_startup: true}}\n", "security.revocation", "not_supported",
       "security.revocation is not implemented by rcand; the node's own revocation list is "
       "always on"},
  };
  for (const Rule& rule : rules) expect_rule(rule);
}

TEST(ConfigBlockRules, RbacAgentSafetyAndSessions) {
  const Rule rules[] = {
      {"rbac: {guest_limits: {session_duration: 0}}\n", "rbac.guest_limits.session_duration",
       "out_of_range", "must be longer than zero"},
      {"guest_limits: {session_duration: 400d}\n", "guest_limits.session_duration", "out_of_range",
       "duration longer than a year"},
      {"agent: {min_obstacle_m: 0.2}\nreactive: {min_obstacle_m: 0.3}\n", "reactive.min_obstacle_m",
       "invalid_value", "conflicts with agent.min_obstacle_m (give one of them)"},
      {"agent: {confidence_gates: [{scope: Nav, min_confidence: 0.5, on_fail: block}]}\n",
       "agent.confidence_gates[0].scope", "invalid_value",
       "invalid scope \"Nav\" (lower-case name like control, nav, admin)"},
      {"agent: {hitl_gates: [{action_types: [''], require_auth: false}]}\n",
       "agent.hitl_gates[0].action_types[0]", "invalid_value", "empty action type"},
      {"agent: {hitl_gates: [{action_type: a, require_auth: true, authorized_roles: []}]}\n",
       "agent.hitl_gates[0].authorized_roles", "invalid_value", "must name OWNER and/or CREATOR"},
      {"agent: {hitl_gates: [{action_type: a, require_auth: true, authorized_roles: [X]}]}\n",
       "agent.hitl_gates[0].authorized_roles[0]", "invalid_value", "unknown role \"X\""},
      {"safety: {collision_monitor_stop_m: 1, collision_monitor_slowdown_m: 0.5}\n",
       "safety.collision_monitor_slowdown_m", "out_of_range",
       "must be at least collision_monitor_stop_m (slow down before stopping)"},
      {"safety: {workspace: {x_min: 0, x_max: 1, y_min: 1, y_max: 1}}\n", "safety.workspace.y_max",
       "out_of_range", "must be greater than y_min"},
      {"safety: {workspace: {x_min: 0, x_max: 1, y_min: 0, y_max: 1, z_max: 1}}\n",
       "safety.workspace.z_min", "missing_key", "z_min and z_max go together"},
      {"safety: {workspace: {x_min: 0, x_max: 1, y_min: 0, y_max: 1, z_min: 2, z_max: 1}}\n",
       "safety.workspace.z_max", "out_of_range", "must be greater than z_min"},
      {"safety: {joint_limits: [{min: 1, max: 1}]}\n", "safety.joint_limits[0].max", "out_of_range",
       "must be greater than min (1 ≥ 1)"},
      {"offline: {issuer_url: 'ftp://x'}\n", "offline.issuer_url", "invalid_value",
       "must be an http:// URL"},
      {"control: {consent_webhook: nope}\n", "control.consent_webhook", "invalid_value",
       "must be an http:// URL"},
  };
  for (const Rule& rule : rules) expect_rule(rule);
}

TEST(ConfigBlockRules, MqttFleetAndSwarm) {
  const Rule rules[] = {
      {"mqtt: {broker: 'mqtts://b'}\n", "mqtt.tls.ca_file", "missing_key",
       "required with an mqtts:// broker"},
      {"mqtt: {client_id: 'a b'}\n", "mqtt.client_id", "invalid_value",
       "expected 1-128 characters of [A-Za-z0-9._-]"},
      {"mqtt: {topic_prefix: 'a/#'}\n", "mqtt.topic_prefix", "invalid_value",
       "expected '/'-separated segments of [A-Za-z0-9._-] (no wildcards)"},
      {"mqtt: {username: u}\n", "mqtt.password_file", "missing_key", "required with mqtt.username"},
      {"mqtt: {tls: {cert_file: c}}\n", "mqtt.tls", "missing_key",
       "cert_file and key_file go together"},
      {"mqtt: {reconnect: {min_s: 10, max_s: 5}}\n", "mqtt.reconnect.max_s", "out_of_range",
       "must be at least reconnect.min_s"},
      {"fleet: {fleet_id: f, robots: [a]}\n", "fleet", "invalid_value",
       "a fleet needs the MQTT transport (mqtt.enabled: true)"},
      {"mqtt: {enabled: true}\nfleet: {fleet_id: 'f f', robots: [a]}\n", "fleet.fleet_id",
       "invalid_value", "expected 1-128 characters of [A-Za-z0-9._-], got \"f f\""},
      {"mqtt: {enabled: true}\nfleet: {fleet_id: f, robots: [a]}\n", "fleet.robots",
       "invalid_value",
       "must list this robot (\"0a1b2c3d\", fleet.member_id or the RURI device id)"},
      {"swarm: {swarm_id: s}\n", "swarm.swarm_id", "invalid_value",
       "a swarm needs the MQTT transport (mqtt.enabled: true)"},
      {"mqtt: {enabled: true}\nswarm: {swarm_id: s, leader: zz}\n", "swarm.leader", "invalid_value",
       "the leader must be one of swarm.members"},
      {"mqtt: {enabled: true}\nswarm: {swarm_id: s, heartbeat_ms: 1500}\n",
       "swarm.leader_timeout_ms", "out_of_range", "must be at least twice swarm.heartbeat_ms"},
  };
  for (const Rule& rule : rules) expect_rule(rule);
}

// A file with several faults reports the first in the order the blocks and their rows are read
// (blocks/document.cpp), whatever the order of the keys in the file.
TEST(ConfigBlockRules, FirstFaultInReadingOrder) {
  const Rule rules[] = {
      {"udp: {bind: 'a b'}\nnode: {data_dir: ''}\n", "node.data_dir", "invalid_value",
       "must not be empty"},
      {"grpc: {enabled: true, port: 8080}\nudp: {enabled: true, heartbeat: false, discovery: "
       "false}\n",
       "udp.enabled", "invalid_value", "udp is enabled but both heartbeat and discovery are off"},
      {"swarm: {swarm_id: s}\nsafety: {local_safety_wins: false}\n", "safety.local_safety_wins",
       "invalid_value", "must be true: local safety always wins over network commands"},
      {"safety: {workspace: {x_min: 1, x_max: 0, y_min: 0, y_max: 1}, max_angular_speed_radps: 1, "
       "max_angular_z: 2, max_linear_speed_mps: 1, max_linear_x: 2}\n",
       "safety.max_linear_x", "invalid_value",
       "conflicts with safety.max_linear_speed_mps (give one of them)"},
      {"agent: {hitl_gates: [{action_types: [''], action_type: a, require_auth: true}]}\n"
       "brain: {confidence_gates: []}\nagent2: 1\n",
       "agent2", "unknown_key", "unknown key"},
      {"agent: {confidence_gates: [{scope: A, min_confidence: 1, on_fail: block}], hitl_gates: "
       "[]}\nbrain: {hitl_gates: []}\n",
       "brain.hitl_gates", "invalid_value",
       "gates are given twice (agent.hitl_gates and brain.hitl_gates)"},
      {"mqtt: {client_id: 'a b', broker: nope}\n", "mqtt.broker", "invalid_value",
       "a broker URL starts with mqtt:// or mqtts://"},
      {"metadata: {robot_uuid: x}\nrobot: {model: a}\nmetadata2: 1\n", "metadata2", "unknown_key",
       "unknown key"},
      {"metadata: {robot_uuid: x, model: b}\nrobot: {model: a}\n", "metadata.model",
       "invalid_value", "conflicts with robot.model (give one of them)"},
  };
  for (const Rule& rule : rules) expect_rule(rule);
}

TEST(ConfigBlockKeys, DriverProcess) {
  auto r = parse(
      "driver:\n  type: process\n  process:\n    command: [python3, /opt/drv/base.py, --port, "
      "/dev/ttyUSB0]\n    heartbeat_ms: 50\n    heartbeat_timeout_ms: 300\n"
      "    restart_backoff_ms: 100\n    restart_backoff_max_ms: 2000\n    max_linear_mps: 0.8\n"
      "    max_angular_radps: 1.5\n    brake_decel_mps2: 2\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const ProcessDriverConfig& p = r->driver.process;
  EXPECT_EQ(r->driver.type, "process");
  ASSERT_EQ(p.command.size(), 4u);
  EXPECT_EQ(p.command[1], "/opt/drv/base.py");
  EXPECT_EQ(p.heartbeat_ms, 50u);
  EXPECT_EQ(p.heartbeat_timeout_ms, 300u);
  EXPECT_EQ(p.startup_timeout_ms, 5000u);
  EXPECT_EQ(p.restart_backoff_ms, 100u);
  EXPECT_EQ(p.restart_backoff_max_ms, 2000u);
  EXPECT_DOUBLE_EQ(p.max_linear_mps, 0.8);
  EXPECT_DOUBLE_EQ(p.brake_decel_mps2, 2.0);
  EXPECT_EQ(p.arm_joints, 0u);  // a base only, unless told
  EXPECT_FALSE(p.gripper);
  auto arm = parse(
      "driver: {type: process, process: {command: [drv], arm_joints: 4, max_joint_speed_radps: "
      "0.5, joint_min_rad: [-1, -2], joint_max_rad: [1, 2], gripper: true}}\n");
  ASSERT_TRUE(arm.ok()) << arm.error().message;
  EXPECT_EQ(arm->driver.process.arm_joints, 4u);
  EXPECT_DOUBLE_EQ(arm->driver.process.max_joint_speed_radps, 0.5);
  EXPECT_EQ(arm->driver.process.joint_max_rad, (std::vector<double>{1, 2}));
  EXPECT_TRUE(arm->driver.process.gripper);
  auto s = parse("driver: {type: process, process: {socket: run/drv.sock}}\n");
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->driver.process.socket, "/etc/rcand/run/drv.sock");  // relative to the file
  const Rule rules[] = {
      {"driver: {type: process}\n", "driver.process", "required",
       "driver.type process needs command or socket"},
      {"driver: {type: can}\n", "driver.type", "invalid_value", ""},
      {"driver: {process: {heartbeat_ms: 100, heartbeat_timeout_ms: 100}}\n",
       "driver.process.heartbeat_timeout_ms", "out_of_range", "must exceed heartbeat_ms"},
      {"driver: {process: {restart_backoff_ms: 500, restart_backoff_max_ms: 100}}\n",
       "driver.process.restart_backoff_max_ms", "out_of_range",
       "must not be below restart_backoff_ms"},
      {"driver: {process: {arm_joints: 7}}\n", "driver.process.arm_joints", "out_of_range", ""},
      {"driver: {process: {arm_joints: 2, joint_min_rad: [0, 1], joint_max_rad: [1, 1]}}\n",
       "driver.process.joint_max_rad[1]", "invalid_value", "must be above joint_min_rad"},
      {"driver: {process: {joint_max_rad: [1]}}\n", "driver.process.arm_joints", "invalid_value",
       "joint ranges need an arm"},
  };
  for (const Rule& rule : rules) expect_rule(rule);
}

}  // namespace
}  // namespace rcan::config
