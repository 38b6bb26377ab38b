#include "driver_factory.h"

#include <numbers>

#include "drivers/process/process_driver.h"
#include "drivers/ros2/ros2_driver.h"
#include "runtime/log.h"

namespace rcan::rcand {
namespace {

drivers::ProcessDriverOptions process_options(const config::ProcessDriverConfig& p) {
  drivers::ProcessDriverOptions o;
  o.file = p;
  node::DriverInfo& i = o.info;
  i.name = "process";
  i.has_base = true;
  i.max_linear_mps = p.max_linear_mps;
  i.max_angular_radps = p.max_angular_radps;
  i.linear_accel_mps2 = p.linear_accel_mps2;
  i.brake_decel_mps2 = p.brake_decel_mps2;
  i.capabilities = {"status", "teleop", "navigation"};
  i.has_arm = p.arm_joints > 0;
  i.arm_joints = static_cast<int>(p.arm_joints);
  i.max_joint_speed_radps = p.max_joint_speed_radps;
  for (int j = 0; j < node::kArmJoints; ++j) {
    const auto at = static_cast<size_t>(j);
    i.joint_min_rad[at] = at < p.joint_min_rad.size() ? p.joint_min_rad[at] : -std::numbers::pi;
    i.joint_max_rad[at] = at < p.joint_max_rad.size() ? p.joint_max_rad[at] : std::numbers::pi;
  }
  if (i.has_arm) i.capabilities.push_back("arm");
  i.has_gripper = p.gripper;
  if (i.has_gripper) i.capabilities.push_back("gripper");
  return o;
}

}  // namespace

Result<std::unique_ptr<node::Driver>> make_driver(const config::NodeConfig& cfg,
                                                  const node::SimRobotConfig& sim) {
  if (cfg.driver.type == "ros2") {
    auto d = drivers::ros2::Ros2Driver::create(cfg.driver.ros2);
    if (!d.ok()) return d.error();
    log(LogLevel::kInfo, "driver",
        json::Object{{"type", "ros2"},
                     {"domain_id", static_cast<int64_t>(cfg.driver.ros2.domain_id)},
                     {"cmd_vel", (*d)->cmd_vel_topic()},
                     {"odom", (*d)->odom_topic()}});
    return std::unique_ptr<node::Driver>(std::move(d).value());
  }
  if (cfg.driver.type == "process") {
    auto d = std::make_unique<drivers::ProcessDriver>(process_options(cfg.driver.process));
    if (Status s = d->start(); !s.ok()) return s.error();
    return std::unique_ptr<node::Driver>(std::move(d));
  }
  return std::unique_ptr<node::Driver>(std::make_unique<node::SimRobot>(sim));
}

}  // namespace rcan::rcand
