// `driver`: which driver runs the robot (the simulator, a ROS 2 robot over DDS, or a driver
// process) and its settings
// (docs/CONFIG.md §driver).
#include <string>
#include <string_view>
#include <utility>

#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

Table<SimDriverConfig> sim_rows() {
  using S = Rows<SimDriverConfig>;
  return {
      S::field("wheel_base_m", Pos(), &SimDriverConfig::wheel_base_m)
          .doc("metres between the simulated wheels"),
      S::field("max_accel_mps2", Pos(), &SimDriverConfig::max_accel_mps2)
          .doc("the simulated base's linear acceleration"),
      S::field("max_angular_accel_radps2", Pos(), &SimDriverConfig::max_angular_accel_radps2)
          .doc("the simulated base's angular acceleration"),
      S::field("tick_hz", Int(1, 1000), &SimDriverConfig::tick_hz)
          .doc("the control loop's rate, whatever the driver (it polls the driver's health every "
               "tick)"),
      S::field("telemetry_hz", Int(1, 100), &SimDriverConfig::telemetry_hz)
          .doc("telemetry rate, at most `tick_hz`"),
      S::field("arm_joints", Int(1, 16), &SimDriverConfig::arm_joints)
          .doc("the simulated arm's joints"),
      S::check([](const At& sim, SimDriverConfig& sd, Ctx&) {
        if (sd.telemetry_hz > sd.tick_hz)
          fail(sim["telemetry_hz"].path, "must not exceed tick_hz", "out_of_range");
      }),
  };
}

Table<ProcessDriverConfig> process_rows() {
  using P = Rows<ProcessDriverConfig>;
  return {
      P::field("command", Arr(Str(), 256), &ProcessDriverConfig::command)
          .doc("the driver process's argv (`argv[0]` searched in `PATH`; give scripts by absolute "
               "path); rcand starts it and hands it a connected socket as fd 3"),
      P::path("socket", Str(107), &ProcessDriverConfig::socket)
          .doc("path (≤ 107 bytes, relative to the config file): instead of `command`, connect to "
               "a driver process already listening there; `driver.type: process` needs `command` "
               "or `socket`"),
      P::field("heartbeat_ms", Int(10, 10000), &ProcessDriverConfig::heartbeat_ms)
          .doc("how often rcand sends a heartbeat"),
      P::field("heartbeat_timeout_ms", Int(20, 60000), &ProcessDriverConfig::heartbeat_timeout_ms)
          .doc("above `heartbeat_ms`: nothing received from the process for this long is a driver "
               "fault"),
      P::field("startup_timeout_ms", Int(100, 120000), &ProcessDriverConfig::startup_timeout_ms)
          .doc("a new process must answer `describe` and heartbeat within this (rcand's start "
               "waits for the first one up to this long)"),
      P::field("restart_backoff_ms", Int(10, 60000), &ProcessDriverConfig::restart_backoff_ms)
          .doc("the first restart delay after a fault, doubled per fault up to "
               "`restart_backoff_max_ms`; back to the first after 10 s healthy"),
      P::field("restart_backoff_max_ms", Int(10, 600000),
               &ProcessDriverConfig::restart_backoff_max_ms)
          .doc("the longest restart delay (≥ `restart_backoff_ms`)"),
      P::field("max_linear_mps", Pos(), &ProcessDriverConfig::max_linear_mps)
          .doc("the hardware envelope the safety core takes the minimum with "
               "(`safety.max_linear_speed_mps`, …); a process whose `describe` reports a lower "
               "maximum is a fault"),
      P::field("max_angular_radps", Pos(), &ProcessDriverConfig::max_angular_radps)
          .doc("the same, angular"),
      P::field("linear_accel_mps2", NonNeg(), &ProcessDriverConfig::linear_accel_mps2)
          .doc(
              "the base's dynamics for the core's stopping-distance prediction (0: instantaneous)"),
      P::field("brake_decel_mps2", NonNeg(), &ProcessDriverConfig::brake_decel_mps2)
          .doc("the same, braking"),
      P::field("arm_joints", Int(0, 6), &ProcessDriverConfig::arm_joints)
          .doc("an arm behind the process with this many joints (0: none; arm commands are then "
               "refused 422 `unsupported`)"),
      P::field("max_joint_speed_radps", Pos(), &ProcessDriverConfig::max_joint_speed_radps)
          .doc("the arm's joint speed envelope (the core takes the minimum with its own)"),
      P::field("joint_min_rad", Arr(Num(), 6), &ProcessDriverConfig::joint_min_rad)
          .doc("up to 6 numbers, min < max per joint; only with `arm_joints` ≥ 1: the arm's joint "
               "ranges (missing entries −π); targets outside are clamped or refused by the safety "
               "policy before the `apply` frame carries them"),
      P::field("joint_max_rad", Arr(Num(), 6), &ProcessDriverConfig::joint_max_rad)
          .doc("the same, upper bounds (missing entries +π)"),
      P::field("gripper", Bool(), &ProcessDriverConfig::gripper)
          .doc("true: a gripper behind the process (`gripper_open` / `gripper_close` reach it as "
               "`{\"gripper\":\"open\"|\"close\"}`); false: refused 422"),
      P::check([](const At& at, ProcessDriverConfig& p, Ctx&) {
        for (size_t i = 0; i < p.joint_min_rad.size() && i < p.joint_max_rad.size(); ++i)
          if (!(p.joint_min_rad[i] < p.joint_max_rad[i]))
            fail(at["joint_max_rad"][i].path, "must be above joint_min_rad", "invalid_value");
        if (p.arm_joints == 0 && (!p.joint_min_rad.empty() || !p.joint_max_rad.empty()))
          fail(at["arm_joints"].path, "joint ranges need an arm (arm_joints 1..6)",
               "invalid_value");
        if (p.heartbeat_timeout_ms <= p.heartbeat_ms)
          fail(at["heartbeat_timeout_ms"].path, "must exceed heartbeat_ms", "out_of_range");
        if (p.restart_backoff_max_ms < p.restart_backoff_ms)
          fail(at["restart_backoff_max_ms"].path, "must not be below restart_backoff_ms",
               "out_of_range");
      }),
  };
}

bool ros2_name_ok(const std::string& n) {
  if (n.empty() || n == "/") return false;
  size_t i = n[0] == '/' ? 1 : 0;
  bool token_start = true;
  for (; i < n.size(); ++i) {
    const char c = n[i];
    if (c == '/') {
      if (token_start) return false;  // "//" or a leading "//"
      token_start = true;
      continue;
    }
    const bool alpha = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_';
    const bool digit = c >= '0' && c <= '9';
    if (!alpha && !digit) return false;
    if (token_start && digit) return false;
    token_start = false;
  }
  return !token_start;  // no trailing '/'
}

Table<Ros2DriverConfig> ros2_rows() {
  using R = Rows<Ros2DriverConfig>;
  return {
      R::field("domain_id", Int(0, 232), &Ros2DriverConfig::domain_id)
          .doc("the robot's `ROS_DOMAIN_ID`"),
      R::field("namespace", Str(256), &Ros2DriverConfig::ns).doc("ROS 2 namespace; empty: none"),
      R::field("cmd_vel_topic", Str(256), &Ros2DriverConfig::cmd_vel_topic)
          .doc("geometry_msgs/msg/Twist, out; ROS 2 names are relative to the namespace unless "
               "they start with `/`"),
      R::field("odom_topic", Str(256), &Ros2DriverConfig::odom_topic)
          .doc("nav_msgs/msg/Odometry, in"),
      R::field("joint_states_topic", Str(256), &Ros2DriverConfig::joint_states_topic)
          .doc("sensor_msgs/msg/JointState, in"),
      R::field("arm_topic", Str(256), &Ros2DriverConfig::arm_topic)
          .doc("trajectory_msgs/msg/JointTrajectory, out; empty: no arm"),
      R::field("arm_joints", Arr(Str(256), 6), &Ros2DriverConfig::arm_joints)
          .doc("up to 6 joint names, in the arm's slot order (required with `arm_topic`)"),
      R::field("gripper_topic", Str(256), &Ros2DriverConfig::gripper_topic)
          .doc("empty: no gripper"),
      R::field("gripper_type", Enum({"std_msgs/msg/Float64", "std_msgs/msg/Bool"}),
               &Ros2DriverConfig::gripper_type)
          .doc("`std_msgs/msg/Bool`: true is closed"),
      R::field("gripper_open", Num(), &Ros2DriverConfig::gripper_open)
          .doc("the Float64 value that opens"),
      R::field("gripper_close", Num(), &Ros2DriverConfig::gripper_close)
          .doc("the Float64 value that closes"),
      R::field("cmd_rate_hz", Int(1, 1000), &Ros2DriverConfig::cmd_rate_hz)
          .doc("Twist republish rate (drives, and zero Twists while stopped)"),
      R::field("odom_timeout_ms", Int(0, 600000), &Ros2DriverConfig::odom_timeout_ms)
          .doc("no odometry this long is a driver fault; 0: no check"),
      R::field("stop_repeat_ms", Int(0, 600000), &Ros2DriverConfig::stop_repeat_ms)
          .doc("zero Twists keep coming this long after a stop"),
      R::field("max_linear_mps", Pos(), &Ros2DriverConfig::max_linear_mps)
          .doc("the hardware envelope"),
      R::field("max_angular_radps", Pos(), &Ros2DriverConfig::max_angular_radps)
          .doc("the hardware envelope"),
      R::field("max_joint_speed_radps", Pos(), &Ros2DriverConfig::max_joint_speed_radps)
          .doc("the hardware envelope"),
      R::field("joint_min_rad", Arr(Num(), 6), &Ros2DriverConfig::joint_min_rad)
          .doc("up to 6 numbers, each max above its min; missing entries −π"),
      R::field("joint_max_rad", Arr(Num(), 6), &Ros2DriverConfig::joint_max_rad)
          .doc("the same, upper bounds (missing entries +π)"),
      R::check([](const At& ros2, Ros2DriverConfig& r, Ctx&) {
        if (!r.arm_topic.empty() && r.arm_joints.empty())
          fail(ros2["arm_joints"].path, "an arm topic needs the arm's joint names",
               "invalid_value");
        for (size_t i = 0; i < r.joint_min_rad.size() && i < r.joint_max_rad.size(); ++i)
          if (!(r.joint_min_rad[i] < r.joint_max_rad[i]))
            fail(ros2["joint_max_rad"][i].path, "must be above joint_min_rad", "invalid_value");
        // ROS 2 names: letters, digits, '_' and '/' separators; no empty or digit-led token.
        const std::pair<const char*, const std::string*> names[] = {
            {"namespace", &r.ns},          {"cmd_vel_topic", &r.cmd_vel_topic},
            {"odom_topic", &r.odom_topic}, {"joint_states_topic", &r.joint_states_topic},
            {"arm_topic", &r.arm_topic},   {"gripper_topic", &r.gripper_topic}};
        for (const auto& [key, value] : names) {
          const bool optional = std::string_view(key) == "namespace" ||
                                std::string_view(key) == "arm_topic" ||
                                std::string_view(key) == "gripper_topic";
          if ((value->empty() && optional) || (*value == "/" && key == names[0].first)) continue;
          if (!ros2_name_ok(*value))
            fail(ros2[key].path,
                 "not a ROS 2 name (letters, digits, '_', '/' between tokens, no token starting "
                 "with a digit)",
                 "invalid_value");
        }
      }),
  };
}

}  // namespace

Table<NodeConfig> driver_blocks() {
  using D = Rows<DriverConfig>;
  return {Rows<NodeConfig>::block(
      "driver",
      Table<DriverConfig>{
          D::field("type", Enum({"sim", "ros2", "process"}), &DriverConfig::type)
              .doc("`sim` (the embedded simulator), `ros2` (a ROS 2 robot over DDS) or `process` "
                   "(a driver process); docs/DRIVERS.md. Profiles' `bridge` blocks are kept, not "
                   "driven"),
          D::block("sim", sim_rows(), &DriverConfig::sim),
          D::block("ros2", ros2_rows(), &DriverConfig::ros2),
          D::block("process", process_rows(), &DriverConfig::process),
          D::check([](const At& at, DriverConfig& d, Ctx&) {
            if (d.type == "process" && d.process.command.empty() && d.process.socket.empty())
              fail(at["process"].path, "driver.type process needs command or socket", "required");
          }),
      },
      &NodeConfig::driver)};
}

}  // namespace rcan::config::internal
