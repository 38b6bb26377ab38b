// Driver — the one interface every actuator backend implements (the simulated robot, real
// hardware later). Nothing calls a Driver except the SafetyCore (src/node/safety/safety.h): the
// core validates and limits each command, serialises apply()/step()/state(), and may call stop()
// from any thread at any time.
//
// Contract for implementers:
//   * apply(), step(), state() and describe() are called by the SafetyCore one at a time
//     (under its apply lock); they must be short (no I/O waits beyond one bus write).
//   * stop() may be called from ANY thread, concurrently with any other method, any number
//     of times. It must be fast (no blocking I/O, no lock that apply()/step() hold for long),
//     idempotent, and must never throw. After stop() returns, the actuators are commanded to
//     their safe/zero state: base velocity target 0 (braking), arm holds where it is.
//   * A drive command always carries a duration: the driver stops the base when it elapses
//     (the core also enforces it on the monotonic clock — belt and braces).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

inline constexpr int kArmJoints = 6;
using JointArray = std::array<double, kArmJoints>;

// Base velocity command (unicycle model).
struct DriveCommand {
  double linear_mps = 0.0;     // forward speed, m/s (negative = reverse)
  double angular_radps = 0.0;  // yaw rate, rad/s (positive = counter-clockwise)
  // How long to hold these velocities; then the base decelerates to rest. The SafetyCore
  // replaces 0 (or a negative value) by its maximum drive duration: no drive runs forever.
  int64_t duration_ms = 0;
};

// Arm position command: every joint moves toward its target at `max_joint_speed_radps`.
struct ArmCommand {
  JointArray targets_rad{};
  // 0 → the configured maximum joint speed.
  double max_joint_speed_radps = 0.0;
};

enum class GripperAction : uint8_t { kOpen, kClose };

// One validated actuator command. Any combination of parts may be present; `stop` alone
// (or with nothing else) stops everything, and wins over the other parts.
struct ActuatorCommand {
  std::optional<DriveCommand> drive;
  std::optional<ArmCommand> arm;
  std::optional<GripperAction> gripper;
  bool stop = false;

  bool empty() const { return !drive && !arm && !gripper && !stop; }
  // True when executing the command can move something.
  bool moves() const {
    return !stop && (drive.has_value() || arm.has_value() || gripper.has_value());
  }

  static ActuatorCommand make_drive(double linear_mps, double angular_radps, int64_t duration_ms) {
    ActuatorCommand c;
    c.drive = DriveCommand{linear_mps, angular_radps, duration_ms};
    return c;
  }
  static ActuatorCommand make_arm(const JointArray& targets, double max_joint_speed_radps = 0.0) {
    ActuatorCommand c;
    c.arm = ArmCommand{targets, max_joint_speed_radps};
    return c;
  }
  static ActuatorCommand make_stop() {
    ActuatorCommand c;
    c.stop = true;
    return c;
  }
  json::Object to_json() const;
};

// A snapshot of the robot. Drivers fill the physical fields; the SafetyCore fills the
// telemetry loop fields (ts, loop_latency_ms, loop_count, paused) when it publishes status.
struct RobotState {
  // Base pose in the odometry frame (m, m, rad; theta wrapped to (-pi, pi]).
  double x = 0.0;
  double y = 0.0;
  double theta = 0.0;
  // Current (integrated) base velocities and the active targets.
  double linear_mps = 0.0;
  double angular_radps = 0.0;
  double target_linear_mps = 0.0;
  double target_angular_radps = 0.0;
  int64_t drive_remaining_ms = 0;  // time left on the active drive command
  double odometry_m = 0.0;         // total distance travelled

  JointArray joints_rad{};
  JointArray joint_targets_rad{};
  double joint_speed_radps = 0.0;  // speed of the active arm motion
  bool gripper_closed = false;

  // Nothing is moving and no motion is commanded.
  bool stopped = true;

  // Battery simulation (NaN-free; real drivers without a gauge report battery_known=false).
  bool battery_known = false;
  double battery_v = 0.0;
  double battery_pct = 0.0;

  int64_t t_ms = 0;  // driver time: milliseconds integrated by step()

  // Telemetry loop fields (spec-digest §4.4 MUSTs), set by the SafetyCore.
  int64_t ts = 0;                // wall-clock Unix milliseconds of the snapshot
  double loop_latency_ms = 0.0;  // duration of the last control-loop tick
  uint64_t loop_count = 0;       // control-loop ticks so far
  bool paused = false;           // ESTOP latched or safe-stop active

  // Telemetry JSON: {"ts","loop_latency_ms","loop_count","paused","base":{…},"arm":{…},
  // "gripper":{…},"battery_v"?,"battery_pct"?,"stopped","t_ms"}.
  json::Object to_json() const;
};

// What a driver is and can do (for /api/status, the P66 manifest and limit prediction).
struct DriverInfo {
  std::string name;  // "sim"
  bool simulated = false;
  bool has_base = false;
  bool has_arm = false;
  int arm_joints = 0;
  bool has_gripper = false;
  bool has_chat = false;
  // Hardware envelope: the SafetyCore's effective limits are min(config, these).
  double max_linear_mps = 0.0;
  double max_angular_radps = 0.0;
  double max_joint_speed_radps = 0.0;
  JointArray joint_min_rad{};
  JointArray joint_max_rad{};
  // Dynamics the core uses to predict where a drive command ends.
  double linear_accel_mps2 = 0.0;         // normal accel/decel limit (0 = instantaneous)
  double brake_decel_mps2 = 0.0;          // deceleration after stop() (0 = instantaneous)
  std::vector<std::string> capabilities;  // e.g. "status", "teleop", "navigation", "arm", "chat"

  json::Object to_json() const;
};

// Driver health, polled by the SafetyCore on every control-loop tick. A driver that loses its
// hardware (no odometry from a ROS 2 base, a driver process that died, missed its heartbeat or
// answered garbage) reports a fault: the core stops it, enters safe stop ("driver_fault"),
// emits DRIVER_FAULT once (audited), latches ESTOP when SafetyConfig::file.estop_on_driver_fault,
// and refuses motion until the driver is healthy again (DRIVER_RECOVERED).
struct DriverHealth {
  bool ok = true;
  std::string fault;  // why, in plain words, when !ok
};

class Driver {
 public:
  virtual ~Driver() = default;
  Driver() = default;
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;

  virtual DriverInfo describe() const = 0;
  // Executes an already validated and limited command. An error means the hardware refused
  // it (the core reports it and stops nothing else).
  virtual Status apply(const ActuatorCommand& cmd) = 0;
  // Fast, idempotent, any thread, never throws (see the contract above).
  virtual void stop() noexcept = 0;
  // Integrates / services the hardware for `dt_ms` milliseconds (the core's loop period).
  virtual void step(int64_t dt_ms) = 0;
  virtual RobotState state() const = 0;
  // True while step() has nothing to integrate or service until the next apply(): the robot
  // is stopped and holds no target. The core's loop then slows to SafetyConfig::idle_tick_ms
  // (and wakes for the next command). The default keeps a driver that services hardware on
  // the full-rate loop.
  virtual bool at_rest() const { return false; }
  // Called under the same lock as step(); must be short (a flag or a timestamp check).
  virtual DriverHealth health() const { return {}; }
};

// ---- JSON (inline so that the header stands alone) ----

namespace driver_detail {
inline json::Value joints_json(const JointArray& a) {
  json::Array out;
  out.reserve(a.size());
  for (double d : a) out.emplace_back(d);
  return json::Value(std::move(out));
}
}  // namespace driver_detail

inline json::Object ActuatorCommand::to_json() const {
  json::Object o;
  if (drive) {
    o.set("drive", json::Object{{"linear_mps", drive->linear_mps},
                                {"angular_radps", drive->angular_radps},
                                {"duration_ms", drive->duration_ms}});
  }
  if (arm) {
    o.set("arm", json::Object{{"targets_rad", driver_detail::joints_json(arm->targets_rad)},
                              {"max_joint_speed_radps", arm->max_joint_speed_radps}});
  }
  if (gripper) o.set("gripper", *gripper == GripperAction::kOpen ? "open" : "close");
  if (stop) o.set("stop", true);
  return o;
}

inline json::Object RobotState::to_json() const {
  json::Object o;
  o.set("ts", ts);
  o.set("loop_latency_ms", loop_latency_ms);
  o.set("loop_count", static_cast<int64_t>(loop_count));
  o.set("paused", paused);
  o.set("stopped", stopped);
  o.set("t_ms", t_ms);
  o.set("base", json::Object{{"x", x},
                             {"y", y},
                             {"theta", theta},
                             {"linear_mps", linear_mps},
                             {"angular_radps", angular_radps},
                             {"target_linear_mps", target_linear_mps},
                             {"target_angular_radps", target_angular_radps},
                             {"drive_remaining_ms", drive_remaining_ms},
                             {"odometry_m", odometry_m}});
  o.set("arm", json::Object{{"joints_rad", driver_detail::joints_json(joints_rad)},
                            {"targets_rad", driver_detail::joints_json(joint_targets_rad)},
                            {"joint_speed_radps", joint_speed_radps}});
  o.set("gripper", json::Object{{"closed", gripper_closed}});
  if (battery_known) {
    o.set("battery_v", battery_v);
    o.set("battery_pct", battery_pct);
  }
  return o;
}

inline json::Object DriverInfo::to_json() const {
  json::Array caps;
  for (const auto& c : capabilities) caps.emplace_back(c);
  return json::Object{{"name", name},
                      {"simulated", simulated},
                      {"has_base", has_base},
                      {"has_arm", has_arm},
                      {"arm_joints", arm_joints},
                      {"has_gripper", has_gripper},
                      {"has_chat", has_chat},
                      {"max_linear_mps", max_linear_mps},
                      {"max_angular_radps", max_angular_radps},
                      {"max_joint_speed_radps", max_joint_speed_radps},
                      {"joint_min_rad", driver_detail::joints_json(joint_min_rad)},
                      {"joint_max_rad", driver_detail::joints_json(joint_max_rad)},
                      {"linear_accel_mps2", linear_accel_mps2},
                      {"brake_decel_mps2", brake_decel_mps2},
                      {"capabilities", json::Value(std::move(caps))}};
}

}  // namespace rcan::node
