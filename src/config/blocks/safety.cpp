// `safety` (profile, OpenCastor and this node's keys: speed caps, joint limits, the
// workspace, limit policies, the deadman), the profile's top-level `watchdog`, and the
// P66 `hardware_safety` manifest, which is kept (docs/CONFIG.md §safety and watchdog).
#include <algorithm>
#include <cmath>

#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

using S = Rows<SafetyConfig>;

constexpr const char* kVendor =
    "a vendor key of the robot profiles (kept; the simulated robot "
    "does not use it)";

LimitPolicy policy_of(const std::string& s) {
  return s == "clamp" ? LimitPolicy::kClamp : LimitPolicy::kReject;
}

// A cap in its node spelling, or in the OpenCastor one (both, different: error).
Row<SafetyConfig> speed_cap(std::string key, const char* alias, double SafetyConfig::*member) {
  return S::read(std::move(key), Pos(),
                 [alias, member](const At& a, SafetyConfig& s, Ctx& x) {
                   At b = x.root["safety"][alias];
                   same_or_fail(a, a.num(), b, b.num());
                   if (At v = a ? a : b) s.*member = v.num();
                 })
      .default_of(member);
}

Row<SafetyConfig> joint_limits() {
  using J = Rows<JointLimit>;
  static const Table<JointLimit> rows = {
      J::field("name", Str(64), &JointLimit::name).doc("the joint's name"),
      J::field("min", Num(), &JointLimit::min_rad).required().doc("radians"),
      J::field("max", Num(), &JointLimit::max_rad).required().doc("radians, greater than `min`"),
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
                 })
      .with_keys(rows)
      .default_text("6 × [−3.14, 3.14] (`joint1…joint6`, the simulated arm)")
      .doc("the arm's joint ranges in order (at most 64)");
}

Row<SafetyConfig> workspace() {
  using W = Rows<Workspace>;
  static const Table<Workspace> rows = {
      W::field("x_min", Num(), &Workspace::x_min).required().doc("metres"),
      W::field("x_max", Num(), &Workspace::x_max).required().doc("metres, greater than `x_min`"),
      W::field("y_min", Num(), &Workspace::y_min).required().doc("metres"),
      W::field("y_max", Num(), &Workspace::y_max).required().doc("metres, greater than `y_min`"),
      W::field("z_min", Num(), &Workspace::z_min).doc("metres; with `z_max` (read, not enforced)"),
      W::field("z_max", Num(), &Workspace::z_max).doc("metres, greater than `z_min`"),
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
  return S::read("workspace", object_of(rows),
                 [](const At& a, SafetyConfig& s, Ctx& x) {
                   if (a) walk(rows, a, s.workspace, x);
                 })
      .with_keys(rows)
      .default_text("±5 m in x and y")
      .doc("the rectangle the base must stay in");
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
             })
      .default_text(std::string("speed ") +
                    std::string(limit_policy_name(SafetyConfig{}.speed_policy)) + ", joints " +
                    std::string(limit_policy_name(SafetyConfig{}.joint_policy)) + ", workspace " +
                    std::string(limit_policy_name(SafetyConfig{}.workspace_policy)))
      .doc(
          "one policy for all limits, or one per limit as `{speed, joints, workspace}`: a "
          "command over a limit is clamped to it, or rejected");
}

Table<SafetyConfig> safety_rows() {
  return {
      S::read("local_safety_wins", Bool(),
              [](const At& a, SafetyConfig&, Ctx&) {
                if (a && !a.flag(true))
                  fail(a.path, "must be true: local safety always wins over network commands",
                       "invalid_value");
              })
          .default_of(&SafetyConfig::local_safety_wins)
          .doc("**must be true**: local safety always wins over network commands"),
      speed_cap("max_linear_speed_mps", "max_linear_x", &SafetyConfig::max_linear_speed_mps)
          .doc("the linear speed cap (m/s); alias `max_linear_x` (both, different: error)"),
      speed_cap("max_angular_speed_radps", "max_angular_z", &SafetyConfig::max_angular_speed_radps)
          .doc("the angular speed cap (rad/s); alias `max_angular_z`"),
      S::schema_only("max_linear_x", Pos()).doc("alias of `max_linear_speed_mps` (OpenCastor)"),
      S::schema_only("max_angular_z", Pos()).doc("alias of `max_angular_speed_radps` (OpenCastor)"),
      S::field("max_speed_override", Num(0.0, 1.0), &SafetyConfig::max_speed_override)
          .doc("a fraction applied on top of the speed caps"),
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
              })
          .default_of(&SafetyConfig::estop_distance_m)
          .doc("metres; alias `estop_distance_mm` in millimetres (both, inconsistent: error)"),
      S::schema_only("estop_distance_mm", NonNeg()).doc("alias of `emergency_stop_distance`"),
      S::field("collision_monitor_stop_m", NonNeg(), &SafetyConfig::collision_monitor_stop_m)
          .doc("metres"),
      S::read("collision_monitor_slowdown_m", NonNeg(),
              [](const At& a, SafetyConfig& s, Ctx&) {
                s.collision_monitor_slowdown_m = a.opt_num();
                if (s.collision_monitor_stop_m && s.collision_monitor_slowdown_m &&
                    *s.collision_monitor_slowdown_m < *s.collision_monitor_stop_m)
                  fail(a.path,
                       "must be at least collision_monitor_stop_m (slow down before stopping)",
                       "out_of_range");
              })
          .default_of(&SafetyConfig::collision_monitor_slowdown_m)
          .doc("metres, at least `collision_monitor_stop_m`"),
      S::field("obstacle_stop_cm", NonNeg(), &SafetyConfig::obstacle_stop_cm)
          .doc("centimetres (OpenCastor)"),
      joint_limits(),
      workspace(),
      limit_policy(),
      S::field("estop_on_startup", Bool(), &SafetyConfig::estop_on_startup)
          .doc("the robot always comes up latched"),
      S::field("estop_on_driver_fault", Bool(), &SafetyConfig::estop_on_driver_fault)
          .doc("a driver fault (DRIVER_FAULT) also latches ESTOP (source `driver`), so motion "
               "needs a RESUME once the driver is back"),
      S::field("estop_clear_requires_presence", Bool(),
               &SafetyConfig::estop_clear_requires_presence)
          .doc("read and kept; rcand does not act on it"),
      S::read("heartbeat_timeout_ms", Int(100, 600'000),
              [](const At& hb, SafetyConfig& s, Ctx& x) {
                const std::optional<uint32_t>& budget = x.c.agent.latency_budget_ms;
                if (hb)
                  assign(hb, s.heartbeat_timeout_ms);
                else if (budget && *budget > 0)
                  s.heartbeat_timeout_ms = std::clamp<uint32_t>(*budget * 2, 100, 600'000);
              })
          .default_text("`agent.latency_budget_ms` × 2 when that is set and > 0, else " +
                        default_text_of(SafetyConfig{}.heartbeat_timeout_ms))
          .doc("a control session silent this long safe-stops the robot (the deadman)"),
      S::field("command_ttl_default_ms", Int(0, 3'600'000), &SafetyConfig::command_ttl_default_ms)
          .doc("the TTL of a command that carries none; 0: only the message's own `ttl_ms`"),
      // vendor keys used by the profiles (kept; the simulated robot does not use them)
      S::field("max_walk_speed_mps", Pos(), &SafetyConfig::max_walk_speed_mps).doc(kVendor),
      S::field("estop_heartbeat_interval_ms", Int(1, 600'000),
               &SafetyConfig::estop_heartbeat_interval_ms)
          .doc(kVendor),
      S::field("estop_timeout_ms", Int(1, 600'000), &SafetyConfig::estop_timeout_ms).doc(kVendor),
      S::field("max_tcp_speed_mm_s", Pos(), &SafetyConfig::max_tcp_speed_mm_s).doc(kVendor),
      S::field("collision_threshold_scale", Num(0.0, 1.0), &SafetyConfig::collision_threshold_scale)
          .doc(kVendor),
      S::field("max_joint_torques_nm", Arr(NonNeg(), 64), &SafetyConfig::max_joint_torques_nm)
          .doc(kVendor),
      S::field("max_tcp_force_n", Pos(), &SafetyConfig::max_tcp_force_n).doc(kVendor),
      S::field("fri_heartbeat_timeout_ms", Int(1, 600'000), &SafetyConfig::fri_heartbeat_timeout_ms)
          .doc(kVendor),
      S::field("protective_stop_distance_mm", NonNeg(), &SafetyConfig::protective_stop_distance_mm)
          .doc(kVendor),
  };
}

Table<WatchdogConfig> watchdog_rows() {
  using W = Rows<WatchdogConfig>;
  return {
      W::field("timeout_s", Int(1, 300), &WatchdogConfig::timeout_s).doc("seconds"),
      W::field("enabled", Bool(), &WatchdogConfig::enabled).doc("the profile's brain watchdog"),
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
                                             {"human_proximity_sensors", Bool()}}))
          .doc("the P66 hardware safety manifest (profiles): validated and kept, not "
               "interpreted"),
  };
}

}  // namespace rcan::config::internal
