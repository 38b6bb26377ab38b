// The `.rcan.yaml` schema: the Schema builders and config_schema(), every key of every block
// in the order the validator lists them.
#include <cstdio>
#include <iterator>

#include "config/config_internal.h"

namespace rcan::config::internal {
namespace {

SP make(Schema s) { return std::make_shared<const Schema>(std::move(s)); }

SP Str(size_t max_len = 4096) {
  Schema s;
  s.k = Schema::K::kString;
  s.max_len = max_len;
  return make(std::move(s));
}
SP Enum(std::initializer_list<const char*> values) {
  Schema s;
  s.k = Schema::K::kString;
  for (const char* v : values) s.enums.emplace_back(v);
  return make(std::move(s));
}
SP Int(std::optional<double> lo = std::nullopt, std::optional<double> hi = std::nullopt) {
  Schema s;
  s.k = Schema::K::kInt;
  s.min = lo;
  s.max = hi;
  return make(std::move(s));
}
SP Num(std::optional<double> lo = std::nullopt, std::optional<double> hi = std::nullopt,
       bool lo_exclusive = false) {
  Schema s;
  s.k = Schema::K::kNumber;
  s.min = lo;
  s.max = hi;
  s.min_exclusive = lo_exclusive;
  return make(std::move(s));
}
SP Pos() { return Num(0.0, std::nullopt, true); }  // > 0
SP NonNeg() { return Num(0.0); }                   // ≥ 0
SP Bool() {
  Schema s;
  s.k = Schema::K::kBool;
  return make(std::move(s));
}
SP Obj(std::vector<std::pair<std::string, SP>> props, std::vector<std::string> required = {}) {
  Schema s;
  s.k = Schema::K::kObject;
  s.props = std::move(props);
  s.required = std::move(required);
  return make(std::move(s));
}
SP Arr(SP items, size_t max_items = 1024) {
  Schema s;
  s.k = Schema::K::kArray;
  s.items = std::move(items);
  s.max_items = max_items;
  return make(std::move(s));
}
SP Either(std::vector<SP> alts) {
  Schema s;
  s.k = Schema::K::kEither;
  s.alts = std::move(alts);
  return make(std::move(s));
}
SP Free() {
  Schema s;
  s.k = Schema::K::kFree;
  return make(std::move(s));
}
SP StrList() { return Arr(Str()); }

using Props = std::vector<std::pair<std::string, SP>>;

// Sub-schemas that more than one block uses.
struct SubSchemas {
  SP gates_c, gates_h, layer, guest_limits, policy, agent_providers, channel;
};

SubSchemas sub_schemas() {
  SP confidence_gate = Obj({{"scope", Str(64)},
                            {"min_confidence", Num(0.0, 1.0)},
                            {"on_fail", Enum({"block", "escalate", "allow", "log"})}},
                           {"scope", "min_confidence", "on_fail"});
  SP hitl_gate = Obj({{"action_types", Arr(Str(128))},
                      {"action_type", Str(128)},
                      {"require_auth", Bool()},
                      {"auth_timeout_ms", Int(1, 86'400'000)},
                      {"on_timeout", Enum({"block", "allow", "escalate"})},
                      {"notify", Arr(Str(128))},
                      {"authorized_roles", Arr(Str(32))}},
                     {"require_auth"});
  SP gates_c = Arr(confidence_gate, 256);
  SP gates_h = Arr(hitl_gate, 256);
  SP layer = Obj({{"url", Str()}, {"timeout_ms", Int(1, 600'000)}}, {"url"});
  SP rate = Either({Int(0, 1'000'000), Str(64)});
  SP duration = Either({Int(0, 31'536'000), Str(64)});
  SP guest_limits = Obj({{"chat_rate", rate},
                         {"query_rate", rate},
                         {"session_duration", duration},
                         {"concurrent_sessions", Int(0, 100'000)},
                         {"capabilities", StrList()},
                         {"blocked", StrList()}});
  SP policy = Enum({"clamp", "reject"});
  SP agent_providers =
      Enum({"none", "local", "sim", "openai", "anthropic", "google", "mistral", "ollama",
            "openrouter", "huggingface", "llamacpp", "llama.cpp", "llama-cpp", "mlx", "mlx-lm",
            "vllm-mlx", "apple", "claude_oauth", "groq"});
  SP channel = Free();  // OpenCastor channels carry provider-specific credentials keys

  return {.gates_c = gates_c,
          .gates_h = gates_h,
          .layer = layer,
          .guest_limits = guest_limits,
          .policy = policy,
          .agent_providers = agent_providers,
          .channel = channel};
}

// `rcan_version`, `ruri`, `rrn`, `registry`, `robot`, `capabilities` and `metadata`.
Props identity_and_robot() {
  return {
      {"rcan_version", Str(32)},
      {"ruri", Str(512)},
      {"rrn", Str(64)},
      {"registry", Obj({{"rrn", Str(64)}, {"registry_url", Str()}})},
      {"robot", Obj({{"manufacturer", Str(256)},
                     {"name", Str(256)},
                     {"model", Str(256)},
                     {"type", Str(128)},
                     {"dof", Int(1, 1000)},
                     {"payload_kg", NonNeg()},
                     {"reach_mm", NonNeg()},
                     {"serial_pattern", Str(256)},
                     {"description", Str()},
                     {"arm_payload", Obj({{"fitted", Bool()},
                                          {"dof", Int(1, 1000)},
                                          {"payload_kg", NonNeg()},
                                          {"reach_mm", NonNeg()}})}})},
      {"capabilities", Either({Arr(Str(64)), Obj({{"motion", StrList()},
                                                  {"sensing", StrList()},
                                                  {"io", StrList()},
                                                  {"safety", StrList()}})})},
      {"metadata", Obj({{"robot_name", Str(256)},
                        {"robot_uuid", Str(64)},
                        {"author", Str(256)},
                        {"license", Str(256)},
                        {"ruri", Str(512)},
                        {"manufacturer", Str(256)},
                        {"model", Str(256)},
                        {"tags", StrList()},
                        {"created_at", Str(64)},
                        {"description", Str()},
                        {"version", Str(64)},
                        {"device_id", Str(64)}})},
  };
}

// `brain` and `agent`.
Props brain_and_agent(const SubSchemas& sub) {
  return {
      {"brain",
       Obj({{"provider", Enum({"openai", "anthropic", "google", "mistral", "local", "none"})},
            {"model", Str(256)},
            {"fast_brain", Str(256)},
            {"api_key_env", Str(256)},
            {"max_tokens", Int(1, 10'000'000)},
            {"temperature", Num(0.0, 2.0)},
            {"confidence_gates", sub.gates_c},
            {"hitl_gates", sub.gates_h}})},
      {"agent",
       Obj({{"provider", sub.agent_providers},
            {"model", Str(256)},
            {"vision_enabled", Bool()},
            {"latency_budget_ms", Int(0, 600'000)},
            {"safety_stop", Bool()},
            {"api_key", Str()},
            {"base_url", Str()},
            {"agentic_vision", Bool()},
            {"tools", StrList()},
            {"secondary_models",
             Arr(Obj({{"provider", Str(128)}, {"model", Str(256)}, {"role", Str(128)}}))},
            {"prompt_caching", Bool()},
            {"cache_alert_threshold", Num(0.0, 1.0)},
            {"min_obstacle_m", NonNeg()},
            {"confidence_gates", sub.gates_c},
            {"hitl_gates", sub.gates_h},
            {"layers", Obj({{"reactive", sub.layer}, {"fast", sub.layer}, {"planner", sub.layer}})},
            {"runtimes", Arr(Obj({{"id", Str(128)},
                                  {"harness", Str(128)},
                                  {"default", Bool()},
                                  {"models", StrList()}}))}})},
  };
}

// `safety`, `watchdog` and `hardware_safety`.
Props safety_blocks(const SubSchemas& sub) {
  return {
      {"safety",
       Obj({{"local_safety_wins", Bool()},
            {"max_linear_speed_mps", Pos()},
            {"max_angular_speed_radps", Pos()},
            {"max_linear_x", Pos()},
            {"max_angular_z", Pos()},
            {"emergency_stop_distance", NonNeg()},
            {"estop_distance_mm", NonNeg()},
            {"max_speed_override", Num(0.0, 1.0)},
            {"collision_monitor_stop_m", NonNeg()},
            {"collision_monitor_slowdown_m", NonNeg()},
            {"obstacle_stop_cm", NonNeg()},
            {"estop_on_startup", Bool()},
            {"estop_clear_requires_presence", Bool()},
            {"joint_limits",
             Arr(Obj({{"name", Str(64)}, {"min", Num()}, {"max", Num()}}, {"min", "max"}), 64)},
            {"workspace", Obj({{"x_min", Num()},
                               {"x_max", Num()},
                               {"y_min", Num()},
                               {"y_max", Num()},
                               {"z_min", Num()},
                               {"z_max", Num()}},
                              {"x_min", "x_max", "y_min", "y_max"})},
            {"limit_policy", Either({sub.policy, Obj({{"speed", sub.policy},
                                                      {"joints", sub.policy},
                                                      {"workspace", sub.policy}})})},
            {"heartbeat_timeout_ms", Int(100, 600'000)},
            {"command_ttl_default_ms", Int(0, 3'600'000)},
            // vendor keys used by the profiles
            {"max_walk_speed_mps", Pos()},
            {"estop_heartbeat_interval_ms", Int(1, 600'000)},
            {"estop_timeout_ms", Int(1, 600'000)},
            {"max_tcp_speed_mm_s", Pos()},
            {"collision_threshold_scale", Num(0.0, 1.0)},
            {"max_joint_torques_nm", Arr(NonNeg(), 64)},
            {"max_tcp_force_n", Pos()},
            {"fri_heartbeat_timeout_ms", Int(1, 600'000)},
            {"protective_stop_distance_mm", NonNeg()}})},
      {"watchdog", Obj({{"timeout_s", Int(1, 300)}, {"enabled", Bool()}})},
      {"hardware_safety", Obj({{"physical_estop", Bool()},
                               {"hardware_watchdog_mcu", Bool()},
                               {"sil_level", Either({Int(0, 4), Str(16)})},
                               {"human_proximity_sensors", Bool()}})},
  };
}

// The profile and OpenCastor blocks, `bridge` … `agent_roster`.
Props profile_blocks(const SubSchemas& sub) {
  return {
      {"bridge", Obj({{"type", Str(128)},
                      {"notes", Str(65536)},
                      {"hostname", Str(256)},
                      {"host", Str(256)},
                      {"username", Str(256)},
                      {"client_name", Str(256)},
                      {"ros_domain_id", Int(0, 232)},
                      {"namespace", Str(256)},
                      {"cmd_vel_topic", Str(256)},
                      {"odom_topic", Str(256)},
                      {"scan_topic", Str(256)},
                      {"nav2_action", Str(256)},
                      {"waypoint_action", Str(256)},
                      {"map_frame", Str(256)},
                      {"base_frame", Str(256)},
                      {"launch_package", Str(256)},
                      {"launch_file", Str(256)},
                      {"launch_args", Free()},
                      {"ros_driver", Str(256)},
                      {"fri_client_ip", Str(256)},
                      {"fri_port", Int(1, 65535)},
                      {"fri_library", Str(256)},
                      {"fri_version", Str(64)},
                      {"rtde_port", Int(1, 65535)},
                      {"dashboard_port", Int(1, 65535)},
                      {"recipe_file", Str(1024)}})},
      {"messaging",
       Obj({{"whatsapp", Obj({{"enabled", Bool()}, {"recipient", Str(256)}})},
            {"slack",
             Obj({{"enabled", Bool()}, {"channel", Str(256)}, {"webhook_url", Str(2048)}})}})},
      // OpenCastor style (schemas/rcan-config.schema.json)
      {"physics", Obj({{"type", Enum({"differential_drive", "ackermann", "serial_manipulator",
                                      "parallel_manipulator", "holonomic", "custom", "mecanum",
                                      "four_wheel_drive", "self_balancing", "omni"})},
                       {"dof", Int(1, 1000)},
                       {"chassis", Obj({{"wheel_base_mm", NonNeg()},
                                        {"wheelbase_mm", NonNeg()},
                                        {"track_width_mm", NonNeg()},
                                        {"wheel_radius_mm", NonNeg()}})},
                       {"kinematics", Arr(Obj({{"id", Str(128)},
                                               {"length_mm", NonNeg()},
                                               {"mass_g", NonNeg()},
                                               {"axis", Enum({"x", "y", "z"})},
                                               {"limits_deg", Arr(Num(), 2)}},
                                              {"id", "length_mm", "axis"}),
                                          64)}})},
      {"drivers", Arr(Obj({{"id", Str(128)},
                           {"link_id", Str(128)},
                           {"protocol", Str(128)},
                           {"port", Either({Int(0, 65535), Str(256)})},
                           {"address", Str(256)},
                           {"frequency", Int(0, 100'000'000)},
                           {"baud_rate", Int(0, 100'000'000)},
                           {"hardware_id", Int(0, 1'000'000)}},
                          {"protocol"}),
                      64)},
      {"network", Obj({{"telemetry_stream", Bool()},
                       {"sim_to_real_sync", Bool()},
                       {"allow_remote_override", Bool()}})},
      {"rcan_protocol", Obj({{"port", Int(1, 65535)},
                             {"capabilities", Arr(Str(64))},
                             {"enable_mdns", Bool()},
                             {"enable_jwt", Bool()},
                             {"registry", Str()},
                             {"channel_admin_scope", Str(64)}})},
      {"tiered_brain",
       Obj({{"planner_interval", Int(1, 1'000'000)}, {"uncertainty_threshold", Num(0.0, 1.0)}})},
      {"reactive",
       Obj({{"hailo_vision", Bool()},
            {"hailo_confidence", Num(0.0, 1.0)},
            {"hailo_model_path", Str(1024)},
            {"hailo_stop_distance_m", NonNeg()},
            {"hailo_warn_distance_m", NonNeg()},
            {"hailo_calibration", NonNeg()},
            {"min_obstacle_m", NonNeg()},
            {"fallback_provider", Obj({{"provider", Str(128)}, {"model", Str(256)}})}})},
      {"learner", Obj({{"enabled", Bool()},
                       {"provider", Str(128)},
                       {"model", Str(256)},
                       {"cadence", Str(64)},
                       {"cadence_n", Int(1, 1'000'000)},
                       {"max_retries", Int(0, 1000)},
                       {"auto_apply_config", Bool()},
                       {"auto_apply_behavior", Bool()},
                       {"auto_apply_code", Bool()}})},
      {"camera", Obj({{"type", Str(128)},
                      {"resolution", Arr(Int(1, 100'000), 2)},
                      {"framerate", Int(1, 10'000)},
                      {"depth_enabled", Bool()},
                      {"fps", Int(1, 10'000)},
                      {"imu_enabled", Bool()}})},
      {"audio", Obj({{"tts_enabled", Bool()},
                     {"engine", Str(128)},
                     {"language", Str(64)},
                     {"output_device", Str(256)}})},
      {"channels", Obj({{"whatsapp", sub.channel},
                        {"telegram", sub.channel},
                        {"discord", sub.channel},
                        {"slack", sub.channel}})},
      {"agent_roster",
       Arr(Obj({{"name", Str(128)}, {"enabled", Bool()}, {"config", Free()}}, {"name", "enabled"}),
           256)},
  };
}

// `swarm`, `mqtt`, `fleet`, `connection`, `notes` and `ros2`.
Props fleet_blocks() {
  return {
      {"swarm", Obj({{"enabled", Bool()},
                     {"sync_interval_s", Num(1.0)},
                     {"patch_sync", Bool()},
                     {"shared_memory_path", Str(1024)},
                     // seed §5.2 (docs/FLEET.md)
                     {"swarm_id", Str(128)},
                     {"member_id", Str(128)},
                     {"members", Arr(Str(128), 256)},
                     {"leader", Str(128)},
                     {"formation", Str(64)},
                     {"join_policy", Enum({"open", "approval", "closed"})},
                     {"heartbeat_ms", Int(50, 60'000)},
                     {"leader_timeout_ms", Int(200, 600'000)}})},
      {"mqtt", Obj({{"enabled", Bool()},
                    {"broker", Str(512)},
                    {"client_id", Str(128)},
                    {"topic_prefix", Str(256)},
                    {"keepalive_s", Int(5, 3600)},
                    {"username", Str(256)},
                    {"password_file", Str()},
                    {"tls", Obj({{"ca_file", Str()}, {"cert_file", Str()}, {"key_file", Str()}})},
                    {"reconnect", Obj({{"min_s", Int(1, 3600)}, {"max_s", Int(1, 3600)}})},
                    {"telemetry_hz", Int(0, 50)},
                    {"publish_audit", Bool()},
                    {"estop_qos", Int(1, 2)}})},
      {"fleet",
       Obj({{"fleet_id", Str(128)},
            {"member_id", Str(128)},
            {"robots", Arr(Str(128), 10'000)},
            {"access_mode", Enum({"coordinated", "independent"})},
            {"commands",
             Obj({{"broadcast", Bool()}, {"individual", Bool()}, {"choreographed", Bool()}})}},
           {"fleet_id", "robots"})},
      {"connection", Free()},
      {"notes", Either({Str(65536), Free()})},
      {"ros2", Obj({{"enabled", Bool()}, {"namespace", Str(256)}, {"domain_id", Int(0, 232)}})},
  };
}

// The v1.5 blocks and the top-level `guest_limits`.
Props v15_blocks(const SubSchemas& sub) {
  return {
      // v1.5 blocks
      {"offline", Obj({{"grace_period_s", Int(0, 31'536'000)},
                       {"cross_owner_grace_s", Int(0, 31'536'000)},
                       {"max_key_ttl_s", Int(0, 31'536'000)},
                       {"issuer_url", Str(2048)},
                       {"issuer_poll_ms", Int(50, 3'600'000)},
                       {"issuer_timeout_ms", Int(50, 60'000)}})},
      {"control", Obj({{"fleet_policy", Enum({"role", "fleet_wins", "individual_wins"})},
                       {"handoff_window_s", Int(1, 3600)},
                       {"queue_max", Int(0, 1024)},
                       {"queue_wait_s", Int(1, 86400)},
                       {"max_session_s", Int(0, 31'536'000)},
                       {"transfer_window_s", Int(1, 31'536'000)},
                       {"consent_ttl_s", Int(1, 31'536'000)},
                       {"consent_webhook", Str(2048)}})},
      {"qos", Obj({{"ack_timeout_ms", Int(1, 600'000)},
                   {"max_retries", Int(0, 100)},
                   {"backoff_base_ms", Int(1, 600'000)}})},
      // seed §6.3 (top-level form)
      {"guest_limits", sub.guest_limits},
  };
}

// `node`, `server`, `grpc` and `udp`.
Props node_blocks() {
  return {
      // this node's own blocks
      {"node", Obj({{"data_dir", Str()},
                    {"log_level", Enum({"trace", "debug", "info", "warn", "error"})}})},
      {"server",
       Obj({{"port", Int(1, 65535)},
            {"bind", Str(256)},
            {"io_threads", Int(1, 64)},
            {"enable_mdns", Bool()},
            {"tls", Obj({{"enabled", Bool()}, {"cert_file", Str()}, {"key_file", Str()}})},
            {"limits", Obj({{"max_body_bytes", Int(1024, 64 << 20)},
                            {"max_header_bytes", Int(1024, 1 << 20)},
                            {"read_timeout_ms", Int(100, 600'000)},
                            {"idle_timeout_ms", Int(100, 86'400'000)},
                            {"max_connections", Int(1, 1'000'000)}})}})},
      {"grpc", Obj({{"enabled", Bool()},
                    {"port", Int(0, 65535)},
                    {"bind", Str(256)},
                    {"max_streams", Int(1, 100'000)},
                    {"module", Str()},
                    {"tls", Obj({{"enabled", Bool()},
                                 {"cert_file", Str()},
                                 {"key_file", Str()},
                                 {"client_ca_file", Str()}})}})},
      {"udp", Obj({{"enabled", Bool()},
                   {"port", Int(0, 65535)},
                   {"bind", Str(256)},
                   {"heartbeat", Bool()},
                   {"discovery", Bool()},
                   {"discovery_per_source_per_min", Int(1, 6000)}})},
  };
}

// `security`, `rbac` and `driver`.
Props security_blocks(const SubSchemas& sub) {
  return {
      {"security",
       Obj({{"key_dir", Str()},
            {"replay_window_s", Int(5, 300)},
            {"msg_id_cache_size", Int(100, 10'000'000)},
            {"audit", Obj({{"dir", Str()},
                           {"chain_secret_file", Str()},
                           {"sync", Enum({"per_group", "interval"})},
                           {"sync_interval_ms", Int(1, 10'000)},
                           {"max_segment_bytes", Int(64 * 1024, 4.0 * 1024 * 1024 * 1024)},
                           {"retention", Obj({{"max_bytes", Int(0, 9.0e15)},
                                              {"max_age_days", Int(0, 36'500)}})}})},
            {"jwt", Obj({{"issuers", Arr(Obj({{"issuer", Str(512)},
                                              {"key_file", Str()},
                                              {"kind", Enum({"auto", "hs256_secret"})},
                                              {"kid", Str(128)}},
                                             {"issuer", "key_file"}),
                                         64)},
                         {"leeway_s", Int(0, 3600)}})},
            {"trusted_robot_keys",
             Arr(Obj({{"name", Str(128)}, {"mldsa65_pub_file", Str()}, {"ed25519_pub_file", Str()}},
                     {"name"}),
                 256)},
            {"trusted_signer_keys",
             Arr(Obj({{"name", Str(128)}, {"mldsa65_pub_file", Str()}, {"ed25519_pub_file", Str()}},
                     {"name"}),
                 256)},
            {"injection",
             Obj({{"use_defaults", Bool()},
                  {"patterns",
                   Arr(Either({Str(256), Obj({{"regex", Str(256)}}, {"regex"})}), 512)}})},
            {"commitment", Obj({{"enabled", Bool()},
                                {"key_mode", Enum({"classical", "quantum", "hybrid"})},
                                {"qber_threshold", Num(0.0, 1.0)}})},
            {"key_rotation", Obj({{"overlap_s", Int(0, 31'536'000)},
                                  {"max_validity_days", Int(1, 36'500)},
                                  {"auto_rotate", Bool()}})},
            {"revocation", Obj({{"check_on_startup", Bool()},
                                {"cache_ttl_s", Int(0, 31'536'000)},
                                {"max_staleness_s", Int(0, 31'536'000)},
                                {"quarantine_on_staleness", Bool()}})}})},
      {"rbac", Obj({{"grants", Obj({{"user_arm", Bool()},
                                    {"user_record", Bool()},
                                    {"leasee_training", Bool()},
                                    {"leasee_diagnostics", Bool()},
                                    {"owner_safety_config", Bool()}})},
                    {"rate_limits", Obj({{"guest", Int(0, 1'000'000)},
                                         {"user", Int(0, 1'000'000)},
                                         {"leasee", Int(0, 1'000'000)},
                                         {"owner", Int(0, 1'000'000)},
                                         {"creator", Int(0, 1'000'000)}})},
                    {"guest_limits", sub.guest_limits}})},
      {"driver", Obj({{"type", Enum({"sim"})},
                      {"sim", Obj({{"wheel_base_m", Pos()},
                                   {"max_accel_mps2", Pos()},
                                   {"max_angular_accel_radps2", Pos()},
                                   {"tick_hz", Int(1, 1000)},
                                   {"telemetry_hz", Int(1, 100)},
                                   {"arm_joints", Int(1, 16)}})}})},
  };
}

}  // namespace

std::string expected_name(const Schema& s) {
  switch (s.k) {
    case Schema::K::kString:
      return s.enums.empty() ? "a string" : "one of the listed strings";
    case Schema::K::kInt:
      return "an integer";
    case Schema::K::kNumber:
      return "a number";
    case Schema::K::kBool:
      return "a boolean";
    case Schema::K::kObject:
      return "a mapping";
    case Schema::K::kArray:
      return "a list";
    case Schema::K::kFree:
      return "a value";
    case Schema::K::kEither:
      break;
  }
  std::string out;
  for (size_t i = 0; i < s.alts.size(); ++i) {
    if (i) out += i + 1 == s.alts.size() ? " or " : ", ";
    out += expected_name(*s.alts[i]);
  }
  return out;
}

std::string join_enum(const std::vector<std::string>& v) {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) {
    if (i) out += ", ";
    out += v[i];
  }
  return out;
}

std::string fmt_num(double d) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", d);
  return buf;
}

// The whole document's schema.
SP config_schema() {
  static const SP schema = [] {
    const SubSchemas sub = sub_schemas();
    Props props;
    auto add = [&props](Props group) {
      props.insert(props.end(), std::make_move_iterator(group.begin()),
                   std::make_move_iterator(group.end()));
    };
    add(identity_and_robot());
    add(brain_and_agent(sub));
    add(safety_blocks(sub));
    add(profile_blocks(sub));
    add(fleet_blocks());
    add(v15_blocks(sub));
    add(node_blocks());
    add(security_blocks(sub));
    return Obj(std::move(props));
  }();
  return schema;
}

}  // namespace rcan::config::internal
