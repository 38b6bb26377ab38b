// Ros2Driver — drives a ROS 2 robot over plain DDS (Eclipse Cyclone DDS), with no ROS
// installation on the node: ROS 2 topics are DDS topics "rt/<namespace>/<topic>" of types
// "<pkg>::msg::dds_::<Type>_" in CDR (docs/DRIVERS.md §ROS 2 has the mapping table).
//
//   out  cmd_vel       geometry_msgs/msg/Twist             reliable, volatile, keep-last 10
//   out  arm_topic     trajectory_msgs/msg/JointTrajectory  (same)
//   out  gripper_topic std_msgs/msg/Float64 | Bool          (same)
//   in   odom          nav_msgs/msg/Odometry               best effort, keep-last 5
//   in   joint_states  sensor_msgs/msg/JointState          (same; reliable publishers match)
//
// Behaviour:
//   * A drive publishes its Twist at once and again every 1/cmd_rate_hz while it lasts (the
//     republishing rides on step(), the safety core's loop, so the rate is at most the loop's);
//     when its duration ends, a zero Twist.
//   * stop() (ESTOP, safe stops, the core's every-tick stop while ESTOP is latched) publishes a
//     zero Twist from the calling thread at once, unless a zero Twist went out less than one
//     period ago; zero Twists then keep coming at cmd_rate_hz for stop_repeat_ms after the
//     last stop() — while ESTOP is latched the core calls stop() on every tick, so they keep
//     coming for as long as the latch holds. A stop() racing an apply() wins: a Twist whose
//     apply() began before the stop() is not written after it.
//   * Arm commands publish a JointTrajectory with one point (time_from_start from the joint
//     speed); stop() during an arm motion publishes an empty trajectory (the controller holds).
//   * Odometry and joint states received are the state(); a sample with a non-finite value
//     or a degenerate quaternion is dropped. health() is a fault when no odometry arrived for
//     odom_timeout_ms — counted from start until the first sample, so a robot that never
//     answers is a fault too.
//
// Thread safety: stop() takes no lock but the short publish lock (held for one DDS write);
// the rest is serialised by the safety core and guarded by the driver's own mutex as well.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "config/driver_config.h"
#include "drivers/ros2/ros2_msgs.h"
#include "node/safety/driver.h"
#include "rcan/result.h"

namespace rcan::drivers::ros2 {

class Ros2Driver final : public node::Driver {
 public:
  // Joins DDS domain cfg.domain_id (Cyclone reads CYCLONEDDS_URI for its own configuration)
  // and creates the topics, readers and writers. An error names what failed.
  static Result<std::unique_ptr<Ros2Driver>> create(const config::Ros2DriverConfig& cfg);
  ~Ros2Driver() override;

  node::DriverInfo describe() const override;
  Status apply(const node::ActuatorCommand& cmd) override;
  void stop() noexcept override;
  void step(int64_t dt_ms) override;
  node::RobotState state() const override;
  // Never at rest: the loop must keep running to republish commands and read the robot.
  bool at_rest() const override { return false; }
  node::DriverHealth health() const override;

  // The DDS topic names in use (for logs and tests).
  const std::string& cmd_vel_topic() const { return cmd_vel_name_; }
  const std::string& odom_topic() const { return odom_name_; }
  // Twists written so far (zero ones included), zero ones alone, and failed writes.
  uint64_t twists_written() const { return twists_.load(std::memory_order_relaxed); }
  uint64_t zero_twists_written() const { return zero_twists_.load(std::memory_order_relaxed); }
  uint64_t write_failures() const { return write_failures_.load(std::memory_order_relaxed); }

 private:
  explicit Ros2Driver(const config::Ros2DriverConfig& cfg);
  Status open();
  void close() noexcept;

  // Writes a Twist unless a stop() came after `gen`: 1 written, 0 a stop() came first (nothing
  // written), a negative DDS return code when the write failed.
  int write_twist(double v, double w, uint64_t gen, int64_t now) EXCLUDES(pub_mu_);
  // Writes a zero Twist unless one went out less than one period ago (a failed write is
  // retried on the next call).
  void write_zero_if_due(int64_t now) noexcept EXCLUDES(pub_mu_);
  void write_arm_hold() noexcept;
  void take_samples_locked(int64_t now) REQUIRES(mu_);
  void absorb_stop_locked() REQUIRES(mu_);
  // The parts of apply(): every part checked first, then each written in turn; `ended` when a
  // stop() won the race and the rest of the command must not be written.
  Status check_command(const node::ActuatorCommand& cmd) const REQUIRES(mu_);
  Status drive_locked(const node::DriveCommand& d, uint64_t gen, int64_t now, bool& ended)
      REQUIRES(mu_);
  Status arm_locked(const node::ArmCommand& a, uint64_t gen, int64_t now, bool& ended)
      REQUIRES(mu_);
  Status gripper_locked(node::GripperAction g) REQUIRES(mu_);

  const config::Ros2DriverConfig cfg_;
  const int64_t period_ns_;
  const int64_t stop_repeat_ns_;
  const int64_t start_ns_;
  std::string cmd_vel_name_, odom_name_, joint_states_name_, arm_name_, gripper_name_;
  std::vector<char*> joint_name_ptrs_;  // into cfg_.arm_joints (immutable)
  size_t arm_slots_ = 0;

  // DDS entities (0 = none); created in open(), deleted with the participant.
  dds_entity_t participant_ = 0;
  dds_entity_t cmd_vel_writer_ = 0, arm_writer_ = 0, gripper_writer_ = 0;
  dds_entity_t odom_reader_ = 0, joint_reader_ = 0;

  // The stop path: a generation counter (apply() compares), the last stop() time, and the
  // publish lock (held only around one write) with what was last written.
  std::atomic<uint64_t> stop_gen_{0};
  std::atomic<int64_t> last_stop_ns_;
  std::atomic<bool> arm_moving_{false};
  mutable Mutex pub_mu_;
  bool last_was_zero_ GUARDED_BY(pub_mu_) = false;
  int64_t last_pub_ns_ GUARDED_BY(pub_mu_) = 0;
  std::atomic<uint64_t> twists_{0}, zero_twists_{0}, write_failures_{0};

  // Everything else, under mu_ (the safety core serialises these calls anyway).
  mutable Mutex mu_;
  node::RobotState st_ GUARDED_BY(mu_);
  uint64_t seen_stop_gen_ GUARDED_BY(mu_) = 0;
  bool drive_active_ GUARDED_BY(mu_) = false;
  double drive_v_ GUARDED_BY(mu_) = 0, drive_w_ GUARDED_BY(mu_) = 0;
  uint64_t drive_gen_ GUARDED_BY(mu_) = 0;
  int64_t drive_end_ns_ GUARDED_BY(mu_) = 0;
  int64_t next_repub_ns_ GUARDED_BY(mu_) = 0;
  int64_t arm_until_ns_ GUARDED_BY(mu_) = 0;
  bool have_odom_ GUARDED_BY(mu_) = false;
  std::atomic<int64_t> last_odom_ns_{0};
  std::atomic<uint64_t> rejected_samples_{0};
};

}  // namespace rcan::drivers::ros2
