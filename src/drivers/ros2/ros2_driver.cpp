#include "drivers/ros2/ros2_driver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include "base/clock.h"
#include "drivers/ros2/ros2_convert.h"

namespace rcan::drivers::ros2 {
namespace {

int64_t now_ns() { return steady_ns(); }

constexpr double kRestEps = 1e-3;  // m/s, rad/s: below this the base counts as stopped
constexpr int kTakeBatch = 8;      // samples per dds_take
constexpr int kMaxTakePerStep = 64;
constexpr int64_t kMaxDriveMs = 86'400'000;  // a drive's end stays representable in ns
constexpr double kMaxArmMoveS = 3600.0;

Error dds_error(const std::string& what, dds_return_t rc) {
  return Error(ErrorCode::kInternal, "ROS 2 driver: " + what + ": " + dds_strretcode(rc));
}

// ROS 2's default QoS for commands (rmw_qos_profile_default): reliable, volatile, keep-last
// 10. A write never waits: with keep-last the writer drops its oldest sample instead.
dds_qos_t* command_qos() {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(0));
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 10);
  return q;
}

// ROS 2's sensor-data QoS (rmw_qos_profile_sensor_data): best effort, volatile, keep-last 5.
// A best-effort reader matches reliable and best-effort publishers alike.
dds_qos_t* sensor_qos() {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 5);
  return q;
}

}  // namespace

Ros2Driver::Ros2Driver(const config::Ros2DriverConfig& cfg)
    : cfg_(cfg),
      period_ns_(1'000'000'000LL / std::max<uint32_t>(cfg.cmd_rate_hz, 1)),
      stop_repeat_ns_(static_cast<int64_t>(cfg.stop_repeat_ms) * 1'000'000),
      start_ns_(now_ns()),
      last_stop_ns_(start_ns_ - stop_repeat_ns_ - 1) {
  arm_slots_ = std::min<size_t>(cfg_.arm_joints.size(), node::kArmJoints);
  for (size_t i = 0; i < arm_slots_; ++i)
    joint_name_ptrs_.push_back(const_cast<char*>(cfg_.arm_joints[i].c_str()));
}

Result<std::unique_ptr<Ros2Driver>> Ros2Driver::create(const config::Ros2DriverConfig& cfg) {
  std::unique_ptr<Ros2Driver> d(new Ros2Driver(cfg));
  if (Status s = d->open(); !s.ok()) return s.error();
  return d;
}

Ros2Driver::~Ros2Driver() { close(); }

void Ros2Driver::close() noexcept {
  if (participant_ > 0) dds_delete(participant_);
  participant_ = 0;
}

Status Ros2Driver::open() {
  auto name = [&](const std::string& topic, std::string& out) -> Status {
    auto n = dds_topic_name(cfg_.ns, topic);
    if (!n.ok()) return n.error();
    out = std::move(n).value();
    return Status::Ok();
  };
  if (Status s = name(cfg_.cmd_vel_topic, cmd_vel_name_); !s.ok()) return s;
  if (Status s = name(cfg_.odom_topic, odom_name_); !s.ok()) return s;
  if (Status s = name(cfg_.joint_states_topic, joint_states_name_); !s.ok()) return s;
  if (!cfg_.arm_topic.empty())
    if (Status s = name(cfg_.arm_topic, arm_name_); !s.ok()) return s;
  if (!cfg_.gripper_topic.empty())
    if (Status s = name(cfg_.gripper_topic, gripper_name_); !s.ok()) return s;
  if (cfg_.domain_id > 232)
    return Error(ErrorCode::kSchemaValidationFailed, "ROS 2 domain id must be 0-232", "domain_id");

  participant_ =
      dds_create_participant(static_cast<dds_domainid_t>(cfg_.domain_id), nullptr, nullptr);
  if (participant_ < 0) {
    const dds_return_t rc = participant_;
    participant_ = 0;
    return dds_error(
        "cannot join DDS domain " + std::to_string(cfg_.domain_id) + " (check CYCLONEDDS_URI)", rc);
  }
  auto topic = [&](const dds_topic_descriptor_t* desc, const std::string& n,
                   dds_entity_t& out) -> Status {
    out = dds_create_topic(participant_, desc, n.c_str(), nullptr, nullptr);
    if (out < 0) return dds_error("topic " + n, out);
    return Status::Ok();
  };
  auto writer = [&](const dds_topic_descriptor_t* desc, const std::string& n,
                    dds_entity_t& out) -> Status {
    dds_entity_t t = 0;
    if (Status s = topic(desc, n, t); !s.ok()) return s;
    dds_qos_t* q = command_qos();
    out = dds_create_writer(participant_, t, q, nullptr);
    dds_delete_qos(q);
    if (out < 0) return dds_error("writer on " + n, out);
    return Status::Ok();
  };
  auto reader = [&](const dds_topic_descriptor_t* desc, const std::string& n,
                    dds_entity_t& out) -> Status {
    dds_entity_t t = 0;
    if (Status s = topic(desc, n, t); !s.ok()) return s;
    dds_qos_t* q = sensor_qos();
    out = dds_create_reader(participant_, t, q, nullptr);
    dds_delete_qos(q);
    if (out < 0) return dds_error("reader on " + n, out);
    return Status::Ok();
  };
  Status s = writer(&geometry_msgs_msg_dds__Twist__desc, cmd_vel_name_, cmd_vel_writer_);
  if (s.ok()) s = reader(&nav_msgs_msg_dds__Odometry__desc, odom_name_, odom_reader_);
  if (s.ok()) s = reader(&sensor_msgs_msg_dds__JointState__desc, joint_states_name_, joint_reader_);
  if (s.ok() && !arm_name_.empty())
    s = writer(&trajectory_msgs_msg_dds__JointTrajectory__desc, arm_name_, arm_writer_);
  if (s.ok() && !gripper_name_.empty())
    s = writer(cfg_.gripper_type == "std_msgs/msg/Bool" ? &std_msgs_msg_dds__Bool__desc
                                                        : &std_msgs_msg_dds__Float64__desc,
               gripper_name_, gripper_writer_);
  if (!s.ok()) close();
  return s;
}

node::DriverInfo Ros2Driver::describe() const {
  node::DriverInfo d;
  d.name = "ros2";
  d.simulated = false;
  d.has_base = true;
  d.has_arm = arm_writer_ > 0 && arm_slots_ > 0;
  d.arm_joints = d.has_arm ? static_cast<int>(arm_slots_) : 0;
  d.has_gripper = gripper_writer_ > 0;
  d.max_linear_mps = cfg_.max_linear_mps;
  d.max_angular_radps = cfg_.max_angular_radps;
  d.max_joint_speed_radps = cfg_.max_joint_speed_radps;
  for (int i = 0; i < node::kArmJoints; ++i) {
    d.joint_min_rad[i] = static_cast<size_t>(i) < cfg_.joint_min_rad.size() ? cfg_.joint_min_rad[i]
                                                                            : -std::numbers::pi;
    d.joint_max_rad[i] = static_cast<size_t>(i) < cfg_.joint_max_rad.size() ? cfg_.joint_max_rad[i]
                                                                            : std::numbers::pi;
  }
  d.capabilities = {"status", "teleop", "navigation", "telemetry"};
  if (d.has_arm) d.capabilities.push_back("arm");
  if (d.has_gripper) d.capabilities.push_back("gripper");
  return d;
}

// ---- the publish path ------------------------------------------------------------------------

int Ros2Driver::write_twist(double v, double w, uint64_t gen, int64_t now) {
  const geometry_msgs_msg_dds__Twist_ t = make_twist(v, w);
  MutexLock lock(pub_mu_);
  if (stop_gen_.load(std::memory_order_acquire) != gen) return 0;  // a stop() came first
  if (const dds_return_t rc = dds_write(cmd_vel_writer_, &t); rc < 0) {
    write_failures_.fetch_add(1, std::memory_order_relaxed);
    return rc;
  }
  const bool zero = v == 0.0 && w == 0.0;
  last_was_zero_ = zero;
  last_pub_ns_ = now;
  twists_.fetch_add(1, std::memory_order_relaxed);
  if (zero) zero_twists_.fetch_add(1, std::memory_order_relaxed);
  return 1;
}

void Ros2Driver::write_zero_if_due(int64_t now) noexcept {
  const geometry_msgs_msg_dds__Twist_ t = make_twist(0.0, 0.0);
  MutexLock lock(pub_mu_);
  if (last_was_zero_ && now - last_pub_ns_ < period_ns_) return;
  if (dds_write(cmd_vel_writer_, &t) < 0) {
    write_failures_.fetch_add(1, std::memory_order_relaxed);
    return;  // not marked as written: the next stop() or loop step tries again
  }
  last_was_zero_ = true;
  last_pub_ns_ = now;
  twists_.fetch_add(1, std::memory_order_relaxed);
  zero_twists_.fetch_add(1, std::memory_order_relaxed);
}

// An empty JointTrajectory: ROS 2's joint_trajectory_controller stops and holds position.
void Ros2Driver::write_arm_hold() noexcept {
  if (arm_writer_ <= 0) return;
  trajectory_msgs_msg_dds__JointTrajectory_ m{};
  m.header.frame_id = const_cast<char*>("");
  m.joint_names._maximum = m.joint_names._length = static_cast<uint32_t>(joint_name_ptrs_.size());
  m.joint_names._buffer = const_cast<char**>(joint_name_ptrs_.data());
  m.joint_names._release = false;
  (void)dds_write(arm_writer_, &m);
}

void Ros2Driver::stop() noexcept {
  // First make every apply() in flight lose (write_twist compares the generation under the
  // publish lock), then put a zero Twist on the wire from this thread.
  stop_gen_.fetch_add(1, std::memory_order_acq_rel);
  const int64_t now = now_ns();
  last_stop_ns_.store(now, std::memory_order_release);
  write_zero_if_due(now);
  if (arm_moving_.exchange(false, std::memory_order_acq_rel)) write_arm_hold();
}

void Ros2Driver::absorb_stop_locked() {
  const uint64_t g = stop_gen_.load(std::memory_order_acquire);
  if (g == seen_stop_gen_) return;
  seen_stop_gen_ = g;
  drive_active_ = false;
  drive_v_ = drive_w_ = 0.0;
  arm_until_ns_ = 0;
  st_.joint_targets_rad = st_.joints_rad;
}

// ---- commands --------------------------------------------------------------------------------

Status Ros2Driver::apply(const node::ActuatorCommand& cmd) {
  MutexLock lock(mu_);
  const uint64_t gen = stop_gen_.load(std::memory_order_acquire);
  absorb_stop_locked();
  if (cmd.stop) {
    stop();
    absorb_stop_locked();
    return Status::Ok();
  }
  // Validate every part before anything reaches the wire.
  if (Status s = check_command(cmd); !s.ok()) return s;
  const int64_t now = now_ns();
  bool ended = false;  // a stop() won the race: the rest of the command is not written
  if (cmd.drive)
    if (Status s = drive_locked(*cmd.drive, gen, now, ended); !s.ok() || ended) return s;
  if (cmd.arm)
    if (Status s = arm_locked(*cmd.arm, gen, now, ended); !s.ok() || ended) return s;
  if (cmd.gripper) return gripper_locked(*cmd.gripper);
  return Status::Ok();
}

Status Ros2Driver::check_command(const node::ActuatorCommand& cmd) const {
  if (cmd.drive) {
    const auto& d = *cmd.drive;
    if (!std::isfinite(d.linear_mps) || !std::isfinite(d.angular_radps) || d.duration_ms < 0)
      return Error(ErrorCode::kSchemaValidationFailed, "drive command has a non-finite value",
                   "drive");
  }
  if (cmd.arm) {
    if (arm_writer_ <= 0)
      return Error(ErrorCode::kNotImplemented, "this ROS 2 robot has no arm topic configured",
                   "arm");
    for (double t : cmd.arm->targets_rad)
      if (!std::isfinite(t))
        return Error(ErrorCode::kSchemaValidationFailed, "arm target is not finite", "arm");
    if (!std::isfinite(cmd.arm->max_joint_speed_radps))
      return Error(ErrorCode::kSchemaValidationFailed, "arm speed is not finite", "arm");
  }
  if (cmd.gripper && gripper_writer_ <= 0)
    return Error(ErrorCode::kNotImplemented, "this ROS 2 robot has no gripper topic configured",
                 "gripper");
  return Status::Ok();
}

// A drive: its Twist written now and again every period until its duration ends (a zero
// duration: one zero Twist).
Status Ros2Driver::drive_locked(const node::DriveCommand& d, uint64_t gen, int64_t now,
                                bool& ended) {
  double v = std::clamp(d.linear_mps, -cfg_.max_linear_mps, cfg_.max_linear_mps);
  double w = std::clamp(d.angular_radps, -cfg_.max_angular_radps, cfg_.max_angular_radps);
  if (d.duration_ms == 0) v = w = 0.0;
  drive_v_ = v;
  drive_w_ = w;
  drive_gen_ = gen;
  drive_end_ns_ = now + std::min<int64_t>(d.duration_ms, kMaxDriveMs) * 1'000'000;
  next_repub_ns_ = now + period_ns_;
  drive_active_ = d.duration_ms > 0;
  const int wrote = write_twist(v, w, gen, now);
  if (wrote == 0) {
    absorb_stop_locked();  // a stop() won the race: nothing was written
    ended = true;
    return Status::Ok();
  }
  if (wrote < 0) {
    drive_active_ = false;
    return dds_error("cmd_vel write", wrote);
  }
  if (!drive_active_) last_stop_ns_.store(now, std::memory_order_release);
  return Status::Ok();
}

// An arm move: one JointTrajectory point, the targets clamped to the joint limits, reached at
// the requested (or configured) joint speed.
Status Ros2Driver::arm_locked(const node::ArmCommand& a, uint64_t gen, int64_t now, bool& ended) {
  const double speed =
      std::min(a.max_joint_speed_radps > 0.0 ? a.max_joint_speed_radps : cfg_.max_joint_speed_radps,
               cfg_.max_joint_speed_radps);
  const node::DriverInfo info = describe();
  std::vector<double> positions(arm_slots_);
  double longest = 0.0;
  for (size_t i = 0; i < arm_slots_; ++i) {
    if (!(info.joint_min_rad[i] <= info.joint_max_rad[i]))
      return Error(ErrorCode::kInternal, "joint limits: min above max", "arm");
    positions[i] = std::clamp(a.targets_rad[i], info.joint_min_rad[i], info.joint_max_rad[i]);
    st_.joint_targets_rad[i] = positions[i];
    longest = std::max(longest, std::abs(positions[i] - st_.joints_rad[i]));
  }
  // At least 0.1 s; at most kMaxArmMoveS (a tiny speed must not overflow the Duration).
  const double secs = std::clamp(longest / speed, 0.1, kMaxArmMoveS);
  trajectory_msgs_msg_dds__JointTrajectoryPoint_ pt{};
  pt.positions._maximum = pt.positions._length = static_cast<uint32_t>(positions.size());
  pt.positions._buffer = positions.data();
  pt.time_from_start.sec = static_cast<int32_t>(secs);
  pt.time_from_start.nanosec =
      static_cast<uint32_t>((secs - std::floor(secs)) * 1e9) % 1'000'000'000u;
  trajectory_msgs_msg_dds__JointTrajectory_ m{};
  m.header.frame_id = const_cast<char*>("");
  m.joint_names._maximum = m.joint_names._length = static_cast<uint32_t>(joint_name_ptrs_.size());
  m.joint_names._buffer = joint_name_ptrs_.data();
  m.points._maximum = m.points._length = 1;
  m.points._buffer = &pt;
  if (stop_gen_.load(std::memory_order_acquire) != gen) {
    absorb_stop_locked();
    ended = true;
    return Status::Ok();
  }
  if (dds_return_t rc = dds_write(arm_writer_, &m); rc < 0)
    return dds_error("arm trajectory write", rc);
  st_.joint_speed_radps = speed;
  arm_until_ns_ = now + static_cast<int64_t>(secs * 1e9);
  arm_moving_.store(true, std::memory_order_release);
  // A stop() between the check and the store above did not see the arm moving: hold it.
  if (stop_gen_.load(std::memory_order_acquire) != gen &&
      arm_moving_.exchange(false, std::memory_order_acq_rel))
    write_arm_hold();
  return Status::Ok();
}

Status Ros2Driver::gripper_locked(node::GripperAction g) {
  const bool close = g == node::GripperAction::kClose;
  dds_return_t rc = 0;
  if (cfg_.gripper_type == "std_msgs/msg/Bool") {
    std_msgs_msg_dds__Bool_ m{close};
    rc = dds_write(gripper_writer_, &m);
  } else {
    std_msgs_msg_dds__Float64_ m{close ? cfg_.gripper_close : cfg_.gripper_open};
    rc = dds_write(gripper_writer_, &m);
  }
  if (rc < 0) return dds_error("gripper write", rc);
  st_.gripper_closed = close;
  return Status::Ok();
}

// ---- the loop --------------------------------------------------------------------------------

void Ros2Driver::take_samples_locked(int64_t now) {
  void* buf[kTakeBatch];
  dds_sample_info_t info[kTakeBatch];
  for (int total = 0; total < kMaxTakePerStep;) {
    for (auto& b : buf) b = nullptr;
    const dds_return_t n = dds_take(odom_reader_, buf, info, kTakeBatch, kTakeBatch);
    if (n <= 0) break;
    for (dds_return_t i = 0; i < n; ++i) {
      if (!info[i].valid_data) continue;
      const auto* m = static_cast<const nav_msgs_msg_dds__Odometry_*>(buf[i]);
      const auto r = read_odometry(*m);
      if (!r) {
        rejected_samples_.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      if (have_odom_) {
        const double d = std::hypot(r->x - st_.x, r->y - st_.y);
        if (std::isfinite(d)) st_.odometry_m += d;
      }
      st_.x = r->x;
      st_.y = r->y;
      st_.theta = r->theta;
      st_.linear_mps = r->linear_mps;
      st_.angular_radps = r->angular_radps;
      have_odom_ = true;
      last_odom_ns_.store(now, std::memory_order_release);
    }
    dds_return_loan(odom_reader_, buf, n);
    total += n;
  }
  for (int total = 0; total < kMaxTakePerStep;) {
    for (auto& b : buf) b = nullptr;
    const dds_return_t n = dds_take(joint_reader_, buf, info, kTakeBatch, kTakeBatch);
    if (n <= 0) break;
    for (dds_return_t i = 0; i < n; ++i) {
      if (!info[i].valid_data) continue;
      const auto* m = static_cast<const sensor_msgs_msg_dds__JointState_*>(buf[i]);
      if (read_joint_state(*m, cfg_.arm_joints, st_.joints_rad) == 0)
        rejected_samples_.fetch_add(1, std::memory_order_relaxed);
    }
    dds_return_loan(joint_reader_, buf, n);
    total += n;
  }
}

void Ros2Driver::step(int64_t dt_ms) {
  MutexLock lock(mu_);
  const int64_t now = now_ns();
  if (dt_ms > 0) st_.t_ms += dt_ms;
  absorb_stop_locked();
  take_samples_locked(now);
  if (drive_active_) {
    if (now >= drive_end_ns_) {
      // The drive's duration is over: a zero Twist at once, then the stop repeats.
      drive_active_ = false;
      drive_v_ = drive_w_ = 0.0;
      last_stop_ns_.store(now, std::memory_order_release);
      write_zero_if_due(now);
    } else if (now >= next_repub_ns_) {
      if (write_twist(drive_v_, drive_w_, drive_gen_, now) == 0) absorb_stop_locked();
      next_repub_ns_ = std::max(next_repub_ns_ + period_ns_, now + period_ns_ / 2);
    }
  }
  if (!drive_active_ && now - last_stop_ns_.load(std::memory_order_acquire) < stop_repeat_ns_)
    write_zero_if_due(now);
  if (arm_until_ns_ != 0 && now >= arm_until_ns_) {
    arm_until_ns_ = 0;
    arm_moving_.store(false, std::memory_order_release);
  }
}

node::RobotState Ros2Driver::state() const {
  MutexLock lock(mu_);
  node::RobotState s = st_;
  const int64_t now = now_ns();
  const bool stop_pending = stop_gen_.load(std::memory_order_acquire) != seen_stop_gen_;
  const bool driving = drive_active_ && !stop_pending;
  s.target_linear_mps = driving ? drive_v_ : 0.0;
  s.target_angular_radps = driving ? drive_w_ : 0.0;
  s.drive_remaining_ms = driving ? std::max<int64_t>(0, (drive_end_ns_ - now) / 1'000'000) : 0;
  if (stop_pending) s.joint_targets_rad = s.joints_rad;
  const bool arm_moving = !stop_pending && arm_until_ns_ != 0 && now < arm_until_ns_;
  s.stopped = !driving && !arm_moving && std::abs(s.linear_mps) < kRestEps &&
              std::abs(s.angular_radps) < kRestEps;
  s.battery_known = false;
  return s;
}

node::DriverHealth Ros2Driver::health() const {
  if (cfg_.odom_timeout_ms == 0) return {};
  const int64_t last = last_odom_ns_.load(std::memory_order_acquire);
  const int64_t since = now_ns() - (last != 0 ? last : start_ns_);
  const int64_t limit = static_cast<int64_t>(cfg_.odom_timeout_ms) * 1'000'000;
  if (since <= limit) return {};
  return {false, (last != 0 ? "no odometry on " : "no odometry yet on ") + odom_name_ + " for " +
                     std::to_string(since / 1'000'000) + " ms (odom_timeout_ms " +
                     std::to_string(cfg_.odom_timeout_ms) + ")"};
}

}  // namespace rcan::drivers::ros2
