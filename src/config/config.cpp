// Node configuration: strict `.rcan.yaml` loading. See config.h and docs/CONFIG.md.
// This file holds the public API; config_internal.h describes the two passes of the loader
// and the files that hold them.
#include "config/config.h"

#include <pwd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "config/config_internal.h"
#include "rcan/hash.h"
#include "runtime/data_dir.h"

namespace rcan::config {

// ---------------------------------------------------------------------------------------
// Public API

GuestLimits GuestLimitsConfig::to_guest_limits() const {
  auto per_min = [](const RateSpec& r) -> uint32_t {
    if (r.count == 0 || r.window_s == 0) return 0;
    uint64_t v = static_cast<uint64_t>(r.count) * 60 / r.window_s;
    return static_cast<uint32_t>(std::clamp<uint64_t>(v, 1, UINT32_MAX));
  };
  GuestLimits g;
  g.chat_per_minute = per_min(chat_rate);
  g.query_per_minute = per_min(query_rate);
  g.session_seconds = session_duration_s;
  g.concurrent_sessions = concurrent_sessions;
  g.capabilities = capabilities;
  g.blocked = blocked;
  return g;
}

uint32_t RateLimits::for_role(Role r) const {
  switch (r) {
    case Role::kGuest:
      return guest;
    case Role::kUser:
      return user;
    case Role::kLeasee:
      return leasee;
    case Role::kOwner:
      return owner;
    case Role::kCreator:
      return creator;
  }
  return guest;
}

const std::vector<std::string>& default_injection_patterns() {
  static const std::vector<std::string> patterns{
      "ignore previous instructions",
      "ignore all previous instructions",
      "ignore the above",
      "disregard all prior",
      "disregard previous instructions",
      "forget your instructions",
      "system prompt",
      "you are now",
      "act as an unrestricted",
      "developer mode",
      "override safety",
      "disable safety",
      "bypass the safety",
      "new instructions:",
      "<|im_start|>",
      "[system]",
  };
  return patterns;
}

std::string_view limit_policy_name(LimitPolicy p) {
  return p == LimitPolicy::kClamp ? "clamp" : "reject";
}
std::string_view gate_on_fail_name(GateOnFail f) {
  switch (f) {
    case GateOnFail::kBlock:
      return "block";
    case GateOnFail::kEscalate:
      return "escalate";
    case GateOnFail::kAllow:
      return "allow";
  }
  return "block";
}
std::string_view hitl_on_timeout_name(HitlOnTimeout t) {
  return t == HitlOnTimeout::kAllow ? "allow" : "block";
}

Result<NodeConfig> parse_config_text(std::string_view yaml, const ConfigOptions& opts) {
  if (yaml.size() > kMaxConfigBytes)
    return internal::make_error("",
                                "config file too large: " + std::to_string(yaml.size()) +
                                    " bytes (at most " + std::to_string(kMaxConfigBytes) + ")",
                                "too_large", "");
  if (yaml.find('\0') != std::string_view::npos)
    return internal::make_error("", "config file contains a NUL byte", "malformed_yaml", "");
  return internal::parse_document(yaml, opts);
}

Result<NodeConfig> load_config(const std::string& path, ConfigOptions opts) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    return Error(ErrorCode::kSchemaValidationFailed,
                 "cannot read config file " + path + ": not a regular file", "", "io_error");
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return Error(ErrorCode::kSchemaValidationFailed,
                 "cannot read config file " + path + ": " + std::strerror(errno), "", "io_error");
  std::string text;
  text.resize(kMaxConfigBytes + 1);
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<size_t>(in.gcount()));
  if (in.bad())
    return Error(ErrorCode::kSchemaValidationFailed, "cannot read config file " + path, "",
                 "io_error");
  if (opts.base_dir.empty()) {
    fs::path abs = fs::absolute(fs::path(path), ec);
    opts.base_dir = (ec ? fs::path(path) : abs).parent_path().lexically_normal().string();
  }
  if (opts.source_name == "<text>") opts.source_name = path;
  Result<NodeConfig> r = parse_config_text(text, opts);
  if (!r.ok()) {
    Error e = r.error();
    e.message = path + ": " + e.message;
    return e;
  }
  return r;
}

std::string_view default_config_yaml() {
  // Keep in step with examples/sim-robot.rcan.yaml (config_test checks they load alike).
  static constexpr std::string_view text = R"yaml(rcan_version: "1.2"
ruri: rcan://local.rcan/rcan/sim-rover/{device_id}
robot:
  name: sim-rover
  manufacturer: rcan
  model: sim-rover
  type: mobile_differential_with_arm
  dof: 8
  description: Simulated differential-drive rover with a 6-joint arm
capabilities: [status, chat, teleop, nav, arm]
node:
  log_level: info
server:
  port: 8080
  bind: 127.0.0.1
  io_threads: 2
  enable_mdns: true
  limits:
    max_body_bytes: 65536
    max_header_bytes: 8192
    read_timeout_ms: 10000
    idle_timeout_ms: 60000
    max_connections: 1024
    max_connections_per_address: 64
    reserved_connections: 16
    unauthenticated_idle_timeout_ms: 5000
security:
  replay_window_s: 30
  msg_id_cache_size: 10000
  audit:
    sync: per_group
  jwt:
    leeway_s: 60
rbac:
  rate_limits: {guest: 10, user: 100, leasee: 500, owner: 1000, creator: 0}
  guest_limits:
    chat_rate: 10/minute
    query_rate: 30/minute
    session_duration: 15min
    concurrent_sessions: 3
    capabilities: [status_read, chat_text, basic_info]
    blocked: [control, camera_access, location_history]
safety:
  local_safety_wins: true
  max_linear_speed_mps: 0.5
  max_angular_speed_radps: 1.0
  emergency_stop_distance: 0.3
  joint_limits:
    - {name: joint1, min: -3.14, max: 3.14}
    - {name: joint2, min: -3.14, max: 3.14}
    - {name: joint3, min: -3.14, max: 3.14}
    - {name: joint4, min: -3.14, max: 3.14}
    - {name: joint5, min: -3.14, max: 3.14}
    - {name: joint6, min: -3.14, max: 3.14}
  workspace: {x_min: -5.0, x_max: 5.0, y_min: -5.0, y_max: 5.0}
  limit_policy: {speed: clamp, joints: reject, workspace: reject}
  estop_on_startup: false
  heartbeat_timeout_ms: 2000
watchdog:
  enabled: true
  timeout_s: 10
agent:
  provider: none
  confidence_gates: []
  hitl_gates: []
driver:
  type: sim
  sim:
    wheel_base_m: 0.3
    max_accel_mps2: 1.0
    max_angular_accel_radps2: 2.0
    tick_hz: 50
    telemetry_hz: 5
    arm_joints: 6
)yaml";
  return text;
}

Result<NodeConfig> default_config(const std::string& data_dir, std::string_view device_id) {
  if (data_dir.empty())
    return Error(ErrorCode::kSchemaValidationFailed, "node.data_dir: must not be empty",
                 "node.data_dir", "invalid_value");
  std::error_code ec;
  std::filesystem::path abs = std::filesystem::absolute(data_dir, ec);
  std::string dir = (ec ? std::filesystem::path(data_dir) : abs).lexically_normal().string();
  ConfigOptions opts;
  opts.device_id = device_id.empty() ? sha256_hex(dir).substr(0, 8) : std::string(device_id);
  opts.source_name = "<embedded default>";
  opts.default_data_dir = dir;
  std::string_view text = default_config_yaml();
  return parse_config_text(text, opts);
}

Result<std::string> default_data_dir() { return user_data_dir("rcand", "RCAND_DATA_DIR"); }

Status apply_overrides(NodeConfig& cfg, std::optional<int> port,
                       std::optional<std::string> data_dir) {
  if (port) {
    // 0 asks the kernel for a free port (tests, several nodes on one host); the node logs it.
    if (*port < 0 || *port > 65535)
      return Error(
          ErrorCode::kSchemaValidationFailed,
          "--port: out of range: " + std::to_string(*port) + " (must be between 0 and 65535)",
          "server.port", "out_of_range");
  }
  if (data_dir && data_dir->empty())
    return Error(ErrorCode::kSchemaValidationFailed, "--data-dir: must not be empty",
                 "node.data_dir", "invalid_value");
  if (port) cfg.server.port = static_cast<uint16_t>(*port);
  if (data_dir) {
    std::error_code ec;
    std::filesystem::path abs = std::filesystem::absolute(*data_dir, ec);
    cfg.data_dir = (ec ? std::filesystem::path(*data_dir) : abs).lexically_normal().string();
    internal::derive_paths(cfg);
  }
  return Status::Ok();
}

}  // namespace rcan::config
