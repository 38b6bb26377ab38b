// `safety` (profile, OpenCastor and this node's keys: speed caps, joint limits, the
// workspace, limit policies, the deadman), the profile's top-level `watchdog`, and the
// P66 `hardware_safety` manifest, which is kept (docs/CONFIG.md §safety and watchdog).
#include <algorithm>
#include <cmath>

#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

using S = Rows<SafetyConfig>;

LimitPolicy policy_of(const std::string& s) {
  return s == "clamp" ? LimitPolicy::kClamp : LimitPolicy::kReject;
}

// A cap in its node spelling, or in the OpenCastor one (both, different: error).
Row<SafetyConfig> speed_cap(std::string key, const char* alias, double SafetyConfig::*member) {
  return S::read(std::move(key), Pos(), [alias, member](const At& a, SafetyConfig& s, Ctx& x) {
    At b = x.root["safety"][alias];
    same_or_fail(a, a.num(), b, b.num());
    if (At v = a ? a : b) s.*member = v.num();
  });
}

Row<SafetyConfig> joint_limits() {
  using J = Rows<JointLimit>;
  static const Table<JointLimit> rows = {
      J::field("name", Str(64), &JointLimit::name),
      J::field("min", Num(), &JointLimit::min_rad).required(),
      J::field("max", Num(), &JointLimit::max_rad).required(),
      J::check([](const At& j, JointLimit& l, Ctx&) {
        if (!(l.min_rad < l.max_rad))
          fail(j["max"].path,
               "must be greater than min (" + fmt_num(l.min_rad) + " ≥ " + fmt_num(l.max_rad) + ")",
               "out_of_range");
      }),
  };
  return S::read("joint_limits", Arr(object_of(rows), 64),
                 [](const At& a, SafetyConfig& s, Ctx& x) {
                   if (!a) {  // the simulated arm: 6 × ±3.14
                     for (int i = 0; i < 6; ++i)
                       s.joint_limits.push_back({"joint" + std::to_string(i + 1), -3.14, 3.14});
                     return;
                   }
                   for (size_t i = 0; i < a.size(); ++i)
                     s.joint_limits.push_back(element(rows, a[i], x));
                 });
}

Row<SafetyConfig> workspace() {
  using W = Rows<Workspace>;
  static const Table<Workspace> rows = {
      W::field("x_min", Num(), &Workspace::x_min).required(),
      W::field("x_max", Num(), &Workspace::x_max).required(),
      W::field("y_min", Num(), &Workspace::y_min).required(),
      W::field("y_max", Num(), &Workspace::y_max).required(),
      W::field("z_min", Num(), &Workspace::z_min),
      W::field("z_max", Num(), &Workspace::z_max),
      W::check([](const At& ws, Workspace& w, Ctx&) {
        if (!(w.x_min < w.x_max))
          fail(ws["x_max"].path, "must be greater than x_min", "out_of_range");
        if (!(w.y_min < w.y_max))
          fail(ws["y_max"].path, "must be greater than y_min", "out_of_range");
        if (w.z_min.has_value() != w.z_max.has_value())
          fail(ws[w.z_min ? "z_max" : "z_min"].path, "z_min and z_max go together", "missing_key");
        if (w.z_min && !(*w.z_min < *w.z_max))
          fail(ws["z_max"].path, "must be greater than z_min", "out_of_range");
      }),
  };
  return S::read("workspace", object_of(rows), [](const At& a, SafetyConfig& s, Ctx& x) {
    if (a) walk(rows, a, s.workspace, x);
  });
}

Row<SafetyConfig> limit_policy() {
  SP policy = Enum({"clamp", "reject"});
  return S::read(
      "limit_policy",
      Either({policy, Obj({{"speed", policy}, {"joints", policy}, {"workspace", policy}})}),
      [](const At& lp, SafetyConfig& s, Ctx&) {
        if (!lp) return;
        if (lp.is_string()) {
          s.speed_policy = s.joint_policy = s.workspace_policy = policy_of(lp.str());
        } else {
          if (lp["speed"]) s.speed_policy = policy_of(lp["speed"].str());
          if (lp["joints"]) s.joint_policy = policy_of(lp["joints"].str());
          if (lp["workspace"]) s.workspace_policy = policy_of(lp["workspace"].str());
        }
      });
}

Table<SafetyConfig> safety_rows() {
  return {
      S::read("local_safety_wins", Bool(),
              [](const At& a, SafetyConfig&, Ctx&) {
                if (a && !a.flag(true))
                  fail(a.path, "must be true: local safety always wins over network commands",
                       "invalid_value");
              }),
      speed_cap("max_linear_speed_mps", "max_linear_x", &SafetyConfig::max_linear_speed_mps),
      speed_cap("max_angular_speed_radps", "max_angular_z", &SafetyConfig::max_angular_speed_radps),
      S::schema_only("max_linear_x", Pos()),   // read by max_linear_speed_mps
      S::schema_only("max_angular_z", Pos()),  // read by max_angular_speed_radps
      S::field("max_speed_override", Num(0.0, 1.0), &SafetyConfig::max_speed_override),
      S::read("emergency_stop_distance", NonNeg(),
              [](const At& m, SafetyConfig& s, Ctx& x) {
                At mm = x.root["safety"]["estop_distance_mm"];
                if (m && mm && std::fabs(m.num() * 1000.0 - mm.num()) > 1e-6)
                  fail(mm.path, "conflicts with safety.emergency_stop_distance (give one)",
                       "invalid_value");
                if (m)
                  s.estop_distance_m = m.num();
                else if (mm)
                  s.estop_distance_m = mm.num() / 1000.0;
              }),
      S::schema_only("estop_distance_mm", NonNeg()),  // read by emergency_stop_distance
      S::field("collision_monitor_stop_m", NonNeg(), &SafetyConfig::collision_monitor_stop_m),
      S::read("collision_monitor_slowdown_m", NonNeg(),
              [](const At& a, SafetyConfig& s, Ctx&) {
                s.collision_monitor_slowdown_m = a.opt_num();
                if (s.collision_monitor_stop_m && s.collision_monitor_slowdown_m &&
                    *s.collision_monitor_slowdown_m < *s.collision_monitor_stop_m)
                  fail(a.path,
                       "must be at least collision_monitor_stop_m (slow down before stopping)",
                       "out_of_range");
              }),
      S::field("obstacle_stop_cm", NonNeg(), &SafetyConfig::obstacle_stop_cm),
      joint_limits(),
      workspace(),
      limit_policy(),
      S::field("estop_on_startup", Bool(), &SafetyConfig::estop_on_startup),
      S::field("estop_on_driver_fault", Bool(), &SafetyConfig::estop_on_driver_fault),
      S::field("estop_clear_requires_presence", Bool(),
               &SafetyConfig::estop_clear_requires_presence),
      S::read("heartbeat_timeout_ms", Int(100, 600'000),
              [](const At& hb, SafetyConfig& s, Ctx& x) {
                const std::optional<uint32_t>& budget = x.c.agent.latency_budget_ms;
                if (hb)
                  assign(hb, s.heartbeat_timeout_ms);
                else if (budget && *budget > 0)
                  s.heartbeat_timeout_ms = std::clamp<uint32_t>(*budget * 2, 100, 600'000);
              }),
      S::field("command_ttl_default_ms", Int(0, 3'600'000), &SafetyConfig::command_ttl_default_ms),
      // vendor keys used by the profiles (kept; the simulated robot does not use them)
      S::field("max_walk_speed_mps", Pos(), &SafetyConfig::max_walk_speed_mps),
      S::field("estop_heartbeat_interval_ms", Int(1, 600'000),
               &SafetyConfig::estop_heartbeat_interval_ms),
      S::field("estop_timeout_ms", Int(1, 600'000), &SafetyConfig::estop_timeout_ms),
      S::field("max_tcp_speed_mm_s", Pos(), &SafetyConfig::max_tcp_speed_mm_s),
      S::field("collision_threshold_scale", Num(0.0, 1.0),
               &SafetyConfig::collision_threshold_scale),
      S::field("max_joint_torques_nm", Arr(NonNeg(), 64), &SafetyConfig::max_joint_torques_nm),
      S::field("max_tcp_force_n", Pos(), &SafetyConfig::max_tcp_force_n),
      S::field("fri_heartbeat_timeout_ms", Int(1, 600'000),
               &SafetyConfig::fri_heartbeat_timeout_ms),
      S::field("protective_stop_distance_mm", NonNeg(), &SafetyConfig::protective_stop_distance_mm),
  };
}

Table<WatchdogConfig> watchdog_rows() {
  using W = Rows<WatchdogConfig>;
  return {
      W::field("timeout_s", Int(1, 300), &WatchdogConfig::timeout_s),
      W::field("enabled", Bool(), &WatchdogConfig::enabled),
  };
}

}  // namespace

Table<NodeConfig> safety_blocks() {
  using R = Rows<NodeConfig>;
  return {
      R::block("safety", safety_rows(), &NodeConfig::safety),  // reads c.agent.latency_budget_ms
      R::block("watchdog", watchdog_rows(),
               [](NodeConfig& c) -> WatchdogConfig& { return c.safety.watchdog; }),
      R::schema_only("hardware_safety", Obj({{"physical_estop", Bool()},
                                             {"hardware_watchdog_mcu", Bool()},
                                             {"sil_level", Either({Int(0, 4), Str(16)})},
                                             {"human_proximity_sensors", Bool()}})),
  };
}

}  // namespace rcan::config::internal
