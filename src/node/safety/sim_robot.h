// SimRobot — the node's embedded default driver: a differential-drive base and a 6-joint arm
// whose state integrates over time, plus a gripper and a simple battery model.
//
// Model (deterministic: the state depends only on the sequence of apply()/step()/stop()):
//   * Base: unicycle  x' = v cos(theta), y' = v sin(theta), theta' = w. v and w move toward
//     their targets at most at linear_accel_mps2 / angular_accel_radps2; after stop() they
//     fall at brake_decel_mps2 / brake_angular_decel_radps2. A drive command holds its
//     targets for duration_ms of integrated time, then the targets return to 0.
//   * Arm: each joint moves toward its target at the commanded joint speed (capped by
//     max_joint_speed_radps), stopping exactly on the target. stop() freezes the targets at
//     the current positions.
//   * step(dt_ms) integrates in sub-steps of at most 5 ms, split exactly where a drive
//     command ends.
//   * Battery: 100 % at start, drains 0.002 %/s idle plus 0.05 %/s per m/s of speed.
//
// Thread safety: stop() is wait-free (an atomic generation counter); every other method
// takes the robot's own mutex briefly, so the object is safe to share even outside the
// SafetyCore (which serialises apply/step/state anyway).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <string_view>

#include "base/thread_annotations.h"
#include "node/safety/driver.h"

namespace rcan::node {

struct SimRobotConfig {
  double max_linear_mps = 1.5;
  double max_angular_radps = 3.0;
  double linear_accel_mps2 = 1.0;
  double angular_accel_radps2 = 4.0;
  double brake_decel_mps2 = 3.0;
  double brake_angular_decel_radps2 = 8.0;
  double max_joint_speed_radps = 2.0;
  JointArray joint_min_rad{-3.1, -2.0, -2.5, -3.1, -2.0, -3.1};
  JointArray joint_max_rad{3.1, 2.0, 2.5, 3.1, 2.0, 3.1};
  // Initial pose.
  double x = 0.0;
  double y = 0.0;
  double theta = 0.0;
  bool battery = true;  // simulate a battery
};

class SimRobot final : public Driver {
 public:
  explicit SimRobot(SimRobotConfig cfg = {});

  DriverInfo describe() const override;
  Status apply(const ActuatorCommand& cmd) override;
  void stop() noexcept override;
  void step(int64_t dt_ms) override;
  RobotState state() const override;
  bool at_rest() const override;

  // How many times stop() has been called (for tests and benchmarks).
  uint64_t stop_count() const { return stop_gen_.load(std::memory_order_acquire); }

 private:
  // Applies a pending stop() (if any) to the state.
  void absorb_stop_locked() const REQUIRES(mu_);
  void integrate_locked(double dt_s) REQUIRES(mu_);
  bool stopped_locked() const REQUIRES(mu_);

  const SimRobotConfig cfg_;
  mutable Mutex mu_;
  mutable RobotState st_ GUARDED_BY(mu_);
  mutable bool braking_ GUARDED_BY(mu_) = false;  // after stop(): decelerate at the brake rates
  mutable uint64_t seen_stop_gen_ GUARDED_BY(mu_) = 0;
  double drain_pct_ GUARDED_BY(mu_) = 0.0;
  std::atomic<uint64_t> stop_gen_{0};
};

// The chat capability: answers simple questions from the robot's status, honestly and
// briefly ("where are you" → pose, "status" → moving/stopped/ESTOP, "battery", "arm",
// "speed"). Anything else gets a one-line list of what it can answer.
struct ChatContext {
  bool estop_active = false;
  std::string estop_reason;
  bool safe_stop_active = false;
  std::string safe_stop_reason;
  std::string robot_name = "rcan simulated robot";
};
std::string chat(std::string_view question, const RobotState& state, const ChatContext& ctx = {});

}  // namespace rcan::node
