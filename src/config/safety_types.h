// The safety value types the `safety` block is read into and the safety core runs with
// (node/safety/safety.h uses these same types): the limit policy, a joint's range, the
// workspace rectangle, and the default deadman timeout.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

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

}  // namespace rcan::config
