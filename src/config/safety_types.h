// The `safety` block and the value types it is read into, which the safety core runs with
// (node/safety/safety.h uses these same types): the limit policy, a joint's range, the
// workspace rectangle, the default deadman timeout, and SafetyConfig itself.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace rcan::config {

// safety.heartbeat_timeout_ms when neither it nor agent.latency_budget_ms is set; also the
// safety core's deadman timeout for a session registered without one.
inline constexpr uint32_t kDefaultHeartbeatTimeoutMs = 2000;
// security.failed_auth_per_address_per_minute: what failed token verifications one peer address
// may cost the node (NodeServices::authenticate).
inline constexpr uint32_t kDefaultFailedAuthPerAddressPerMinute = 1200;

enum class LimitPolicy : uint8_t { kClamp, kReject };
std::string_view limit_policy_name(LimitPolicy p);  // "clamp" / "reject"

struct JointLimit {
  std::string name;  // may be empty
  double min_rad = 0;
  double max_rad = 0;
};

// The rectangle the base must stay in (metres); z is read from the file but not enforced.
struct Workspace {
  bool enabled = true;  // false: no workspace guard (the file cannot turn it off)
  double x_min = -5.0;
  double x_max = 5.0;
  double y_min = -5.0;
  double y_max = 5.0;
  std::optional<double> z_min{}, z_max{};

  bool contains(double x, double y) const {
    return !enabled || (x >= x_min && x <= x_max && y >= y_min && y <= y_max);
  }
  // Distance from (x, y) to the rectangle (0 inside, and when the workspace is disabled).
  double distance_outside(double x, double y) const {
    if (!enabled) return 0.0;
    const double dx = std::max({x_min - x, 0.0, x - x_max});
    const double dy = std::max({y_min - y, 0.0, y - y_max});
    return std::hypot(dx, dy);
  }
};

// The `safety` block and the top-level `watchdog`, as the file gives them; the node's safety
// core runs with them (node::SafetyConfig::file). A member's initializer is its key's default;
// what a key means, its type and range are its row's (blocks/safety.cpp, docs/CONFIG.md).
struct WatchdogConfig {
  bool enabled = true;
  uint32_t timeout_s = 10;
};

struct SafetyConfig {
  bool local_safety_wins = true;
  double max_linear_speed_mps = 0.5;
  double max_angular_speed_radps = 1.0;
  std::optional<double> max_speed_override;
  std::optional<double> estop_distance_m;
  std::optional<double> collision_monitor_stop_m;
  std::optional<double> collision_monitor_slowdown_m;
  std::optional<double> obstacle_stop_cm;
  std::vector<JointLimit> joint_limits;  // the row's default: the simulated arm's
  Workspace workspace;
  LimitPolicy speed_policy = LimitPolicy::kClamp;
  LimitPolicy joint_policy = LimitPolicy::kReject;
  LimitPolicy workspace_policy = LimitPolicy::kReject;
  bool estop_on_startup = false;
  bool estop_on_driver_fault = false;
  bool estop_clear_requires_presence = false;
  uint32_t heartbeat_timeout_ms = kDefaultHeartbeatTimeoutMs;  // or the row's computed default
  uint32_t command_ttl_default_ms = 0;
  WatchdogConfig watchdog;
  // Vendor keys from the profiles (kept; the simulated robot does not use them).
  std::optional<double> max_walk_speed_mps;
  std::optional<double> max_tcp_speed_mm_s;
  std::optional<double> max_tcp_force_n;
  std::optional<double> collision_threshold_scale;
  std::optional<double> protective_stop_distance_mm;
  std::optional<uint32_t> estop_heartbeat_interval_ms;
  std::optional<uint32_t> estop_timeout_ms;
  std::optional<uint32_t> fri_heartbeat_timeout_ms;
  std::vector<double> max_joint_torques_nm;
};

}  // namespace rcan::config
