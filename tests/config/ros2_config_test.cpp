// The `driver.ros2` block (docs/DRIVERS.md §Configuration): its defaults, every key read into
// Ros2DriverConfig, and what is refused with its path (domain range, ROS 2 names, an arm topic
// without joint names, the gripper type, list lengths).
#include <gtest/gtest.h>

#include <string>

#include "config/config.h"

namespace rcan::config {
namespace {

Result<NodeConfig> parse(const std::string& driver) {
  ConfigOptions o;
  o.default_data_dir = "/var/lib/rcand-test";
  o.base_dir = "/etc/rcand";
  return parse_config_text(
      "rcan_version: \"1.2\"\nruri: rcan://local.rcan/rcan/sim-rover/0a1b2c3d\n" + driver, o);
}

TEST(Ros2Config, Defaults) {
  auto r = parse("driver:\n  type: ros2\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const Ros2DriverConfig& c = r->driver.ros2;
  EXPECT_EQ(r->driver.type, "ros2");
  EXPECT_EQ(c.domain_id, 0u);
  EXPECT_EQ(c.ns, "");
  EXPECT_EQ(c.cmd_vel_topic, "cmd_vel");
  EXPECT_EQ(c.odom_topic, "odom");
  EXPECT_EQ(c.joint_states_topic, "joint_states");
  EXPECT_EQ(c.arm_topic, "");
  EXPECT_TRUE(c.arm_joints.empty());
  EXPECT_EQ(c.gripper_topic, "");
  EXPECT_EQ(c.gripper_type, "std_msgs/msg/Float64");
  EXPECT_EQ(c.cmd_rate_hz, 20u);
  EXPECT_EQ(c.odom_timeout_ms, 1000u);
  EXPECT_EQ(c.stop_repeat_ms, 1000u);
  EXPECT_DOUBLE_EQ(c.max_linear_mps, 1.0);
  EXPECT_DOUBLE_EQ(c.max_angular_radps, 2.0);
}

TEST(Ros2Config, EveryKeyIsRead) {
  auto r = parse(
      "driver:\n  type: ros2\n  ros2:\n    domain_id: 232\n    namespace: /rover1\n"
      "    cmd_vel_topic: /mobile_base/cmd_vel\n    odom_topic: odometry/filtered\n"
      "    joint_states_topic: arm/joint_states\n"
      "    arm_topic: arm_controller/joint_trajectory\n    arm_joints: [a, b, c]\n"
      "    gripper_topic: gripper\n    gripper_type: std_msgs/msg/Bool\n"
      "    gripper_open: 0.1\n    gripper_close: 0.9\n    cmd_rate_hz: 50\n"
      "    odom_timeout_ms: 0\n    stop_repeat_ms: 250\n    max_linear_mps: 0.5\n"
      "    max_angular_radps: 1.2\n    max_joint_speed_radps: 0.7\n"
      "    joint_min_rad: [-1, -2]\n    joint_max_rad: [1, 2, 3]\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const Ros2DriverConfig& c = r->driver.ros2;
  EXPECT_EQ(c.domain_id, 232u);
  EXPECT_EQ(c.ns, "/rover1");
  EXPECT_EQ(c.cmd_vel_topic, "/mobile_base/cmd_vel");
  EXPECT_EQ(c.odom_topic, "odometry/filtered");
  EXPECT_EQ(c.joint_states_topic, "arm/joint_states");
  EXPECT_EQ(c.arm_topic, "arm_controller/joint_trajectory");
  EXPECT_EQ(c.arm_joints, (std::vector<std::string>{"a", "b", "c"}));
  EXPECT_EQ(c.gripper_topic, "gripper");
  EXPECT_EQ(c.gripper_type, "std_msgs/msg/Bool");
  EXPECT_DOUBLE_EQ(c.gripper_open, 0.1);
  EXPECT_DOUBLE_EQ(c.gripper_close, 0.9);
  EXPECT_EQ(c.cmd_rate_hz, 50u);
  EXPECT_EQ(c.odom_timeout_ms, 0u);
  EXPECT_EQ(c.stop_repeat_ms, 250u);
  EXPECT_DOUBLE_EQ(c.max_linear_mps, 0.5);
  EXPECT_DOUBLE_EQ(c.max_angular_radps, 1.2);
  EXPECT_DOUBLE_EQ(c.max_joint_speed_radps, 0.7);
  EXPECT_EQ(c.joint_min_rad, (std::vector<double>{-1, -2}));
  EXPECT_EQ(c.joint_max_rad, (std::vector<double>{1, 2, 3}));
}

TEST(Ros2Config, RefusedWithTheirPath) {
  struct Case {
    const char* ros2;
    const char* path;
  };
  const Case cases[] = {
      {"domain_id: 233", "driver.ros2.domain_id"},
      {"domain_id: -1", "driver.ros2.domain_id"},
      {"namespace: \"bad-ns\"", "driver.ros2.namespace"},
      {"cmd_vel_topic: \"\"", "driver.ros2.cmd_vel_topic"},
      {"cmd_vel_topic: \"cmd vel\"", "driver.ros2.cmd_vel_topic"},
      {"odom_topic: \"a//b\"", "driver.ros2.odom_topic"},
      {"joint_states_topic: \"2fast\"", "driver.ros2.joint_states_topic"},
      {"odom_topic: \"odom/\"", "driver.ros2.odom_topic"},
      {"arm_topic: arm", "driver.ros2.arm_joints"},
      {"gripper_type: std_msgs/msg/String", "driver.ros2.gripper_type"},
      {"cmd_rate_hz: 0", "driver.ros2.cmd_rate_hz"},
      {"max_linear_mps: 0", "driver.ros2.max_linear_mps"},
      {"arm_joints: [a, b, c, d, e, f, g]", "driver.ros2.arm_joints"},
      {"joint_min_rad: [1, 2, 3, 4, 5, 6, 7]", "driver.ros2.joint_min_rad"},
      {"topic: x", "driver.ros2"},
      {"joint_min_rad: [0, 1]\n    joint_max_rad: [1, 1]", "driver.ros2.joint_max_rad[1]"},
  };
  for (const auto& c : cases) {
    auto r = parse(std::string("driver:\n  type: ros2\n  ros2:\n    ") + c.ros2 + "\n");
    ASSERT_FALSE(r.ok()) << c.ros2;
    EXPECT_NE(r.error().field.find(c.path), std::string::npos)
        << c.ros2 << ": " << r.error().field << ": " << r.error().message;
  }
  EXPECT_FALSE(parse("driver:\n  type: ros3\n").ok());
  EXPECT_TRUE(parse("driver:\n  type: ros2\n  ros2:\n    namespace: /\n").ok());
}

}  // namespace
}  // namespace rcan::config
