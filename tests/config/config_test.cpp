// Node configuration: the six published profiles, the example, the embedded default, every
// kind of bad input (with the key path in the error), hostile YAML, and overrides.
#include "config/config.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "test_support.h"

namespace rcan::config {
namespace {

const std::string kData = RCAN_TESTDATA_DIR;
const std::string kProfiles = kData + "/profiles/";
const std::string kFixtures = kData + "/config/";
const std::string kExample = std::string(RCAN_TESTDATA_DIR) + "/../../examples/sim-robot.rcan.yaml";

constexpr const char* kHead =
    "rcan_version: \"1.2\"\nruri: rcan://local.rcan/rcan/sim-rover/0a1b2c3d\n";

ConfigOptions opts_with_dir() {
  ConfigOptions o;
  o.default_data_dir = "/var/lib/rcand-test";
  return o;
}

Result<NodeConfig> parse(const std::string& body) {
  return parse_config_text(std::string(kHead) + body, opts_with_dir());
}

// Asserts failure; returns the error for further checks.
Error expect_error(const Result<NodeConfig>& r, const std::string& field,
                   const std::string& reason) {
  EXPECT_FALSE(r.ok());
  if (r.ok()) return {};
  const Error& e = r.error();
  EXPECT_EQ(e.code, ErrorCode::kSchemaValidationFailed);
  EXPECT_EQ(e.field, field) << e.message;
  EXPECT_EQ(e.reason, reason) << e.message;
  if (!field.empty()) {
    EXPECT_NE(e.message.find(field + ": "), std::string::npos) << e.message;
  }
  return e;
}

// ------------------------------------------------------------------------------------------
// Profiles

struct Profile {
  const char* file;
  const char* ruri_prefix;
  const char* type;
  double control_conf;
  double admin_conf;
};

class ProfileTest : public ::testing::TestWithParam<Profile> {};

TEST_P(ProfileTest, LoadsAfterDeviceIdSubstitution) {
  const Profile& p = GetParam();
  std::string text = test::read_file(kProfiles + p.file);
  ASSERT_FALSE(text.empty());
  // 1. textual substitution, as a deployment would do
  std::string sub = text;
  sub.replace(sub.find("{device_id}"), 11, "0a1b2c3d");
  auto r = parse_config_text(sub, opts_with_dir());
  ASSERT_TRUE(r.ok()) << p.file << ": " << r.error().message;
  EXPECT_EQ(r->ruri, std::string(p.ruri_prefix) + "0a1b2c3d");
  EXPECT_EQ(r->rcan_version, "1.2");
  EXPECT_EQ(r->robot.type, p.type);
  EXPECT_TRUE(r->safety.local_safety_wins);
  ASSERT_EQ(r->agent.confidence_gates.size(), 2u);
  EXPECT_EQ(r->agent.confidence_gates[0].scope, "control");
  EXPECT_DOUBLE_EQ(r->agent.confidence_gates[0].min_confidence, p.control_conf);
  EXPECT_EQ(r->agent.confidence_gates[0].on_fail, GateOnFail::kEscalate);
  EXPECT_EQ(r->agent.confidence_gates[1].scope, "admin");
  EXPECT_DOUBLE_EQ(r->agent.confidence_gates[1].min_confidence, p.admin_conf);
  EXPECT_EQ(r->agent.confidence_gates[1].on_fail, GateOnFail::kBlock);
  EXPECT_TRUE(r->agent.hitl_gates.empty());
  EXPECT_FALSE(r->hardware_capabilities.motion.empty());
  EXPECT_FALSE(r->hardware_capabilities.safety.empty());
  ASSERT_NE(r->kept.find("bridge"), nullptr);
  EXPECT_TRUE(r->kept.find("bridge")->get("type")->is_string());
  ASSERT_TRUE(r->safety.estop_distance_m.has_value());
  EXPECT_GT(*r->safety.estop_distance_m, 0.0);

  // 2. the loader's own substitution (ConfigOptions::device_id), from the file
  ConfigOptions o = opts_with_dir();
  o.device_id = "0a1b2c3d";
  auto f = load_config(kProfiles + p.file, o);
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->ruri, r->ruri);
  EXPECT_EQ(f->source, kProfiles + p.file);

  // 3. without an id the placeholder is named
  auto n = load_config(kProfiles + p.file, opts_with_dir());
  ASSERT_FALSE(n.ok());
  EXPECT_EQ(n.error().field, "ruri");
  EXPECT_NE(n.error().message.find("{device_id}"), std::string::npos);
}

INSTANTIATE_TEST_SUITE_P(
    AllProfiles, ProfileTest,
    ::testing::Values(Profile{"spot.rcan.yaml", "rcan://local.rcan/boston-dynamics/spot/",
                              "mobile_quadruped", 0.75, 0.95},
                      Profile{"ur5e.rcan.yaml", "rcan://local.rcan/universal-robots/ur5e/",
                              "collaborative_arm", 0.90, 0.98},
                      Profile{"ur10e.rcan.yaml", "rcan://local.rcan/universal-robots/ur10e/",
                              "collaborative_arm", 0.90, 0.98},
                      Profile{"franka-research-3.rcan.yaml",
                              "rcan://local.rcan/franka-robotics/franka-research-3/",
                              "collaborative_arm", 0.85, 0.97},
                      Profile{"iiwa7.rcan.yaml", "rcan://local.rcan/kuka/iiwa7/",
                              "collaborative_arm", 0.90, 0.97},
                      Profile{"mobile-differential-drive.rcan.yaml",
                              "rcan://local.rcan/generic/differential-drive/",
                              "mobile_differential", 0.70, 0.92}));

TEST(ConfigProfiles, VendorKeysAreKept) {
  ConfigOptions o = opts_with_dir();
  o.device_id = "0a1b2c3d";
  auto spot = load_config(kProfiles + "spot.rcan.yaml", o);
  ASSERT_TRUE(spot.ok()) << spot.error().message;
  EXPECT_EQ(spot->safety.estop_heartbeat_interval_ms, 500u);
  EXPECT_EQ(spot->safety.estop_timeout_ms, 3000u);
  EXPECT_DOUBLE_EQ(*spot->safety.max_walk_speed_mps, 0.8);
  EXPECT_DOUBLE_EQ(*spot->safety.estop_distance_m, 0.8);
  EXPECT_DOUBLE_EQ(*spot->safety.max_speed_override, 0.5);
  EXPECT_EQ(spot->robot.dof, 12u);
  EXPECT_EQ(spot->robot.manufacturer, "Boston Dynamics");
  // Mobile types get teleop/nav; no arm.
  EXPECT_EQ(spot->capabilities, (std::vector<std::string>{"status", "chat", "teleop", "nav"}));
  EXPECT_EQ(spot->hardware_capabilities.motion.front(), "walk");

  auto iiwa = load_config(kProfiles + "iiwa7.rcan.yaml", o);
  ASSERT_TRUE(iiwa.ok()) << iiwa.error().message;
  EXPECT_EQ(iiwa->safety.max_joint_torques_nm.size(), 7u);
  EXPECT_DOUBLE_EQ(*iiwa->safety.max_tcp_force_n, 150);
  EXPECT_EQ(iiwa->safety.fri_heartbeat_timeout_ms, 100u);
  EXPECT_EQ(iiwa->capabilities, (std::vector<std::string>{"status", "chat", "arm"}));
  EXPECT_EQ(iiwa->kept.find("bridge")->get("fri_port")->as_int(), 30200);
  EXPECT_DOUBLE_EQ(*iiwa->robot.reach_mm, 800);

  auto fr3 = load_config(kProfiles + "franka-research-3.rcan.yaml", o);
  ASSERT_TRUE(fr3.ok()) << fr3.error().message;
  const json::Value* args = fr3->kept.find("bridge")->get("launch_args");
  ASSERT_NE(args, nullptr);
  EXPECT_EQ(args->get("arm_id")->as_string(), "fr3");
  EXPECT_DOUBLE_EQ(*fr3->safety.collision_threshold_scale, 0.5);

  auto diff = load_config(kProfiles + "mobile-differential-drive.rcan.yaml", o);
  ASSERT_TRUE(diff.ok()) << diff.error().message;
  EXPECT_DOUBLE_EQ(diff->safety.max_linear_speed_mps, 0.5);
  EXPECT_DOUBLE_EQ(diff->safety.max_angular_speed_radps, 1.0);
  EXPECT_DOUBLE_EQ(*diff->safety.collision_monitor_stop_m, 0.25);
  EXPECT_TRUE(diff->hardware_capabilities.io.empty());

  auto ur10 = load_config(kProfiles + "ur10e.rcan.yaml", o);
  ASSERT_TRUE(ur10.ok()) << ur10.error().message;
  EXPECT_DOUBLE_EQ(*ur10->safety.protective_stop_distance_mm, 300);
  EXPECT_EQ(ur10->robot.serial_pattern, "{device_id}");
}

TEST(ConfigProfiles, ProfileWithUnknownVendorKeyFails) {
  std::string text = test::read_file(kProfiles + "ur5e.rcan.yaml");
  text.replace(text.find("{device_id}"), 11, "0a1b2c3d");
  text.replace(text.find("max_tcp_force_n"), 15, "max_tcp_farce_n");
  auto r = parse_config_text(text, opts_with_dir());
  expect_error(r, "safety.max_tcp_farce_n", "unknown_key");
}

// ------------------------------------------------------------------------------------------
// The example and the embedded default

TEST(ConfigDefault, EmbeddedDefault) {
  auto r = default_config("/tmp/rcand-data", "0a1b2c3d");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const NodeConfig& c = *r;
  EXPECT_EQ(c.ruri, "rcan://local.rcan/rcan/sim-rover/0a1b2c3d");
  EXPECT_EQ(c.robot.name, "sim-rover");
  EXPECT_EQ(c.capabilities, (std::vector<std::string>{"status", "chat", "teleop", "nav", "arm"}));
  EXPECT_EQ(c.server.port, 8080);
  EXPECT_EQ(c.server.bind_address, "127.0.0.1");
  EXPECT_EQ(c.server.io_threads, 2u);
  EXPECT_EQ(c.server.limits.max_body_bytes, 65536u);
  EXPECT_EQ(c.server.limits.max_header_bytes, 8192u);
  EXPECT_EQ(c.server.limits.read_timeout_ms, 10000u);
  EXPECT_EQ(c.server.limits.idle_timeout_ms, 60000u);
  EXPECT_EQ(c.server.limits.max_connections, 1024u);
  EXPECT_FALSE(c.server.tls.enabled);
  EXPECT_EQ(c.data_dir, "/tmp/rcand-data");
  EXPECT_EQ(c.security.key_dir, "/tmp/rcand-data/keys");
  EXPECT_EQ(c.security.audit.dir, "/tmp/rcand-data/audit");
  EXPECT_EQ(c.security.audit.chain_secret_file, "/tmp/rcand-data/audit.secret");
  EXPECT_EQ(c.security.audit.sync_policy, audit::SyncPolicy::kPerGroup);
  EXPECT_EQ(c.security.replay_window_s, 30u);
  EXPECT_EQ(c.security.msg_id_cache_size, 10000u);
  EXPECT_EQ(c.security.jwt.leeway_s, 60);
  EXPECT_TRUE(c.security.jwt.issuers.empty());
  EXPECT_EQ(c.security.injection_patterns.size(), default_injection_patterns().size());
  EXPECT_TRUE(c.rrn.empty());
  EXPECT_TRUE(c.agent.confidence_gates.empty());
  EXPECT_TRUE(c.agent.hitl_gates.empty());
  EXPECT_EQ(c.safety.joint_limits.size(), 6u);
  EXPECT_DOUBLE_EQ(c.safety.joint_limits[0].min_rad, -3.14);
  EXPECT_DOUBLE_EQ(c.safety.joint_limits[5].max_rad, 3.14);
  EXPECT_EQ(c.safety.speed_policy, LimitPolicy::kClamp);
  EXPECT_EQ(c.safety.joint_policy, LimitPolicy::kReject);
  EXPECT_EQ(c.safety.workspace_policy, LimitPolicy::kReject);
  EXPECT_EQ(c.safety.heartbeat_timeout_ms, 2000u);
  EXPECT_TRUE(c.safety.watchdog.enabled);
  EXPECT_EQ(c.safety.watchdog.timeout_s, 10u);
  EXPECT_EQ(c.driver.type, "sim");
  EXPECT_EQ(c.driver.sim.tick_hz, 50u);
  EXPECT_EQ(c.driver.sim.telemetry_hz, 5u);
  EXPECT_EQ(c.rbac.guest_limits.chat_rate.count, 10u);
  EXPECT_EQ(c.rbac.rate_limits.for_role(Role::kOwner), 1000u);
  EXPECT_EQ(c.source, "<embedded default>");
}

TEST(ConfigDefault, DeviceIdDerivedFromDataDirIsStable) {
  auto a = default_config("/tmp/rcand-a");
  auto a2 = default_config("/tmp/rcand-a/");
  auto b = default_config("/tmp/rcand-b");
  ASSERT_TRUE(a.ok() && a2.ok() && b.ok());
  EXPECT_EQ(a->ruri_parts.device_id.size(), 8u);
  EXPECT_EQ(a->ruri, default_config("/tmp/rcand-a")->ruri);
  EXPECT_NE(a->ruri, b->ruri);
  auto bad = default_config("/tmp/x", "NOT-HEX");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().field, "ruri");
  EXPECT_FALSE(default_config("").ok());
}

TEST(ConfigDefault, ExampleLoadsLikeTheEmbeddedDefault) {
  ConfigOptions o;
  o.default_data_dir = "/tmp/rcand-data";
  auto ex = load_config(kExample, o);
  ASSERT_TRUE(ex.ok()) << ex.error().message;
  auto def = default_config("/tmp/rcand-data", "0a1b2c3d");
  ASSERT_TRUE(def.ok());
  EXPECT_EQ(ex->ruri, def->ruri);
  EXPECT_EQ(ex->capabilities, def->capabilities);
  EXPECT_EQ(ex->server.port, def->server.port);
  EXPECT_EQ(ex->server.bind_address, def->server.bind_address);
  EXPECT_EQ(ex->robot.name, def->robot.name);
  EXPECT_EQ(ex->robot.type, def->robot.type);
  EXPECT_EQ(ex->safety.joint_limits.size(), def->safety.joint_limits.size());
  EXPECT_EQ(ex->safety.max_linear_speed_mps, def->safety.max_linear_speed_mps);
  EXPECT_EQ(ex->safety.estop_distance_m, def->safety.estop_distance_m);
  EXPECT_EQ(ex->rbac.guest_limits.session_duration_s, def->rbac.guest_limits.session_duration_s);
  EXPECT_EQ(ex->driver.sim.wheel_base_m, def->driver.sim.wheel_base_m);
  EXPECT_EQ(ex->security.audit.chain_secret_file, def->security.audit.chain_secret_file);
  EXPECT_EQ(ex->log_level, def->log_level);
}

TEST(ConfigDefault, DataDirFromEnvironment) {
  const char* old_rcand = std::getenv("RCAND_DATA_DIR");
  const char* old_xdg = std::getenv("XDG_DATA_HOME");
  const char* old_home = std::getenv("HOME");
  std::string s_rcand = old_rcand ? old_rcand : "", s_xdg = old_xdg ? old_xdg : "",
              s_home = old_home ? old_home : "";

  setenv("RCAND_DATA_DIR", "/srv/rcand", 1);
  EXPECT_EQ(*default_data_dir(), "/srv/rcand");
  unsetenv("RCAND_DATA_DIR");
  setenv("XDG_DATA_HOME", "/home/u/.data", 1);
  EXPECT_EQ(*default_data_dir(), "/home/u/.data/rcand");
  setenv("XDG_DATA_HOME", "relative/ignored", 1);
  setenv("HOME", "/home/u", 1);
  EXPECT_EQ(*default_data_dir(), "/home/u/.local/share/rcand");
  unsetenv("XDG_DATA_HOME");
  EXPECT_EQ(*default_data_dir(), "/home/u/.local/share/rcand");

  // A file without node.data_dir and no explicit default takes default_data_dir().
  auto r = parse_config_text(kHead);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->data_dir, "/home/u/.local/share/rcand");
  EXPECT_EQ(r->security.key_dir, "/home/u/.local/share/rcand/keys");

  auto restore = [](const char* n, const char* old, const std::string& v) {
    if (old)
      setenv(n, v.c_str(), 1);
    else
      unsetenv(n);
  };
  restore("RCAND_DATA_DIR", old_rcand, s_rcand);
  restore("XDG_DATA_HOME", old_xdg, s_xdg);
  restore("HOME", old_home, s_home);
}

// ------------------------------------------------------------------------------------------
// Good fixtures

TEST(ConfigFixtures, FullConfig) {
  auto r = load_config(kFixtures + "full.rcan.yaml");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const NodeConfig& c = *r;
  const std::string dir = std::filesystem::path(kFixtures).lexically_normal().string();
  auto in_dir = [&](const std::string& rel) {
    return (std::filesystem::path(dir) / rel).lexically_normal().string();
  };
  EXPECT_EQ(c.ruri, "rcan://registry.example.com/acme/rover-x/0123abcd");
  EXPECT_EQ(c.rrn, "RRN-000000000042");
  EXPECT_EQ(c.registry_url, "https://registry.example.com");
  EXPECT_EQ(c.data_dir, in_dir("state"));
  EXPECT_EQ(c.log_level, "debug");
  EXPECT_EQ(c.server.port, 9443);
  EXPECT_EQ(c.server.bind_address, "0.0.0.0");
  EXPECT_EQ(c.server.io_threads, 4u);
  EXPECT_TRUE(c.server.enable_mdns);
  EXPECT_TRUE(c.server.tls.enabled);
  EXPECT_EQ(c.server.tls.cert_file, in_dir("certs/robot.pem"));
  EXPECT_EQ(c.server.tls.key_file, "/etc/rcand/robot.key");
  EXPECT_EQ(c.server.limits.max_connections, 64u);
  EXPECT_EQ(c.security.key_dir, in_dir("keys"));
  EXPECT_EQ(c.security.audit.dir, "/var/lib/rcand/audit");
  EXPECT_EQ(c.security.audit.chain_secret_file, in_dir("secrets/audit.secret"));
  EXPECT_EQ(c.security.audit.sync_policy, audit::SyncPolicy::kInterval);
  EXPECT_EQ(c.security.audit.sync_interval_ms, 20u);
  EXPECT_EQ(c.security.audit.max_segment_bytes, 1048576u);
  EXPECT_EQ(c.security.audit.retention_max_age_days, 90u);
  ASSERT_EQ(c.security.jwt.issuers.size(), 2u);
  EXPECT_EQ(c.security.jwt.issuers[0].issuer, "https://auth.example.com");
  EXPECT_EQ(c.security.jwt.issuers[0].kind, "auto");
  EXPECT_EQ(c.security.jwt.issuers[0].key_file, in_dir("jwks.json"));
  EXPECT_EQ(c.security.jwt.issuers[1].kind, "hs256_secret");
  EXPECT_EQ(c.security.jwt.issuers[1].kid, "dev1");
  EXPECT_EQ(c.security.jwt.leeway_s, 30);
  EXPECT_EQ(c.security.replay_window_s, 60u);
  ASSERT_EQ(c.security.trusted_robot_keys.size(), 2u);
  EXPECT_EQ(c.security.trusted_robot_keys[1].ed25519_pub_file, in_dir("peers/p2.ed25519.pub"));
  ASSERT_EQ(c.security.injection_patterns.size(), 2u);
  EXPECT_FALSE(c.security.injection_patterns[0].regex);
  EXPECT_TRUE(c.security.injection_patterns[1].regex);
  EXPECT_TRUE(c.security.commitment.enabled);
  EXPECT_EQ(c.security.commitment.key_mode, "hybrid");
  EXPECT_TRUE(c.rbac.policy.user_arm);
  EXPECT_FALSE(c.rbac.policy.user_record);
  EXPECT_TRUE(c.rbac.policy.owner_safety_config);
  EXPECT_EQ(c.rbac.rate_limits.for_role(Role::kGuest), 5u);
  EXPECT_EQ(c.rbac.guest_limits.chat_rate.count, 20u);
  EXPECT_EQ(c.rbac.guest_limits.chat_rate.window_s, 3600u);
  EXPECT_EQ(c.rbac.guest_limits.query_rate.window_s, 1u);
  EXPECT_EQ(c.rbac.guest_limits.session_duration_s, 5400u);
  GuestLimits gl = c.rbac.guest_limits.to_guest_limits();
  EXPECT_EQ(gl.chat_per_minute, 1u);  // 20/hour rounds down, at least 1
  EXPECT_EQ(gl.query_per_minute, 120u);
  EXPECT_EQ(gl.concurrent_sessions, 1u);
  EXPECT_DOUBLE_EQ(c.safety.max_linear_speed_mps, 1.5);
  EXPECT_DOUBLE_EQ(c.safety.max_angular_speed_radps, 2.0);
  EXPECT_DOUBLE_EQ(*c.safety.estop_distance_m, 0.45);
  ASSERT_EQ(c.safety.joint_limits.size(), 2u);
  EXPECT_EQ(c.safety.joint_limits[1].name, "wrist");
  EXPECT_DOUBLE_EQ(*c.safety.workspace.z_max, 1.2);
  EXPECT_EQ(c.safety.speed_policy, LimitPolicy::kReject);
  EXPECT_EQ(c.safety.workspace_policy, LimitPolicy::kReject);
  EXPECT_TRUE(c.safety.estop_on_startup);
  EXPECT_EQ(c.safety.heartbeat_timeout_ms, 1500u);  // latency_budget_ms × 2
  EXPECT_EQ(c.safety.command_ttl_default_ms, 5000u);
  EXPECT_FALSE(c.safety.watchdog.enabled);
  EXPECT_EQ(c.safety.watchdog.timeout_s, 30u);
  // brain.* gates are aliases of agent.*
  ASSERT_EQ(c.agent.confidence_gates.size(), 3u);
  EXPECT_EQ(c.agent.confidence_gates[1].on_fail, GateOnFail::kAllow);  // log → allow
  ASSERT_EQ(c.agent.hitl_gates.size(), 2u);
  EXPECT_EQ(c.agent.hitl_gates[0].action_types,
            (std::vector<std::string>{"arm_deploy", "nav_goal"}));
  EXPECT_EQ(c.agent.hitl_gates[0].on_timeout, HitlOnTimeout::kAllow);
  EXPECT_EQ(c.agent.hitl_gates[0].authorized_roles, (std::vector<Role>{Role::kOwner}));
  EXPECT_EQ(c.agent.hitl_gates[1].action_types, (std::vector<std::string>{"arm_extend"}));
  EXPECT_EQ(c.agent.hitl_gates[1].auth_timeout_ms, 30000u);
  EXPECT_EQ(c.agent.hitl_gates[1].on_timeout, HitlOnTimeout::kBlock);  // escalate → block
  EXPECT_EQ(c.agent.hitl_gates[1].authorized_roles,
            (std::vector<Role>{Role::kOwner, Role::kCreator}));
  ASSERT_TRUE(c.agent.reactive_layer.has_value());
  EXPECT_EQ(c.agent.reactive_layer->timeout_ms, 50u);
  EXPECT_FALSE(c.agent.fast_layer.has_value());
  EXPECT_EQ(c.brain.max_tokens, 2048u);
  EXPECT_EQ(c.offline.grace_period_s, 600u);
  EXPECT_EQ(c.qos.max_retries, 5u);
  EXPECT_EQ(c.driver.sim.tick_hz, 100u);
  EXPECT_NE(c.kept.find("hardware_safety"), nullptr);
  EXPECT_NE(c.kept.find("messaging"), nullptr);
  EXPECT_TRUE(c.explicit_paths.key_dir && c.explicit_paths.audit_dir &&
              c.explicit_paths.chain_secret_file);
}

TEST(ConfigFixtures, OpenCastorStyle) {
  auto r = load_config(kFixtures + "opencastor.rcan.yaml", opts_with_dir());
  ASSERT_TRUE(r.ok()) << r.error().message;
  const NodeConfig& c = *r;
  EXPECT_EQ(c.rcan_version, "1.3.0");
  EXPECT_EQ(c.ruri, "rcan://local.rcan/opencastor/rover/0a1b2c3d");  // shorthand normalised
  EXPECT_EQ(c.robot.name, "castor-pi");
  EXPECT_EQ(c.robot.manufacturer, "OpenCastor");
  EXPECT_EQ(c.robot.type, "differential_drive");
  EXPECT_EQ(c.robot.dof, 2u);
  EXPECT_EQ(c.server.port, 8000);  // rcan_protocol.port
  EXPECT_TRUE(c.server.enable_mdns);
  EXPECT_EQ(c.capabilities,
            (std::vector<std::string>{"status", "chat", "nav", "teleop", "vision"}));
  EXPECT_EQ(c.registry_url, "https://registry.rcan.dev");
  EXPECT_TRUE(c.enable_jwt_false_ignored);
  ASSERT_EQ(c.warnings.size(), 1u);
  EXPECT_NE(c.warnings[0].find("always requires"), std::string::npos);
  EXPECT_EQ(c.agent.provider, "anthropic");
  EXPECT_EQ(c.agent.latency_budget_ms, 400u);
  EXPECT_EQ(c.safety.heartbeat_timeout_ms, 800u);
  EXPECT_DOUBLE_EQ(*c.agent.min_obstacle_m, 0.3);
  EXPECT_TRUE(c.safety.estop_on_startup);
  EXPECT_DOUBLE_EQ(*c.safety.obstacle_stop_cm, 30);
  for (const char* k : {"metadata", "physics", "drivers", "network", "reactive", "camera", "notes"})
    EXPECT_NE(c.kept.find(k), nullptr) << k;
}

TEST(ConfigFixtures, SeedGuestLimitsAtTopLevel) {
  auto r = load_config(kFixtures + "seed-guest-limits.rcan.yaml", opts_with_dir());
  ASSERT_TRUE(r.ok()) << r.error().message;
  const GuestLimitsConfig& g = r->rbac.guest_limits;
  EXPECT_EQ(g.chat_rate.count, 10u);
  EXPECT_EQ(g.chat_rate.window_s, 60u);
  EXPECT_EQ(g.query_rate.count, 30u);
  EXPECT_EQ(g.session_duration_s, 900u);
  EXPECT_EQ(g.concurrent_sessions, 3u);
  EXPECT_EQ(g.blocked.size(), 3u);
  EXPECT_EQ(g.to_guest_limits().chat_per_minute, 10u);
}

// ------------------------------------------------------------------------------------------
// Bad fixtures: each names its key path

TEST(ConfigErrors, Fixtures) {
  struct Case {
    const char* file;
    const char* field;
    const char* reason;
    const char* text;
  };
  const Case cases[] = {
      {"bad-unknown-top.yaml", "flavour", "unknown_key", "flavour: unknown key (line 3, column 1)"},
      {"bad-unknown-nested.yaml", "safety.max_linear_speed", "unknown_key", "unknown key"},
      {"bad-gate-typo.yaml", "agent.confidence_gates[1].on_fial", "unknown_key",
       "agent.confidence_gates[1].on_fial: unknown key"},
      {"bad-type.yaml", "safety.max_linear_speed_mps", "wrong_type",
       "safety.max_linear_speed_mps: expected a number, got string \"fast\""},
      {"bad-range.yaml", "security.replay_window_s", "out_of_range", "must be between 5 and 300"},
      {"bad-ruri.yaml", "ruri", "invalid_value", "invalid RURI"},
      {"bad-syntax.yaml", "", "malformed_yaml", "malformed YAML"},
      {"empty.yaml", "", "missing_key", "empty"},
      {"duplicate-key.yaml", "server.port", "duplicate_key", "server.port: duplicate key (line 5"},
      {"bomb.yaml", "", "too_large", "too large"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.file);
    auto start = std::chrono::steady_clock::now();
    auto r = load_config(kFixtures + c.file, opts_with_dir());
    auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(
        std::chrono::steady_clock::now() - start);
    EXPECT_LT(ms.count(), 2000);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kSchemaValidationFailed);
    if (std::string(c.file) != "bomb.yaml") {
      EXPECT_EQ(r.error().field, c.field);
    }
    EXPECT_EQ(r.error().reason, c.reason) << r.error().message;
    EXPECT_NE(r.error().message.find(c.text), std::string::npos) << r.error().message;
    // load_config prefixes the file name
    EXPECT_EQ(r.error().message.rfind(kFixtures + c.file + ": ", 0), 0u) << r.error().message;
  }
}

// ------------------------------------------------------------------------------------------
// Inline bad inputs

TEST(ConfigErrors, UnknownKeys) {
  expect_error(parse("colour: red\n"), "colour", "unknown_key");
  expect_error(parse("server:\n  prot: 1\n"), "server.prot", "unknown_key");
  expect_error(parse("server:\n  limits:\n    max_body: 1\n"), "server.limits.max_body",
               "unknown_key");
  expect_error(
      parse("agent:\n  hitl_gates:\n    - {action_types: [a], require_auth: true, notfy: [x]}\n"),
      "agent.hitl_gates[0].notfy", "unknown_key");
  expect_error(parse("bridge:\n  type: ros2\n  topic: /x\n"), "bridge.topic", "unknown_key");
  expect_error(parse("capabilities:\n  motion: [walk]\n  flying: [hover]\n"), "capabilities.flying",
               "unknown_key");
  expect_error(parse("robot:\n  dof: 2\n  wheels: 4\n"), "robot.wheels", "unknown_key");
  expect_error(parse("security:\n  jwt:\n    issuers:\n      - {issuer: a, key_file: b, alg: x}\n"),
               "security.jwt.issuers[0].alg", "unknown_key");
  // Keys needing quoting are shown in brackets.
  expect_error(parse("\"we.ird key\": 1\n"), "[\"we.ird key\"]", "unknown_key");
  // Merge keys are refused rather than silently half-supported.
  expect_error(parse("safety:\n  <<: {local_safety_wins: true}\n"), "safety[\"<<\"]",
               "unknown_key");
}

TEST(ConfigErrors, WrongTypes) {
  Error e = expect_error(parse("server:\n  port: \"8080\"\n"), "server.port", "wrong_type");
  EXPECT_NE(e.message.find("expected an integer, got string \"8080\""), std::string::npos);
  expect_error(parse("server:\n  port: 80.5\n"), "server.port", "wrong_type");
  expect_error(parse("server: 8080\n"), "server", "wrong_type");
  expect_error(parse("server:\n  port: [1]\n"), "server.port", "wrong_type");
  expect_error(parse("server:\n  enable_mdns: maybe\n"), "server.enable_mdns", "wrong_type");
  e = expect_error(parse("robot:\n  name: 42\n"), "robot.name", "wrong_type");
  EXPECT_NE(e.message.find("quote it"), std::string::npos);
  expect_error(parse("robot:\n  name: no\n"), "robot.name", "wrong_type");  // the Norway problem
  expect_error(parse("robot:\n  name:\n"), "robot.name", "wrong_type");     // null
  expect_error(parse("capabilities: status\n"), "capabilities", "wrong_type");
  expect_error(parse("capabilities: [status, [nested]]\n"), "capabilities[1]", "wrong_type");
  expect_error(parse("agent:\n  hitl_gates:\n    - {action_types: [a], require_auth: \"true\"}\n"),
               "agent.hitl_gates[0].require_auth", "wrong_type");
  expect_error(parse("safety:\n  max_linear_speed_mps: .inf\n"), "safety.max_linear_speed_mps",
               "out_of_range");
  expect_error(parse("safety:\n  max_linear_speed_mps: !!float 1\n"), "safety.max_linear_speed_mps",
               "wrong_type");
  e = expect_error(parse_config_text("rcan_version: 1.2\nruri: rcan://local.rcan/a1/b1/0a1b2c3d\n",
                                     opts_with_dir()),
                   "rcan_version", "wrong_type");
  EXPECT_NE(e.message.find("got number 1.2"), std::string::npos) << e.message;
  expect_error(parse_config_text("- a\n- b\n", opts_with_dir()), "", "wrong_type");
  expect_error(parse("rrn: 42\n"), "rrn", "wrong_type");
}

TEST(ConfigErrors, Ranges) {
  expect_error(parse("server:\n  port: 0\n"), "server.port", "out_of_range");
  expect_error(parse("server:\n  port: 65536\n"), "server.port", "out_of_range");
  expect_error(parse("server:\n  port: 99999999999999999999999\n"), "server.port", "out_of_range");
  expect_error(parse("safety:\n  max_linear_speed_mps: 0\n"), "safety.max_linear_speed_mps",
               "out_of_range");
  expect_error(parse("safety:\n  max_angular_speed_radps: -1\n"), "safety.max_angular_speed_radps",
               "out_of_range");
  expect_error(parse("security:\n  replay_window_s: 301\n"), "security.replay_window_s",
               "out_of_range");
  expect_error(parse("agent:\n  confidence_gates:\n    - {scope: control, min_confidence: 1.5, "
                     "on_fail: block}\n"),
               "agent.confidence_gates[0].min_confidence", "out_of_range");
  expect_error(parse("agent:\n  confidence_gates:\n    - {scope: control, min_confidence: 0.5, "
                     "on_fail: ignore}\n"),
               "agent.confidence_gates[0].on_fail", "invalid_value");
  expect_error(parse("agent:\n  hitl_gates:\n    - {action_types: [a], require_auth: true, "
                     "auth_timeout_ms: 0}\n"),
               "agent.hitl_gates[0].auth_timeout_ms", "out_of_range");
  expect_error(parse("watchdog:\n  timeout_s: 301\n"), "watchdog.timeout_s", "out_of_range");
  expect_error(parse("safety:\n  joint_limits:\n    - {min: 1, max: -1}\n"),
               "safety.joint_limits[0].max", "out_of_range");
  expect_error(parse("safety:\n  workspace: {x_min: 1, x_max: 1, y_min: 0, y_max: 1}\n"),
               "safety.workspace.x_max", "out_of_range");
  expect_error(parse("safety:\n  workspace: {x_min: 0, x_max: 1}\n"), "safety.workspace.y_min",
               "missing_key");
  expect_error(parse("safety:\n  max_speed_override: 1.5\n"), "safety.max_speed_override",
               "out_of_range");
  expect_error(parse("driver:\n  sim: {tick_hz: 10, telemetry_hz: 20}\n"),
               "driver.sim.telemetry_hz", "out_of_range");
  expect_error(parse("bridge:\n  ros_domain_id: 233\n"), "bridge.ros_domain_id", "out_of_range");
  expect_error(parse("mqtt:\n  estop_qos: -1\n"), "mqtt.estop_qos", "out_of_range");
  expect_error(parse("mqtt:\n  estop_qos: 3\n"), "mqtt.estop_qos", "out_of_range");
}

TEST(ConfigMqtt, EstopSubscriptionQos) {
  auto dflt = parse("mqtt:\n  enabled: true\n");
  ASSERT_TRUE(dflt.ok()) << dflt.error().message;
  EXPECT_EQ(dflt->mqtt.estop_qos, 1);
  auto two = parse("mqtt:\n  enabled: true\n  estop_qos: 2\n");
  ASSERT_TRUE(two.ok()) << two.error().message;
  EXPECT_EQ(two->mqtt.estop_qos, 2);
  auto zero = parse("mqtt:\n  enabled: true\n  estop_qos: 0\n  max_qos: 1\n");
  ASSERT_TRUE(zero.ok()) << zero.error().message;
  EXPECT_EQ(zero->mqtt.estop_qos, 0);
}

TEST(ConfigMqtt, ReplyQos) {
  auto dflt = parse("mqtt:\n  enabled: true\n");
  ASSERT_TRUE(dflt.ok()) << dflt.error().message;
  EXPECT_EQ(dflt->mqtt.reply_qos, 1);
  auto zero = parse("mqtt:\n  enabled: true\n  reply_qos: 0\n");
  ASSERT_TRUE(zero.ok()) << zero.error().message;
  EXPECT_EQ(zero->mqtt.reply_qos, 0);
  expect_error(parse("mqtt:\n  reply_qos: 2\n"), "mqtt.reply_qos", "out_of_range");
  expect_error(parse("mqtt:\n  reply_qos: -1\n"), "mqtt.reply_qos", "out_of_range");
}

TEST(ConfigMqtt, MaxQos) {
  auto dflt = parse("mqtt:\n  enabled: true\n");
  ASSERT_TRUE(dflt.ok()) << dflt.error().message;
  EXPECT_EQ(dflt->mqtt.max_qos, 2);
  auto one = parse("mqtt:\n  enabled: true\n  max_qos: 1\n");
  ASSERT_TRUE(one.ok()) << one.error().message;
  EXPECT_EQ(one->mqtt.max_qos, 1);
  expect_error(parse("mqtt:\n  max_qos: 0\n"), "mqtt.max_qos", "out_of_range");
  expect_error(parse("mqtt:\n  max_qos: 3\n"), "mqtt.max_qos", "out_of_range");
  // An estop subscription above the cap is a contradiction, not something to clamp silently.
  expect_error(parse("mqtt:\n  max_qos: 1\n  estop_qos: 2\n"), "mqtt.estop_qos", "out_of_range");
}

TEST(ConfigErrors, Semantics) {
  expect_error(parse("safety:\n  local_safety_wins: false\n"), "safety.local_safety_wins",
               "invalid_value");
  expect_error(parse("driver:\n  type: gazebo\n"), "driver.type", "invalid_value");
  expect_error(parse("agent:\n  confidence_gates:\n"
                     "    - {scope: control, min_confidence: 0.5, on_fail: block}\n"
                     "    - {scope: control, min_confidence: 0.7, on_fail: block}\n"),
               "agent.confidence_gates[1].scope", "invalid_value");
  expect_error(parse("agent:\n  confidence_gates:\n    - {scope: control, min_confidence: 0.5}\n"),
               "agent.confidence_gates[0].on_fail", "missing_key");
  expect_error(parse("agent:\n  hitl_gates:\n    - {action_types: [a]}\n"),
               "agent.hitl_gates[0].require_auth", "missing_key");
  expect_error(parse("agent:\n  hitl_gates:\n    - {action_types: [a], require_auth: true, "
                     "authorized_roles: [OWNER, LEASEE]}\n"),
               "agent.hitl_gates[0].authorized_roles[1]", "invalid_value");
  expect_error(
      parse(
          "agent:\n  hitl_gates:\n    - {action_types: [a], action_type: b, require_auth: true}\n"),
      "agent.hitl_gates[0].action_type", "invalid_value");
  expect_error(parse("agent:\n  hitl_gates:\n    - {require_auth: true}\n"),
               "agent.hitl_gates[0].action_types", "missing_key");
  expect_error(parse("agent:\n  hitl_gates: []\nbrain:\n  hitl_gates: []\n"), "brain.hitl_gates",
               "invalid_value");
  expect_error(parse("server: {port: 8080}\nrcan_protocol: {port: 8000}\n"), "rcan_protocol.port",
               "invalid_value");
  expect_error(parse("safety: {max_linear_speed_mps: 1, max_linear_x: 2}\n"), "safety.max_linear_x",
               "invalid_value");
  expect_error(parse("safety: {emergency_stop_distance: 0.3, estop_distance_mm: 500}\n"),
               "safety.estop_distance_mm", "invalid_value");
  expect_error(parse("guest_limits: {chat_rate: 10/fortnight}\n"), "guest_limits.chat_rate",
               "invalid_value");
  expect_error(parse("guest_limits: {chat_rate: lots}\n"), "guest_limits.chat_rate",
               "invalid_value");
  expect_error(parse("guest_limits: {session_duration: 15 parsecs}\n"),
               "guest_limits.session_duration", "invalid_value");
  expect_error(parse("guest_limits: {}\nrbac: {guest_limits: {}}\n"), "guest_limits",
               "invalid_value");
  expect_error(parse("server:\n  tls: {enabled: true, key_file: k.pem}\n"), "server.tls.cert_file",
               "missing_key");
  expect_error(parse("server:\n  bind: \"0.0.0.0; rm -rf\"\n"), "server.bind", "invalid_value");
  expect_error(parse("security:\n  injection:\n    patterns: [{regex: \"(unclosed\"}]\n"),
               "security.injection.patterns[0].regex", "invalid_value");
  expect_error(parse("security:\n  trusted_robot_keys: [{name: a}]\n"),
               "security.trusted_robot_keys[0]", "missing_key");
  expect_error(parse("security:\n  trusted_signer_keys: [{name: a}]\n"),
               "security.trusted_signer_keys[0]", "missing_key");
  expect_error(parse("security:\n  trusted_robot_keys: [{name: a, ed25519_pub_file: a.pub}]\n"
                     "  trusted_signer_keys: [{name: a, ed25519_pub_file: b.pub}]\n"),
               "security.trusted_signer_keys[0].name", "invalid_value");
  expect_error(parse("agent:\n  layers:\n    fast: {url: ftp://x}\n"), "agent.layers.fast.url",
               "invalid_value");
  expect_error(parse("rrn: RRN-12\n"), "rrn", "invalid_value");
  expect_error(parse("metadata: {robot_uuid: not-a-uuid}\n"), "metadata.robot_uuid",
               "invalid_value");
  expect_error(parse("capabilities: [Status]\n"), "capabilities[0]", "invalid_value");
}

TEST(ConfigErrors, Identity) {
  ConfigOptions o = opts_with_dir();
  expect_error(parse_config_text("rcan_version: \"1.2\"\n", o), "ruri", "missing_key");
  expect_error(parse_config_text("ruri: rcan://local.rcan/a1/b1/0a1b2c3d\n", o), "rcan_version",
               "missing_key");
  expect_error(
      parse_config_text("rcan_version: \"v1\"\nruri: rcan://local.rcan/a1/b1/0a1b2c3d\n", o),
      "rcan_version", "invalid_value");
  expect_error(parse_config_text("rcan_version: \"1.2\"\nruri: rcan://local.rcan/a1/b1/zz\n", o),
               "ruri", "invalid_value");
  expect_error(
      parse_config_text("rcan_version: \"1.2\"\nruri: rcan://local.rcan/a1/b1/0a1b2c3d/arm\n", o),
      "ruri", "invalid_value");
  expect_error(parse_config_text(
                   "rcan_version: \"1.2\"\nruri: rcan://local.rcan/discovered/10.0.0.1:8080\n", o),
               "ruri", "invalid_value");
  expect_error(parse_config_text("rcan_version: \"1.2\"\nruri: rcan://local.rcan/a1/b1/0a1b2c3d\n"
                                 "metadata: {ruri: rcan://local.rcan/a1/b1/0a1b2c3d}\n",
                                 o),
               "metadata.ruri", "invalid_value");
  // metadata.ruri alone is enough, and version strings of both styles pass.
  auto r = parse_config_text(
      "rcan_version: \"1.3.0-rc.1\"\nmetadata: {ruri: rcan://a1.b1.0a1b2c3d}\n", o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->ruri, "rcan://local.rcan/a1/b1/0a1b2c3d");
  // Shorthand with a device id that is not hex (found by config_fuzz): its expanded form is a
  // RURI the parser accepts again, so it loads, normalised.
  auto sh =
      parse_config_text("rcan_version: \"1.2\"\nruri: rcan://opencastor.rover.0a1bj2c3d\n", o);
  ASSERT_TRUE(sh.ok()) << sh.error().message;
  EXPECT_EQ(sh->ruri, "rcan://local.rcan/opencastor/rover/0a1bj2c3d");
  // A bad substituted device id is refused.
  o.device_id = "XYZ";
  expect_error(
      parse_config_text("rcan_version: \"1.2\"\nruri: rcan://local.rcan/a1/b1/{device_id}\n", o),
      "ruri", "invalid_value");
}

TEST(ConfigErrors, MalformedAndEmpty) {
  ConfigOptions o = opts_with_dir();
  expect_error(parse_config_text("", o), "", "missing_key");
  expect_error(parse_config_text("   \n# c\n", o), "", "missing_key");
  expect_error(parse_config_text("---\n...\n", o), "", "missing_key");
  Error e = expect_error(parse_config_text("a: [1, 2\n", o), "", "malformed_yaml");
  EXPECT_NE(e.message.find("line"), std::string::npos);
  expect_error(parse_config_text("a: *nope\n", o), "", "malformed_yaml");
  // (yaml-cpp 0.7 accepts a double-quoted scalar left open at the end of the text.)
  expect_error(parse_config_text(std::string(kHead) + "---\nrcan_version: \"1.2\"\n", o), "",
               "malformed_yaml");
  expect_error(parse_config_text(std::string("a: b\0c", 6), o), "", "malformed_yaml");
  expect_error(parse_config_text("just a string\n", o), "", "wrong_type");
  // A stray flow token at document level: yaml-cpp 0.7's LoadAll() would loop forever here.
  for (const char* t : {",\n", ", a\n", "# c\n, Bridge: x\n", "]\n", "}\n"}) {
    auto start = std::chrono::steady_clock::now();
    auto r = parse_config_text(t, o);
    ASSERT_FALSE(r.ok()) << t;
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  }
  // Invalid UTF-8 in a value.
  expect_error(parse(std::string("robot:\n  name: \"\xff\xfe\"\n")), "robot.name", "invalid_value");
}

TEST(ConfigErrors, DuplicateKeys) {
  Error e = expect_error(parse("robot:\n  name: a\n  name: b\n"), "robot.name", "duplicate_key");
  EXPECT_NE(e.message.find("line 5"), std::string::npos) << e.message;
  expect_error(parse_config_text(std::string(kHead) + "rcan_version: \"1.3\"\n", opts_with_dir()),
               "rcan_version", "duplicate_key");
  expect_error(parse("bridge:\n  launch_args: {a: 1, a: 2}\n"), "bridge.launch_args.a",
               "duplicate_key");
  expect_error(parse("agent:\n  confidence_gates:\n    - {scope: a, scope: b, min_confidence: 1, "
                     "on_fail: block}\n"),
               "agent.confidence_gates[0].scope", "duplicate_key");
}

// ------------------------------------------------------------------------------------------
// Hostile YAML

TEST(ConfigHostile, BillionLaughsFinishesQuickly) {
  // 10^9 leaves through nine levels of aliases, in a free-form block and in a typed list.
  for (const char* where : {"bridge:\n  launch_args:\n", "notes:\n", "connection:\n"}) {
    std::string text = std::string(kHead) + where;
    text +=
        "    a: &a "
        "[\"lol\",\"lol\",\"lol\",\"lol\",\"lol\",\"lol\",\"lol\",\"lol\",\"lol\",\"lol\"]\n";
    char prev = 'a';
    for (char c = 'b'; c <= 'j'; ++c) {
      text += std::string("    ") + c + ": &" + c + " [";
      for (int i = 0; i < 10; ++i) text += std::string(i ? "," : "") + "*" + prev;
      text += "]\n";
      prev = c;
    }
    auto start = std::chrono::steady_clock::now();
    auto r = parse_config_text(text, opts_with_dir());
    auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(
        std::chrono::steady_clock::now() - start);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().reason, "too_large") << r.error().message;
    EXPECT_LT(ms.count(), 2000);
  }
  std::string caps = std::string(kHead) + "metadata:\n  tags: &t [";
  for (int i = 0; i < 1000; ++i) caps += std::string(i ? "," : "") + "s";
  caps += "]\ncapabilities:\n  motion: *t\n  sensing: *t\n  io: *t\n  safety: *t\n";
  auto ok = parse_config_text(caps, opts_with_dir());
  EXPECT_TRUE(ok.ok()) << ok.error().message;  // 5000 nodes: legitimate aliases still work
}

TEST(ConfigHostile, RecursiveAliasAndDeepNesting) {
  auto start = std::chrono::steady_clock::now();
  for (const char* body : {"bridge:\n  launch_args: &x {a: *x}\n", "notes: &x [*x]\n",
                           "agent_roster:\n  - {name: a, enabled: true, config: &x {k: [*x]}}\n"}) {
    auto cyc = parse(body);
    ASSERT_FALSE(cyc.ok()) << body;
    EXPECT_EQ(cyc.error().reason, "too_large") << cyc.error().message;
    EXPECT_NE(cyc.error().message.find("nesting too deep"), std::string::npos);
  }
  auto r = parse_config_text(std::string(100000, '['), opts_with_dir());
  ASSERT_FALSE(r.ok());
  std::string nested =
      std::string(kHead) + "notes: " + std::string(200, '[') + std::string(200, ']') + "\n";
  r = parse_config_text(nested, opts_with_dir());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().reason, "too_large");
  auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() -
                                                                  start);
  EXPECT_LT(ms.count(), 3000);
}

TEST(ConfigHostile, SizeCap) {
  std::string big = std::string(kHead) + "notes: \"" + std::string(kMaxConfigBytes, 'x') + "\"\n";
  auto r = parse_config_text(big, opts_with_dir());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().reason, "too_large");
  test::TempDir dir;
  {
    std::ofstream f(dir.file("big.yaml"));
    f << big;
  }
  r = load_config(dir.file("big.yaml"), opts_with_dir());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().reason, "too_large");
  r = load_config(dir.path(), opts_with_dir());  // a directory
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().reason, "io_error");
  r = load_config(dir.file("missing.yaml"), opts_with_dir());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().reason, "io_error");
}

// ------------------------------------------------------------------------------------------
// Overrides and paths

TEST(ConfigOverrides, PortAndDataDir) {
  auto r = default_config("/tmp/rcand-one", "0a1b2c3d");
  ASSERT_TRUE(r.ok());
  NodeConfig c = *r;
  ASSERT_TRUE(apply_overrides(c, 9090, std::string("/tmp/rcand-two")).ok());
  EXPECT_EQ(c.server.port, 9090);
  // --port 0: any free port (tests run several nodes at once).
  ASSERT_TRUE(apply_overrides(c, 0, std::nullopt).ok());
  EXPECT_EQ(c.server.port, 0);
  ASSERT_TRUE(apply_overrides(c, 9090, std::nullopt).ok());
  EXPECT_EQ(c.data_dir, "/tmp/rcand-two");
  EXPECT_EQ(c.security.key_dir, "/tmp/rcand-two/keys");
  EXPECT_EQ(c.security.audit.dir, "/tmp/rcand-two/audit");
  EXPECT_EQ(c.security.audit.chain_secret_file, "/tmp/rcand-two/audit.secret");
  EXPECT_EQ(c.ruri, r->ruri);  // identity does not move with the data dir

  // Out of range or empty: refused, config unchanged.
  Status s = apply_overrides(c, 70000, std::nullopt);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "server.port");
  EXPECT_FALSE(apply_overrides(c, -1, std::nullopt).ok());
  EXPECT_FALSE(apply_overrides(c, std::nullopt, std::string()).ok());
  EXPECT_EQ(c.server.port, 9090);
  ASSERT_TRUE(apply_overrides(c, std::nullopt, std::nullopt).ok());
  EXPECT_EQ(c.server.port, 9090);

  // A relative --data-dir becomes absolute.
  ASSERT_TRUE(apply_overrides(c, std::nullopt, std::string("rel/dir")).ok());
  EXPECT_TRUE(std::filesystem::path(c.data_dir).is_absolute());
}

TEST(ConfigOverrides, ExplicitPathsStay) {
  auto r = load_config(kFixtures + "full.rcan.yaml");
  ASSERT_TRUE(r.ok()) << r.error().message;
  NodeConfig c = *r;
  std::string key_dir = c.security.key_dir;
  ASSERT_TRUE(apply_overrides(c, std::nullopt, std::string("/srv/other")).ok());
  EXPECT_EQ(c.data_dir, "/srv/other");
  EXPECT_EQ(c.security.key_dir, key_dir);
  EXPECT_EQ(c.security.audit.dir, "/var/lib/rcand/audit");

  // Only some explicit: the rest follow the data dir.
  auto p = parse("security:\n  key_dir: /etc/rcand/keys\n");
  ASSERT_TRUE(p.ok()) << p.error().message;
  NodeConfig q = *p;
  ASSERT_TRUE(apply_overrides(q, std::nullopt, std::string("/srv/x")).ok());
  EXPECT_EQ(q.security.key_dir, "/etc/rcand/keys");
  EXPECT_EQ(q.security.audit.dir, "/srv/x/audit");
  EXPECT_EQ(q.security.audit.chain_secret_file, "/srv/x/audit.secret");
}

TEST(ConfigPaths, RelativeAndHome) {
  ConfigOptions o = opts_with_dir();
  o.base_dir = "/etc/rcand";
  const char* home = std::getenv("HOME");
  std::string saved = home ? home : "";
  setenv("HOME", "/home/robot", 1);
  auto r =
      parse_config_text(std::string(kHead) +
                            "node: {data_dir: ../../var/lib/rcand}\n"
                            "security:\n  key_dir: ~/keys\n  audit: {chain_secret_file: secret}\n",
                        o);
  if (home)
    setenv("HOME", saved.c_str(), 1);
  else
    unsetenv("HOME");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->data_dir, "/var/lib/rcand");
  EXPECT_EQ(r->security.key_dir, "/home/robot/keys");
  EXPECT_EQ(r->security.audit.chain_secret_file, "/etc/rcand/secret");
  EXPECT_EQ(r->security.audit.dir, "/var/lib/rcand/audit");
}

TEST(ConfigScalars, YamlForms) {
  auto r = parse(
      "server:\n  port: 0x1F90\n  enable_mdns: yes\nsafety:\n  max_linear_speed_mps: 1\n"
      "  max_angular_speed_radps: .5\n  estop_on_startup: False\n"
      "robot:\n  name: \"no\"\n  model: 'x'\n  description: |\n    multi\n    line\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->server.port, 8080);
  EXPECT_TRUE(r->server.enable_mdns);
  EXPECT_DOUBLE_EQ(r->safety.max_linear_speed_mps, 1.0);
  EXPECT_DOUBLE_EQ(r->safety.max_angular_speed_radps, 0.5);
  EXPECT_FALSE(r->safety.estop_on_startup);
  EXPECT_EQ(r->robot.name, "no");
  EXPECT_EQ(r->robot.description, "multi\nline\n");
  // Gates: log → allow; brain.* alias; a single action_type string.
  r = parse("brain:\n  confidence_gates: [{scope: nav, min_confidence: 0.7, on_fail: log}]\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->agent.confidence_gates.size(), 1u);
  EXPECT_EQ(r->agent.confidence_gates[0].on_fail, GateOnFail::kAllow);
  EXPECT_EQ(gate_on_fail_name(r->agent.confidence_gates[0].on_fail), "allow");
  // Rates and durations in several spellings.
  r = parse("guest_limits: {chat_rate: 5 per second, query_rate: 12, session_duration: 2 hours}\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->rbac.guest_limits.chat_rate.window_s, 1u);
  EXPECT_EQ(r->rbac.guest_limits.query_rate.count, 12u);
  EXPECT_EQ(r->rbac.guest_limits.query_rate.window_s, 60u);
  EXPECT_EQ(r->rbac.guest_limits.session_duration_s, 7200u);
  r = parse("guest_limits: {session_duration: 900}\n");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->rbac.guest_limits.session_duration_s, 900u);
}

}  // namespace
}  // namespace rcan::config
