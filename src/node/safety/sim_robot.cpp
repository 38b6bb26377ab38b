#include "node/safety/sim_robot.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "base/strings.h"

namespace rcan::node {
namespace {

constexpr int64_t kSubStepMs = 5;

// Moves `current` toward `target` by at most `max_delta`; snaps onto the target when the
// remaining gap is within rounding of max_delta (sums of sub-steps are not exact in binary).
double approach(double current, double target, double max_delta) {
  if (std::abs(target - current) <= max_delta * (1.0 + 1e-9) + 1e-12) return target;
  if (target > current) return std::min(target, current + max_delta);
  return std::max(target, current - max_delta);
}

double wrap_angle(double a) {
  constexpr double kPi = std::numbers::pi;
  a = std::remainder(a, 2.0 * kPi);  // [-pi, pi]
  if (a <= -kPi) a += 2.0 * kPi;
  return a;
}

}  // namespace

SimRobot::SimRobot(SimRobotConfig cfg) : cfg_(std::move(cfg)) {
  st_.x = cfg_.x;
  st_.y = cfg_.y;
  st_.theta = wrap_angle(cfg_.theta);
  st_.battery_known = cfg_.battery;
  if (cfg_.battery) {
    st_.battery_pct = 100.0;
    st_.battery_v = 12.6;
  }
  st_.stopped = true;
}

DriverInfo SimRobot::describe() const {
  DriverInfo d;
  d.name = "sim";
  d.simulated = true;
  d.has_base = true;
  d.has_arm = true;
  d.arm_joints = kArmJoints;
  d.has_gripper = true;
  d.has_chat = true;
  d.max_linear_mps = cfg_.max_linear_mps;
  d.max_angular_radps = cfg_.max_angular_radps;
  d.max_joint_speed_radps = cfg_.max_joint_speed_radps;
  d.joint_min_rad = cfg_.joint_min_rad;
  d.joint_max_rad = cfg_.joint_max_rad;
  d.linear_accel_mps2 = cfg_.linear_accel_mps2;
  d.brake_decel_mps2 = cfg_.brake_decel_mps2;
  d.capabilities = {"status", "teleop", "navigation", "arm", "gripper", "chat", "telemetry"};
  return d;
}

void SimRobot::stop() noexcept {
  // Wait-free: the next apply/step/state under mu_ absorbs it. Nothing can move in between,
  // because motion only happens inside step(), which absorbs pending stops first.
  stop_gen_.fetch_add(1, std::memory_order_acq_rel);
}

void SimRobot::absorb_stop_locked() const {
  const uint64_t g = stop_gen_.load(std::memory_order_acquire);
  if (g == seen_stop_gen_) return;
  seen_stop_gen_ = g;
  st_.target_linear_mps = 0.0;
  st_.target_angular_radps = 0.0;
  st_.drive_remaining_ms = 0;
  st_.joint_targets_rad = st_.joints_rad;
  st_.joint_speed_radps = 0.0;
  braking_ = true;
}

Status SimRobot::apply(const ActuatorCommand& cmd) {
  MutexLock lock(mu_);
  absorb_stop_locked();
  if (cmd.stop) {
    st_.target_linear_mps = 0.0;
    st_.target_angular_radps = 0.0;
    st_.drive_remaining_ms = 0;
    st_.joint_targets_rad = st_.joints_rad;
    st_.joint_speed_radps = 0.0;
    braking_ = true;
    st_.stopped = stopped_locked();
    return Status::Ok();
  }
  if (cmd.drive) {
    const auto& d = *cmd.drive;
    if (!std::isfinite(d.linear_mps) || !std::isfinite(d.angular_radps) || d.duration_ms < 0)
      return Error(ErrorCode::kSchemaValidationFailed, "drive command has a non-finite value",
                   "drive");
    st_.target_linear_mps = std::clamp(d.linear_mps, -cfg_.max_linear_mps, cfg_.max_linear_mps);
    st_.target_angular_radps =
        std::clamp(d.angular_radps, -cfg_.max_angular_radps, cfg_.max_angular_radps);
    st_.drive_remaining_ms = d.duration_ms;
    if (d.duration_ms == 0) {
      st_.target_linear_mps = 0.0;
      st_.target_angular_radps = 0.0;
    }
    braking_ = false;
  }
  if (cmd.arm) {
    const auto& a = *cmd.arm;
    for (int i = 0; i < kArmJoints; ++i) {
      if (!std::isfinite(a.targets_rad[i]))
        return Error(ErrorCode::kSchemaValidationFailed, "arm target is not finite", "arm");
      st_.joint_targets_rad[i] =
          std::clamp(a.targets_rad[i], cfg_.joint_min_rad[i], cfg_.joint_max_rad[i]);
    }
    double speed =
        a.max_joint_speed_radps > 0.0 ? a.max_joint_speed_radps : cfg_.max_joint_speed_radps;
    st_.joint_speed_radps = std::min(speed, cfg_.max_joint_speed_radps);
  }
  if (cmd.gripper) st_.gripper_closed = (*cmd.gripper == GripperAction::kClose);
  st_.stopped = stopped_locked();
  return Status::Ok();
}

bool SimRobot::stopped_locked() const {
  if (st_.linear_mps != 0.0 || st_.angular_radps != 0.0) return false;
  if (st_.target_linear_mps != 0.0 || st_.target_angular_radps != 0.0) return false;
  for (int i = 0; i < kArmJoints; ++i)
    if (st_.joints_rad[i] != st_.joint_targets_rad[i]) return false;
  return true;
}

void SimRobot::integrate_locked(double dt) {
  // Velocities: toward the targets under the acceleration (or braking) limits.
  const double lin_rate = braking_ ? cfg_.brake_decel_mps2 : cfg_.linear_accel_mps2;
  const double ang_rate = braking_ ? cfg_.brake_angular_decel_radps2 : cfg_.angular_accel_radps2;
  const double v0 = st_.linear_mps;
  const double w0 = st_.angular_radps;
  const double v1 =
      lin_rate > 0 ? approach(v0, st_.target_linear_mps, lin_rate * dt) : st_.target_linear_mps;
  const double w1 = ang_rate > 0 ? approach(w0, st_.target_angular_radps, ang_rate * dt)
                                 : st_.target_angular_radps;
  // Within a sub-step the velocity changes linearly (or saturates part-way); the mean of the
  // end points is exact when it does not saturate, and within one sub-step's error otherwise.
  auto mean_velocity = [dt](double a, double b, double rate) {
    if (a == b || rate <= 0) return b;
    const double t_sat = std::abs(b - a) / rate;  // time to reach b
    if (t_sat >= dt) return 0.5 * (a + b);
    return (0.5 * (a + b) * t_sat + b * (dt - t_sat)) / dt;
  };
  const double v = mean_velocity(v0, v1, lin_rate);
  const double w = mean_velocity(w0, w1, ang_rate);
  const double theta_mid = st_.theta + 0.5 * w * dt;
  st_.x += v * std::cos(theta_mid) * dt;
  st_.y += v * std::sin(theta_mid) * dt;
  st_.theta = wrap_angle(st_.theta + w * dt);
  st_.odometry_m += std::abs(v) * dt;
  st_.linear_mps = v1;
  st_.angular_radps = w1;
  if (braking_ && v1 == 0.0 && w1 == 0.0) braking_ = false;

  // Arm.
  for (int i = 0; i < kArmJoints; ++i)
    st_.joints_rad[i] =
        approach(st_.joints_rad[i], st_.joint_targets_rad[i], st_.joint_speed_radps * dt);

  if (cfg_.battery) {
    drain_pct_ += (0.002 + 0.05 * std::abs(v)) * dt;
    st_.battery_pct = std::max(0.0, 100.0 - drain_pct_);
    st_.battery_v = 10.5 + 2.1 * st_.battery_pct / 100.0;
  }
}

void SimRobot::step(int64_t dt_ms) {
  if (dt_ms <= 0) return;
  MutexLock lock(mu_);
  absorb_stop_locked();
  if (st_.drive_remaining_ms == 0 && stopped_locked()) {
    // At rest nothing moves: only the clock and the battery's idle drain advance, sub-step by
    // sub-step as below (the same sums), without the trigonometry of integrate_locked. The
    // safety loop rests up to a second between ticks, i.e. 200 sub-steps.
    braking_ = false;
    st_.linear_mps = st_.target_linear_mps;  // all zero; as integrate_locked leaves them
    st_.angular_radps = st_.target_angular_radps;
    for (int64_t left = dt_ms; left > 0; left -= kSubStepMs) {
      const double dt = static_cast<double>(std::min(left, kSubStepMs)) / 1000.0;
      if (cfg_.battery) drain_pct_ += (0.002 + 0.05 * 0.0) * dt;
    }
    st_.t_ms += dt_ms;
    if (cfg_.battery) {
      st_.battery_pct = std::max(0.0, 100.0 - drain_pct_);
      st_.battery_v = 10.5 + 2.1 * st_.battery_pct / 100.0;
    }
    st_.stopped = true;
    return;
  }
  int64_t left = dt_ms;
  while (left > 0) {
    int64_t sub = std::min(left, kSubStepMs);
    if (st_.drive_remaining_ms > 0) sub = std::min(sub, st_.drive_remaining_ms);
    integrate_locked(static_cast<double>(sub) / 1000.0);
    left -= sub;
    st_.t_ms += sub;
    if (st_.drive_remaining_ms > 0) {
      st_.drive_remaining_ms -= sub;
      if (st_.drive_remaining_ms == 0) {
        st_.target_linear_mps = 0.0;
        st_.target_angular_radps = 0.0;
      }
    }
  }
  st_.stopped = stopped_locked();
}

bool SimRobot::at_rest() const {
  MutexLock lock(mu_);
  absorb_stop_locked();
  return stopped_locked();
}

RobotState SimRobot::state() const {
  MutexLock lock(mu_);
  absorb_stop_locked();
  st_.stopped = stopped_locked();
  return st_;
}

// ---------------------------------------------------------------------------------------------

namespace {

bool has(const std::string& q, std::string_view word) { return q.find(word) != std::string::npos; }

std::string fmt(const char* f, double a) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, a);
  return buf;
}

std::string pose_sentence(const RobotState& s) {
  char buf[160];
  std::snprintf(buf, sizeof buf,
                "I am at x=%.2f m, y=%.2f m, heading %.0f degrees (odometry frame).", s.x, s.y,
                s.theta * 180.0 / std::numbers::pi);
  return buf;
}

std::string motion_sentence(const RobotState& s, const ChatContext& ctx) {
  std::string out;
  if (ctx.estop_active) {
    out = "Emergency stop is latched";
    if (!ctx.estop_reason.empty()) out += " (" + ctx.estop_reason + ")";
    out += "; I will not move until an authorised RESUME.";
  } else if (ctx.safe_stop_active) {
    out = "I am in safe-stop";
    if (!ctx.safe_stop_reason.empty()) out += " (" + ctx.safe_stop_reason + ")";
    out += "; a new command from a live session clears it.";
  } else if (s.stopped) {
    out = "I am stopped and ready.";
  } else {
    out = "I am moving: " + fmt("%.2f m/s", s.linear_mps) + ", " +
          fmt("%.2f rad/s", s.angular_radps) + ".";
  }
  return out;
}

std::string battery_sentence(const RobotState& s) {
  if (!s.battery_known) return "I have no battery gauge.";
  char buf[96];
  std::snprintf(buf, sizeof buf, "Battery at %.1f%% (%.2f V).", s.battery_pct, s.battery_v);
  return buf;
}

std::string arm_sentence(const RobotState& s) {
  std::string out = "Arm joints (rad):";
  for (int i = 0; i < kArmJoints; ++i) out += fmt(i == 0 ? " %.2f" : ", %.2f", s.joints_rad[i]);
  out += s.gripper_closed ? "; gripper closed." : "; gripper open.";
  return out;
}

}  // namespace

std::string chat(std::string_view question, const RobotState& s, const ChatContext& ctx) {
  const std::string q = ascii_lower(question);
  if (has(q, "where") || has(q, "position") || has(q, "pose") || has(q, "location"))
    return pose_sentence(s);
  if (has(q, "battery") || has(q, "charge") || has(q, "power")) return battery_sentence(s);
  if (has(q, "arm") || has(q, "joint") || has(q, "gripper")) return arm_sentence(s);
  if (has(q, "speed") || has(q, "velocity") || has(q, "fast") || has(q, "moving"))
    return motion_sentence(s, ctx) + " Odometry " + fmt("%.2f m.", s.odometry_m);
  if (has(q, "status") || has(q, "how are you") || has(q, "state") || has(q, "estop") ||
      has(q, "stop"))
    return motion_sentence(s, ctx) + " " + pose_sentence(s) + " " + battery_sentence(s);
  if (has(q, "who are you") || has(q, "what are you") || has(q, "name"))
    return "I am the " + ctx.robot_name + ": a differential-drive base with a 6-joint arm.";
  return "I can answer: where are you, status, battery, arm, speed. I do not execute commands "
         "from chat.";
}

}  // namespace rcan::node
