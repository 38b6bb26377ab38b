// The `driver` block (docs/CONFIG.md §driver, docs/DRIVERS.md): which driver runs under the
// safety core and its settings. Read by blocks/driver.cpp; the process driver
// (drivers/process, ProcessDriverOptions::file) and the ROS 2 driver run with these structs.
// A member's initializer is its key's default.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace rcan::config {

struct SimDriverConfig {
  double wheel_base_m = 0.3;
  double max_accel_mps2 = 1.0;
  double max_angular_accel_radps2 = 2.0;
  uint32_t tick_hz = 50;
  uint32_t telemetry_hz = 5;
  uint32_t arm_joints = 6;
};

// driver.type process: a driver process on a Unix socket (docs/DRIVERS.md).
struct ProcessDriverConfig {
  std::vector<std::string> command;  // argv to start; empty: connect to `socket`
  std::string socket;                // an already-running driver process's socket
  uint32_t heartbeat_ms = 100;
  uint32_t heartbeat_timeout_ms = 500;
  uint32_t startup_timeout_ms = 5000;
  uint32_t restart_backoff_ms = 200;
  uint32_t restart_backoff_max_ms = 5000;
  // The hardware envelope (the safety core uses min(safety.*, these)).
  double max_linear_mps = 1.0;
  double max_angular_radps = 2.0;
  double linear_accel_mps2 = 0.0;  // 0: unknown (the core predicts an instant change)
  double brake_decel_mps2 = 0.0;
  // An arm and a gripper behind the process (0 joints = no arm): the safety core checks arm
  // targets against these ranges and speed before an apply frame carries them.
  uint32_t arm_joints = 0;  // 0..6
  double max_joint_speed_radps = 1.0;
  std::vector<double> joint_min_rad;  // per arm joint; missing entries -pi
  std::vector<double> joint_max_rad;  // missing entries +pi
  bool gripper = false;
};

// driver.ros2: a ROS 2 robot over DDS (docs/DRIVERS.md §ROS 2).
struct Ros2DriverConfig {
  uint32_t domain_id = 0;                           // ROS_DOMAIN_ID
  std::string ns;                                   // ROS namespace, e.g. "/robot1" ("" = none)
  std::string cmd_vel_topic = "cmd_vel";            // geometry_msgs/msg/Twist, out
  std::string odom_topic = "odom";                  // nav_msgs/msg/Odometry, in
  std::string joint_states_topic = "joint_states";  // sensor_msgs/msg/JointState, in
  std::string arm_topic;                // trajectory_msgs/msg/JointTrajectory, out ("" = no arm)
  std::vector<std::string> arm_joints;  // joint names, in the arm's slot order (≤ 6)
  std::string gripper_topic;            // "" = no gripper
  std::string gripper_type = "std_msgs/msg/Float64";  // or std_msgs/msg/Bool (true = closed)
  double gripper_open = 0.0;                          // Float64 value that opens
  double gripper_close = 1.0;                         // Float64 value that closes
  uint32_t cmd_rate_hz = 20;        // Twist republish rate (active drive, stop/ESTOP)
  uint32_t odom_timeout_ms = 1000;  // no odometry this long → driver fault (0 = never)
  uint32_t stop_repeat_ms = 1000;   // zero Twists keep coming this long after a stop
  double max_linear_mps = 1.0;      // the hardware's envelope (describe())
  double max_angular_radps = 2.0;
  double max_joint_speed_radps = 1.0;
  std::vector<double> joint_min_rad;  // per arm joint; missing entries -pi
  std::vector<double> joint_max_rad;  // missing entries +pi
};

struct DriverConfig {
  std::string type = "sim";  // "sim" | "ros2" | "process"
  SimDriverConfig sim;
  Ros2DriverConfig ros2;
  ProcessDriverConfig process;
};

}  // namespace rcan::config
