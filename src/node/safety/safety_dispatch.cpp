// The safety core's limits and dispatch: what a command may do, clamped or refused, before
// it reaches the driver (safety.h).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "node/safety/safety.h"

namespace rcan::node {
namespace {

std::string num(double d) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%g", d);
  return buf;
}

// Predicts a drive from the current state: v ramps from v0 to `v` at `accel` (instantly when
// 0), holds until `duration_ms`, then ramps to 0 at `accel`; w is constant during the drive and
// taken to stop with v. Returns true when the path moves further outside the workspace at
// any sample (from inside, any exit; from outside, any step away from it).
bool leaves_workspace(const Workspace& ws, const RobotState& st, double v, double w,
                      int64_t duration_ms, double accel) {
  if (!ws.enabled) return false;
  const double dt = 0.01;
  double x = st.x, y = st.y, th = st.theta, cur = st.linear_mps;
  double prev_out = ws.distance_outside(x, y);
  const double drive_s = static_cast<double>(duration_ms) / 1000.0;
  const double tail_s = accel > 0 ? std::abs(v) / accel + dt : 0.0;
  const double total = drive_s + tail_s;
  const int n = static_cast<int>(std::ceil(total / dt));
  for (int k = 0; k < n; ++k) {
    const double t = k * dt;
    const bool driving = t < drive_s;
    const double target = driving ? v : 0.0;
    const double wt = driving ? w : (std::abs(v) > 1e-12 ? w * std::abs(cur) / std::abs(v) : 0.0);
    const double next = accel > 0 ? (target > cur ? std::min(target, cur + accel * dt)
                                                  : std::max(target, cur - accel * dt))
                                  : target;
    const double vm = 0.5 * (cur + next);
    const double thm = th + 0.5 * wt * dt;
    x += vm * std::cos(thm) * dt;
    y += vm * std::sin(thm) * dt;
    th += wt * dt;
    cur = next;
    const double out = ws.distance_outside(x, y);
    if (out > prev_out + 1e-9) return true;
    prev_out = out;
  }
  return false;
}

Error limit_error(const std::string& what, const std::string& field) {
  return Error(ErrorCode::kCommandRejected, what, field, "limit_exceeded");
}

// A limit passed: noted in the outcome when clamping (kClamp).
void note(DispatchOutcome& out, const std::string& s) {
  out.clamped = true;
  out.clamps.push_back(s);
}

// A drive's duration and velocities within the limits: refused past them, or clamped.
Status limit_drive(const SafetyLimits& lim, DriveCommand& d, bool clamp, DispatchOutcome& out) {
  if (!std::isfinite(d.linear_mps) || !std::isfinite(d.angular_radps))
    return Error(ErrorCode::kSchemaValidationFailed, "drive velocities must be finite numbers",
                 "drive");
  if (d.duration_ms <= 0) d.duration_ms = lim.max_drive_duration_ms;
  if (d.duration_ms > lim.max_drive_duration_ms) {
    if (!clamp)
      return limit_error("duration_ms " + std::to_string(d.duration_ms) +
                             " exceeds max_drive_duration_ms " +
                             std::to_string(lim.max_drive_duration_ms),
                         "drive.duration_ms");
    note(out, "duration_ms " + std::to_string(d.duration_ms) + " -> " +
                  std::to_string(lim.max_drive_duration_ms) + " (max_drive_duration_ms)");
    d.duration_ms = lim.max_drive_duration_ms;
  }
  if (std::abs(d.linear_mps) > lim.max_linear_mps) {
    if (!clamp)
      return limit_error(
          "linear_mps " + num(d.linear_mps) + " exceeds max_linear_mps " + num(lim.max_linear_mps),
          "drive.linear_mps");
    const double c = std::copysign(lim.max_linear_mps, d.linear_mps);
    note(out, "linear_mps " + num(d.linear_mps) + " -> " + num(c) + " (max_linear_mps)");
    d.linear_mps = c;
  }
  if (std::abs(d.angular_radps) > lim.max_angular_radps) {
    if (!clamp)
      return limit_error("angular_radps " + num(d.angular_radps) + " exceeds max_angular_radps " +
                             num(lim.max_angular_radps),
                         "drive.angular_radps");
    const double c = std::copysign(lim.max_angular_radps, d.angular_radps);
    note(out, "angular_radps " + num(d.angular_radps) + " -> " + num(c) + " (max_angular_radps)");
    d.angular_radps = c;
  }
  return {};
}

// A drive whose path (with the deceleration) would leave the workspace: refused, or cut to the
// longest duration that stays inside (a stop when none does).
Status fit_workspace(const Workspace& ws, double accel, const RobotState& now, DriveCommand& d,
                     bool clamp, DispatchOutcome& out) {
  if (!ws.enabled || d.linear_mps == 0.0 ||
      !leaves_workspace(ws, now, d.linear_mps, d.angular_radps, d.duration_ms, accel))
    return {};
  char rect[160];
  std::snprintf(rect, sizeof rect, "[%g, %g] x [%g, %g]", ws.x_min, ws.x_max, ws.y_min, ws.y_max);
  if (!clamp)
    return limit_error(std::string("drive would leave the workspace ") + rect + " (workspace)",
                       "drive");
  int64_t lo = 0, hi = d.duration_ms;
  while (lo < hi) {
    const int64_t mid = lo + (hi - lo + 1) / 2;
    if (leaves_workspace(ws, now, d.linear_mps, d.angular_radps, mid, accel)) {
      hi = mid - 1;
    } else {
      lo = mid;
    }
  }
  if (lo == 0 || leaves_workspace(ws, now, d.linear_mps, d.angular_radps, lo, accel)) {
    note(out, "drive -> stop at the workspace boundary " + std::string(rect) + " (workspace)");
    d = DriveCommand{0.0, 0.0, 0};
  } else {
    note(out, "duration_ms " + std::to_string(d.duration_ms) + " -> " + std::to_string(lo) +
                  " to stop inside the workspace " + rect + " (workspace)");
    d.duration_ms = lo;
  }
  return {};
}

// An arm's joint targets within their ranges and its joint speed within the limit (0: the
// limit): refused past them, or clamped.
Status limit_arm(const SafetyLimits& lim, ArmCommand& arm, bool clamp, DispatchOutcome& out) {
  for (int i = 0; i < kArmJoints; ++i) {
    const double t = arm.targets_rad[i];
    const std::string j = "joint_" + std::to_string(i);
    if (!std::isfinite(t))
      return Error(ErrorCode::kSchemaValidationFailed, j + " target must be a finite number",
                   "arm." + j);
    if (t < lim.joint_min_rad[i] || t > lim.joint_max_rad[i]) {
      const bool low = t < lim.joint_min_rad[i];
      const double bound = low ? lim.joint_min_rad[i] : lim.joint_max_rad[i];
      const std::string lname = low ? "joint_min_rad" : "joint_max_rad";
      if (!clamp)
        return limit_error(j + " target " + num(t) + " outside " + lname + " " + num(bound),
                           "arm." + j);
      note(out, j + " target " + num(t) + " -> " + num(bound) + " (" + lname + ")");
      arm.targets_rad[i] = bound;
    }
  }
  if (!std::isfinite(arm.max_joint_speed_radps) || arm.max_joint_speed_radps < 0)
    return Error(ErrorCode::kSchemaValidationFailed, "max_joint_speed_radps must be >= 0",
                 "arm.max_joint_speed_radps");
  if (arm.max_joint_speed_radps == 0.0) {
    arm.max_joint_speed_radps = lim.max_joint_speed_radps;
  } else if (arm.max_joint_speed_radps > lim.max_joint_speed_radps) {
    if (!clamp)
      return limit_error("max_joint_speed_radps " + num(arm.max_joint_speed_radps) +
                             " exceeds limit " + num(lim.max_joint_speed_radps),
                         "arm.max_joint_speed_radps");
    note(out, "max_joint_speed_radps " + num(arm.max_joint_speed_radps) + " -> " +
                  num(lim.max_joint_speed_radps) + " (max_joint_speed_radps)");
    arm.max_joint_speed_radps = lim.max_joint_speed_radps;
  }
  return {};
}

}  // namespace

Result<ActuatorCommand> SafetyCore::limit_command(const ActuatorCommand& cmd, LimitPolicy policy,
                                                  const RobotState& now,
                                                  DispatchOutcome& out) const {
  ActuatorCommand a = cmd;
  const bool clamp = policy == LimitPolicy::kClamp;
  if (a.drive) {
    if (!driver_info_.has_base)
      return Error(ErrorCode::kCommandRejected, "this robot has no base", "drive", "unsupported");
    if (Status s = limit_drive(limits_, *a.drive, clamp, out); !s.ok()) return s.error();
    if (Status s = fit_workspace(limits_.workspace, driver_info_.linear_accel_mps2, now, *a.drive,
                                 clamp, out);
        !s.ok())
      return s.error();
  }
  if (a.arm) {
    if (!driver_info_.has_arm)
      return Error(ErrorCode::kCommandRejected, "this robot has no arm", "arm", "unsupported");
    if (Status s = limit_arm(limits_, *a.arm, clamp, out); !s.ok()) return s.error();
  }
  if (a.gripper && !driver_info_.has_gripper)
    return Error(ErrorCode::kCommandRejected, "this robot has no gripper", "gripper",
                 "unsupported");
  return a;
}

Result<DispatchOutcome> SafetyCore::precheck(const ActuatorCommand& cmd,
                                             const DispatchOptions& opts, int64_t now) const {
  DispatchOutcome out;
  if (cmd.stop) {
    out.applied = ActuatorCommand::make_stop();
    return out;
  }
  if (cmd.empty())
    return Error(ErrorCode::kSchemaValidationFailed, "empty actuator command", "command",
                 "missing_field");
  if (latched_.load(std::memory_order_acquire))
    return Error(ErrorCode::kCommandRejected, "ESTOP is latched; an explicit RESUME is required",
                 "", "estop_active");
  if (driver_faulted_.load(std::memory_order_acquire)) {
    std::string why;
    {
      MutexLock lock(meta_mu_);
      why = driver_fault_;
    }
    return Error(ErrorCode::kSafeStop,
                 "the driver reports a fault (" + why + "); motion is refused until it recovers",
                 "", "driver_fault");
  }
  if (opts.deadline_mono_ms > 0 && now > opts.deadline_mono_ms)
    return Error(
        ErrorCode::kMessageStale,
        "command expired " + std::to_string(now - opts.deadline_mono_ms) + " ms before dispatch",
        "", "ttl_expired");
  if (!opts.session_id.empty()) {
    MutexLock lock(deadman_mu_);
    auto it = deadmen_.find(opts.session_id);
    if (it != deadmen_.end() &&
        (it->second.lost || now - it->second.last_heartbeat_mono > it->second.timeout_ms)) {
      return Error(ErrorCode::kSafeStop,
                   "session heartbeat lost; send a heartbeat before commanding", "",
                   "heartbeat_lost");
    }
    if (it != deadmen_.end() &&
        it->second.armed_epoch < estop_epoch_.load(std::memory_order_acquire)) {
      return Error(ErrorCode::kCommandRejected,
                   "an ESTOP latched since this control session was armed; re-arm it (claim or "
                   "renew with rearm: true) before commanding motion",
                   "session", "rearm_required");
    }
  }
  if (opts.stream_epoch && *opts.stream_epoch < estop_epoch_.load(std::memory_order_acquire))
    return Error(ErrorCode::kCommandRejected,
                 "an ESTOP latched since this stream connected; send the next motion command "
                 "with \"rearm\": true (a fresh operator action) to drive again",
                 "rearm", "rearm_required");
  RobotState snapshot;
  {
    MutexLock lock(apply_mu_);
    snapshot = driver_->state();
  }
  auto limited = limit_command(cmd, opts.policy.value_or(cfg_.file.speed_policy), snapshot, out);
  if (!limited.ok()) return std::move(limited).error();
  out.applied = std::move(limited).value();
  return out;
}

Result<DispatchOutcome> SafetyCore::check(const ActuatorCommand& cmd,
                                          const DispatchOptions& opts) const {
  return precheck(cmd, opts, clock_.mono_ms());
}

Result<DispatchOutcome> SafetyCore::dispatch(const ActuatorCommand& cmd,
                                             const DispatchOptions& opts) {
  if (cmd.stop) {
    // A stop is always allowed, latched or not, stale or not.
    driver_->stop();
    {
      MutexLock lock(apply_mu_);
      driver_->stop();
      drive_deadline_mono_ = 0;
    }
    DispatchOutcome out;
    out.applied = ActuatorCommand::make_stop();
    return out;
  }
  const int64_t now = clock_.mono_ms();
  auto pre = precheck(cmd, opts, now);
  if (!pre.ok()) return pre;
  DispatchOutcome out = std::move(pre).value();

  {
    MutexLock lock(apply_mu_);
    // apply_seq_ is odd while this thread may call Driver::apply(); estop() waits for it to
    // turn even (see estop()). The latch is re-checked after making it odd.
    struct SeqGuard {
      std::atomic<uint64_t>& seq;
      explicit SeqGuard(std::atomic<uint64_t>& s) : seq(s) {
        seq.fetch_add(1, std::memory_order_seq_cst);
      }
      ~SeqGuard() { seq.fetch_add(1, std::memory_order_seq_cst); }
    } guard(apply_seq_);
    if (latched_.load(std::memory_order_seq_cst))
      return Error(ErrorCode::kCommandRejected, "ESTOP is latched; an explicit RESUME is required",
                   "", "estop_active");
    // tick() sets the fault under apply_mu_: checked here, no apply follows a reported fault.
    if (driver_faulted_.load(std::memory_order_acquire))
      return Error(ErrorCode::kSafeStop,
                   "the driver reports a fault; motion is refused until it recovers", "",
                   "driver_fault");
    if (resting_.load(std::memory_order_seq_cst)) {
      // The loop may have slept up to idle_tick_ms: bring the driver to now first, so the
      // new motion is integrated from this moment and not from the last tick.
      step_driver_to_locked(clock_.mono_ms());
    }
    Status st = driver_->apply(out.applied);
    // An estop() whose bounded fence gave up on us: stop right behind our own apply.
    if (latched_.load(std::memory_order_seq_cst)) driver_->stop();
    if (!st.ok()) return st.error();
    if (out.applied.drive) {
      drive_deadline_mono_ =
          out.applied.drive->duration_ms > 0 ? now + out.applied.drive->duration_ms : 0;
    }
    motion_owner_ = opts.session_id;
  }
  wake_ticker();
  if (safe_stop_.load(std::memory_order_acquire)) {
    MutexLock lock(meta_mu_);
    safe_stop_.store(false, std::memory_order_release);
    safe_stop_reason_.clear();
    safe_stop_session_.clear();
  }
  return out;
}

}  // namespace rcan::node
