// Node configuration: `.rcan.yaml` loaded and strictly validated into a typed NodeConfig.
//
// The file format is the union of the two published RCAN config styles (the profile style of
// schemas/rcan-config.json used by spec/profiles/*.rcan.yaml, and the OpenCastor style of
// schemas/rcan-config.schema.json) where they overlap, plus this node's own blocks (`node`,
// `server`, `security`, `rbac`, `driver`). docs/CONFIG.md lists every key, its type, default
// and source.
//
// Validation is strict: an unknown key, a duplicate key, a wrong type, a value out of range
// or an inconsistent pair of aliases stops loading. Errors are values (never exceptions):
// ErrorCode::kSchemaValidationFailed (kMalformedJson for YAML syntax errors is NOT used — the
// code is always kSchemaValidationFailed), with
//   field   = the key path, e.g. "agent.confidence_gates[1].on_fial"
//   message = "<path>: <what is wrong> (line L, column C)"
//   reason  = unknown_key | duplicate_key | wrong_type | out_of_range | invalid_value |
//             missing_key | malformed_yaml | too_large | io_error
// The first error stops loading.
//
// Hostile input: the text is capped at kMaxConfigBytes, the walk visits at most
// kMaxConfigNodes nodes (alias expansion counts every time an alias is walked, so a
// "billion laughs" document fails fast) and free-form blocks nest at most kMaxFreeDepth.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "config/driver_config.h"
#include "config/fleet_config.h"
#include "config/safety_types.h"
#include "rcan/audit/audit_log.h"
#include "rcan/crypto/jwt.h"
#include "rcan/json.h"
#include "rcan/result.h"
#include "rcan/roles.h"
#include "rcan/ruri.h"

namespace rcan::config {

inline constexpr size_t kMaxConfigBytes = 1 << 20;  // 1 MiB of YAML text
inline constexpr size_t kMaxConfigNodes = 100000;   // YAML nodes walked (aliases re-counted)
inline constexpr size_t kMaxFreeDepth = 16;         // nesting inside free-form blocks

// ---------------------------------------------------------------------------------------
// Blocks. A member's initializer is its key's default (a default that is computed, e.g. from
// another key, is computed by the key's row in blocks/*.cpp, which read the keys).

struct TlsConfig {
  bool enabled = false;
  std::string cert_file;  // PEM chain; required when enabled
  std::string key_file;   // PEM private key; required when enabled
};

struct ServerLimits {
  uint64_t max_body_bytes = 64 * 1024;
  uint64_t max_header_bytes = 8 * 1024;
  uint32_t read_timeout_ms = 10000;
  uint32_t idle_timeout_ms = 60000;
  uint32_t max_connections = 1024;
  uint32_t max_connections_per_address = 64;  // 0 = no per-address limit
  uint32_t reserved_connections = 16;         // over max_connections, for a stop only
  uint32_t unauthenticated_idle_timeout_ms = 5000;
};

struct ServerConfig {
  uint16_t port = 8080;                    // server.port | rcan_protocol.port
  std::string bind_address = "127.0.0.1";  // server.bind; "0.0.0.0" to expose on a robot
  uint32_t io_threads = 2;
  bool enable_mdns = false;  // server.enable_mdns | rcan_protocol.enable_mdns
  TlsConfig tls;
  ServerLimits limits;
};

// `dashboard` (docs/CONFIG.md §dashboard, docs/DASHBOARD.md §Robots): the other rcand nodes the
// dashboard's Robots view lists, with their state, and can stop.
struct DashboardConfig {
  std::vector<std::string> robots;  // http(s)://host[:port] of each node, at most 64, no repeats
  std::string ca_file;              // for https:// robots (default: the system's trust anchors)
  bool mdns = false;                // also list the rcand nodes announcing _rcan._tcp (no stop)
  uint32_t poll_ms = 2000;          // how often each robot's state is read
  uint32_t stop_timeout_ms = 3000;  // a relayed ESTOP's answer
};

struct GrpcConfig {  // `grpc` (docs/CONFIG.md, docs/TRANSPORT.md §gRPC)
  bool enabled = false;
  uint16_t port = 8081;                    // 0 = any free port (logged)
  std::string bind_address = "127.0.0.1";  // grpc.bind
  TlsConfig tls;
  std::string client_ca_file;  // grpc.tls.client_ca_file: require client certificates
  uint32_t max_streams = 64;
  std::string module;  // grpc.module: path of librcand_grpc.so (default: beside rcand)
};

struct UdpConfig {  // `udp` (docs/CONFIG.md, docs/TRANSPORT.md §UDP)
  bool enabled = false;
  uint16_t port = 8082;                    // 0 = any free port (logged)
  std::string bind_address = "127.0.0.1";  // udp.bind; 0.0.0.0 to hear broadcast DISCOVER
  bool heartbeat = true;                   // per-session keys in GRANTED, HEARTBEAT datagrams
  bool discovery = true;                   // DISCOVER → ANNOUNCE
  uint32_t discovery_per_source_per_min = 30;
};

struct AuditConfig {
  std::string dir;                // default <data_dir>/audit
  std::string chain_secret_file;  // default <data_dir>/audit.secret
  audit::SyncPolicy sync_policy = audit::SyncPolicy::kPerGroup;
  uint32_t sync_interval_ms = 2;
  uint64_t max_segment_bytes = 16ull << 20;  // small disks first (docs/CONFIG.md)
  uint64_t retention_max_bytes = 0;          // 0 = unlimited
  uint32_t retention_max_age_days = 0;       // 0 = unlimited
};

struct JwtConfig {
  std::vector<jwt::TrustStore::IssuerConfig> issuers;  // {issuer, key_file, kind, kid}
  int64_t leeway_s = 60;
};

struct TrustedRobotKey {
  std::string name;
  std::string mldsa65_pub_file;  // at least one of the two files is set
  std::string ed25519_pub_file;
};

struct InjectionPattern {
  std::string text;  // case-insensitive substring, or an ECMAScript regex when `regex`
  bool regex = false;
};

struct CommitmentConfig {  // security.commitment (profile schema; kept, unused)
  bool enabled = false;
  std::string key_mode = "classical";  // classical | quantum | hybrid
  std::optional<double> qber_threshold;
};

struct SecurityConfig {
  std::string key_dir;  // default <data_dir>/keys
  AuditConfig audit;
  JwtConfig jwt;
  uint32_t replay_window_s = 30;  // 5..300
  uint32_t msg_id_cache_size = 10000;
  // Tokens failing verification one peer address may send per minute (0: no limit).
  uint32_t failed_auth_per_address_per_minute = kDefaultFailedAuthPerAddressPerMinute;
  std::vector<TrustedRobotKey> trusted_robot_keys;
  // Operators' and integrators' message-signing keys (rcan-py clients sign with their own
  // key): a verified signature from one of these is a human/software signer, not a robot.
  std::vector<TrustedRobotKey> trusted_signer_keys;
  std::vector<InjectionPattern> injection_patterns;  // defaults (unless disabled) + configured
  CommitmentConfig commitment;
};

// "10/minute" → {10, 60}.
struct RateSpec {
  uint32_t count = 0;
  uint32_t window_s = 60;
  double per_minute() const { return window_s == 0 ? 0.0 : count * 60.0 / window_s; }
};

struct GuestLimitsConfig {  // seed §6.3; the defaults are rcan::GuestLimits's (roles.h)
  RateSpec chat_rate{GuestLimits{}.chat_per_minute, 60};
  RateSpec query_rate{GuestLimits{}.query_per_minute, 60};
  uint32_t session_duration_s = GuestLimits{}.session_seconds;
  uint32_t concurrent_sessions = GuestLimits{}.concurrent_sessions;
  std::vector<std::string> capabilities = GuestLimits{}.capabilities;
  std::vector<std::string> blocked = GuestLimits{}.blocked;
  // The roles.h shape. Rates are converted to whole events per minute, rounded down, at
  // least 1 when the configured count is non-zero.
  GuestLimits to_guest_limits() const;
};

struct RateLimits {  // per principal per minute, 0 = unlimited (PROFILE §5)
  uint32_t guest = 10;
  uint32_t user = 100;
  uint32_t leasee = 500;
  uint32_t owner = 1000;
  uint32_t creator = 0;
  uint32_t for_role(Role r) const;
};

struct RbacConfig {
  RolePolicy
      policy;  // rbac.grants.{user_arm,user_record,leasee_training,leasee_diagnostics,owner_safety_config}
  RateLimits rate_limits;
  GuestLimitsConfig guest_limits;  // rbac.guest_limits | top-level guest_limits (seed shape)
};

enum class GateOnFail { kBlock, kEscalate, kAllow };  // "log" is read as kAllow
enum class HitlOnTimeout { kBlock, kAllow };          // "escalate" is read as kBlock

struct ConfidenceGate {
  std::string scope;  // control, nav, admin, observe, configure, safety, … (unique)
  double min_confidence = 0;
  GateOnFail on_fail = GateOnFail::kBlock;
};

struct HitlGate {
  std::vector<std::string> action_types;  // action_types | action_type
  bool require_auth = true;
  uint32_t auth_timeout_ms = 30000;
  HitlOnTimeout on_timeout = HitlOnTimeout::kBlock;
  std::vector<std::string> notify;
  std::vector<Role> authorized_roles{Role::kOwner, Role::kCreator};  // only OWNER/CREATOR
};

struct AgentLayer {
  std::string url;
  uint32_t timeout_ms = 1000;
};

struct AgentConfig {
  std::string provider;  // empty when not configured
  std::string model;
  std::optional<uint32_t> latency_budget_ms;
  bool safety_stop = true;
  std::optional<double> min_obstacle_m;          // agent.min_obstacle_m | reactive.min_obstacle_m
  std::vector<ConfidenceGate> confidence_gates;  // agent.* | brain.* (alias)
  std::vector<HitlGate> hitl_gates;              // agent.* | brain.* (alias)
  std::optional<AgentLayer> reactive_layer;      // agent.layers.reactive
  std::optional<AgentLayer> fast_layer;          // agent.layers.fast
  std::optional<AgentLayer> planner_layer;       // agent.layers.planner
};

struct BrainConfig {  // profile-style `brain`
  std::string provider;
  std::string model;
  std::string fast_brain;
  std::string api_key_env;
  std::optional<uint32_t> max_tokens;
  std::optional<double> temperature;
};

struct RobotInfo {
  std::string name;          // robot.name | metadata.robot_name
  std::string manufacturer;  // robot.manufacturer | metadata.manufacturer (display text)
  std::string model;         // robot.model | metadata.model
  std::string type;          // robot.type | physics.type
  std::optional<uint32_t> dof;
  std::optional<double> payload_kg;
  std::optional<double> reach_mm;
  std::string serial_pattern;
  std::string description;
  std::vector<std::string> tags;
  std::string robot_uuid;  // metadata.robot_uuid
};

struct HardwareCapabilities {  // profile-style `capabilities: {motion, sensing, io, safety}`
  std::vector<std::string> motion, sensing, io, safety;
};

struct OfflineConfig {  // v1.5 `offline`
  uint32_t grace_period_s = 86400;
  uint32_t cross_owner_grace_s = 3600;
  uint32_t max_key_ttl_s = 86400;
  std::string issuer_url;  // probed for reachability (seed §6.1); empty: off
  uint32_t issuer_poll_ms = 5000;
  uint32_t issuer_timeout_ms = 1000;
};

struct ControlConfig {                // this node's `control` block (docs/SESSIONS.md)
  std::string fleet_policy = "role";  // role | fleet_wins | individual_wins
  uint32_t handoff_window_s = 30;
  uint32_t queue_max = 16;
  uint32_t queue_wait_s = 300;
  uint32_t queue_stream_grace_s = 5;   // a queued claimant without a stream leaves the queue
  uint32_t max_session_s = 0;          // caps every role's session TTL; 0 = the role TTLs
  uint32_t transfer_window_s = 86400;  // seed §6.2: 24 h
  uint32_t consent_ttl_s = 86400;
  std::string consent_webhook;  // http:// URL; empty: stream only
};

struct QosConfig {  // v1.5 `qos`
  uint32_t ack_timeout_ms = 500;
  uint32_t max_retries = 3;
  uint32_t backoff_base_ms = 100;
};

// ---------------------------------------------------------------------------------------

// `registry`: the registry this robot joins (docs/REGISTRY.md §A robot joins its registry).
// Joining needs registry.registry_url and key_file; without them the node stays on its own.
struct RegistryLinkConfig {
  std::string key_file;           // a registrant API key (mode 0600), resolved; empty: not joining
  bool register_at_start = true;  // register (with proof of possession) when no RRN is stored
  std::string endpoint;           // the URL the registry hands out for this robot; empty: none
  uint32_t refresh_s = 300;       // how often the robot tells the registry it is there
  std::string ca_file;            // https: trust anchors (empty: the system's)
  // Tokens issued by the registry (docs/SECURITY.md §Tokens from the registry).
  bool trust_tokens = false;               // verify tokens with the registry's published keys
  std::string issuer;                      // their `iss` (resolved: registry_url when not given)
  uint32_t jwks_refresh_s = 300;           // how often the keys are fetched again
  uint32_t revocations_refresh_s = 30;     // how often the revocation feed is polled
  uint32_t max_feed_revocations = 10'000;  // the feed's entries kept in force (their own table)
  uint32_t max_key_age_s = 86400;          // keys trusted this long without a successful fetch
};

struct NodeConfig {
  std::string rcan_version = "1.2";  // "1.2" and "1.3.0" styles
  std::string ruri;                  // canonical (ruri | metadata.ruri, normalised)
  Ruri ruri_parts;                   // parse_ruri(ruri)
  std::string rrn;                   // canonical RRN, empty unless configured (rrn | registry.rrn)
  std::string registry_url;          // registry.registry_url | rcan_protocol.registry
  RegistryLinkConfig registry;       // registry.key_file, register, endpoint, refresh_s, ca_file
  RobotInfo robot;
  // Protocol capabilities the node offers (status, chat, teleop, nav, arm, vision, …):
  // top-level `capabilities` as a list | rcan_protocol.capabilities; when neither is given,
  // derived from robot.type (docs/CONFIG.md).
  std::vector<std::string> capabilities;
  HardwareCapabilities hardware_capabilities;
  std::string channel_admin_scope;  // rcan_protocol.channel_admin_scope

  std::string data_dir;            // node.data_dir, default default_data_dir()
  std::string log_level = "info";  // trace|debug|info|warn|error
  ServerConfig server;
  GrpcConfig grpc;
  UdpConfig udp;
  SecurityConfig security;
  RbacConfig rbac;
  SafetyConfig safety;
  AgentConfig agent;
  BrainConfig brain;
  DriverConfig driver;
  OfflineConfig offline;
  QosConfig qos;
  MqttConfig mqtt;    // `mqtt` (config/fleet_config.h)
  FleetConfig fleet;  // `fleet`
  SwarmConfig swarm;  // `swarm` seed §5.2 keys
  ControlConfig control;
  DashboardConfig dashboard;  // `dashboard`

  // Validated blocks the node keeps but does not interpret, as JSON objects keyed by their
  // top-level name: bridge, hardware_safety, messaging, metadata, physics, drivers, network,
  // tiered_brain, reactive, learner, camera, audio, channels, agent_roster, swarm,
  // connection, notes, ros2 (only those present).
  json::Object kept;

  // rcan_protocol.enable_jwt: false was given. It is ignored: JWT is always required.
  bool enable_jwt_false_ignored = false;
  // Non-fatal notes for the log (e.g. the enable_jwt note above).
  std::vector<std::string> warnings;

  std::string source;  // the file path, or "<embedded default>" / "<text>"

  // Which data_dir-derived paths the file set explicitly (apply_overrides keeps these).
  struct ExplicitPaths {
    bool key_dir = false;
    bool audit_dir = false;
    bool chain_secret_file = false;
  } explicit_paths;
};

struct ConfigOptions {
  // Relative paths in the file resolve against this directory (load_config: the file's
  // directory). Empty: relative paths are kept relative (resolved against the CWD later).
  std::string base_dir;
  // When non-empty, replaces a `{device_id}` placeholder in ruri / metadata.ruri (8 hex
  // digits or a UUID, lower case), as in spec/profiles/*.rcan.yaml.
  std::string device_id;
  // Name used in NodeConfig::source.
  std::string source_name = "<text>";
  // data_dir when the file has no node.data_dir; empty → default_data_dir().
  std::string default_data_dir;
};

// Parses and validates YAML text. Never throws. The fuzz entry point.
Result<NodeConfig> parse_config_text(std::string_view yaml, const ConfigOptions& opts = {});

// Reads `path` (at most kMaxConfigBytes) and parses it with base_dir = its directory.
Result<NodeConfig> load_config(const std::string& path, ConfigOptions opts = {});

// The embedded simulated robot (`rcand` with no arguments): name "sim-rover",
// ruri rcan://local.rcan/rcan/sim-rover/<device_id>, capabilities status, chat, teleop, nav,
// arm; port 8080 on 127.0.0.1; no gates. `device_id` (8 hex or UUID): empty → the first 8
// hex digits of SHA-256(data_dir), stable per data directory.
Result<NodeConfig> default_config(const std::string& data_dir, std::string_view device_id = {});
// The YAML text default_config() parses (same as examples/sim-robot.rcan.yaml, minus
// comments and node.data_dir), with a `{device_id}` placeholder.
std::string_view default_config_yaml();

// $RCAND_DATA_DIR, else $XDG_DATA_HOME/rcand (when absolute), else $HOME/.local/share/rcand,
// else the passwd home directory. Error when no home directory can be found.
Result<std::string> default_data_dir();

// `--port N` and `--data-dir D`. Port must be 0..65535 (0: any free port, logged at start). A new
// data_dir (made absolute) moves key_dir, audit.dir and audit.chain_secret_file with it unless the
// file set them.
Status apply_overrides(NodeConfig& cfg, std::optional<int> port,
                       std::optional<std::string> data_dir);

// Names used in docs and logs (limit_policy_name: safety_types.h).
std::string_view gate_on_fail_name(GateOnFail f);
std::string_view hitl_on_timeout_name(HitlOnTimeout t);

// The built-in prompt-injection substrings (lower case).
const std::vector<std::string>& default_injection_patterns();

}  // namespace rcan::config
