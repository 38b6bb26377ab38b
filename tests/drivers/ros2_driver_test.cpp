// The ROS 2 driver in process, against a DDS peer on the ROS 2 names (tests/support/ros2_peer.h):
// topic and type names, the CDR layout of every message it reads or writes, the Twist
// publishing rules (at once, republished while a drive lasts, a zero Twist at its end, at once
// on stop() and at the command rate while stop() keeps being called), odometry and joint
// states into state(), bad samples refused, and the odometry timeout as a driver fault.
#include "drivers/ros2/ros2_driver.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <thread>
#include <vector>

#include "drivers/ros2/ros2_convert.h"
#include "ros2_peer.h"

namespace rcan {
namespace {

using drivers::ros2::Ros2Driver;
using test::WireTwist;

void sleep_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }

TEST(Ros2Names, TopicsMapToRtAndNamespaces) {
  using drivers::ros2::dds_topic_name;
  EXPECT_EQ(*dds_topic_name("", "cmd_vel"), "rt/cmd_vel");
  EXPECT_EQ(*dds_topic_name("/", "cmd_vel"), "rt/cmd_vel");
  EXPECT_EQ(*dds_topic_name("/robot1", "cmd_vel"), "rt/robot1/cmd_vel");
  EXPECT_EQ(*dds_topic_name("robot1", "arm_controller/joint_trajectory"),
            "rt/robot1/arm_controller/joint_trajectory");
  EXPECT_EQ(*dds_topic_name("/robot1", "/cmd_vel"), "rt/cmd_vel");  // absolute: no namespace
  EXPECT_FALSE(dds_topic_name("", "").ok());
  EXPECT_FALSE(dds_topic_name("", "cmd vel").ok());
  EXPECT_FALSE(dds_topic_name("", "a//b").ok());
  EXPECT_FALSE(dds_topic_name("", "1abc").ok());
  EXPECT_FALSE(dds_topic_name("bad-ns", "cmd_vel").ok());
  EXPECT_EQ(std::string(geometry_msgs_msg_dds__Twist__desc.m_typename),
            "geometry_msgs::msg::dds_::Twist_");
  EXPECT_EQ(std::string(nav_msgs_msg_dds__Odometry__desc.m_typename),
            "nav_msgs::msg::dds_::Odometry_");
  EXPECT_EQ(std::string(sensor_msgs_msg_dds__JointState__desc.m_typename),
            "sensor_msgs::msg::dds_::JointState_");
  EXPECT_EQ(std::string(trajectory_msgs_msg_dds__JointTrajectory__desc.m_typename),
            "trajectory_msgs::msg::dds_::JointTrajectory_");
}

TEST(Ros2Convert, OdometryYawVelocitiesAndRefusals) {
  nav_msgs_msg_dds__Odometry_ m{};
  m.pose.pose.position.x = 1.5;
  m.pose.pose.position.y = -2.0;
  m.pose.pose.orientation.z = std::sin(0.35);
  m.pose.pose.orientation.w = std::cos(0.35);
  m.twist.twist.linear.x = 0.4;
  m.twist.twist.angular.z = -0.2;
  auto r = drivers::ros2::read_odometry(m);
  ASSERT_TRUE(r);
  EXPECT_DOUBLE_EQ(r->x, 1.5);
  EXPECT_DOUBLE_EQ(r->y, -2.0);
  EXPECT_NEAR(r->theta, 0.7, 1e-12);
  EXPECT_DOUBLE_EQ(r->linear_mps, 0.4);
  EXPECT_DOUBLE_EQ(r->angular_radps, -0.2);
  // A quaternion of any length gives the same yaw; a half turn is +pi.
  m.pose.pose.orientation.z *= 3;
  m.pose.pose.orientation.w *= 3;
  EXPECT_NEAR(drivers::ros2::read_odometry(m)->theta, 0.7, 1e-12);
  EXPECT_DOUBLE_EQ(drivers::ros2::yaw_of(0, 0, 1, 0), std::numbers::pi);
  // Refused: NaN, infinity, a zero quaternion.
  auto bad = m;
  bad.pose.pose.position.x = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(drivers::ros2::read_odometry(bad));
  bad = m;
  bad.twist.twist.angular.z = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(drivers::ros2::read_odometry(bad));
  bad = m;
  bad.pose.pose.orientation = {};
  EXPECT_FALSE(drivers::ros2::read_odometry(bad));
  bad = m;
  bad.pose.pose.orientation.w = 1e300;  // its square overflows
  bad.pose.pose.orientation.z = 1e300;
  EXPECT_FALSE(drivers::ros2::read_odometry(bad));
}

TEST(Ros2Convert, JointStatesByNameSkippingNaNAndShortArrays) {
  const std::vector<std::string> names{"shoulder", "elbow", "wrist"};
  char n0[] = "elbow", n1[] = "other", n2[] = "shoulder", n3[] = "wrist";
  char* nm[] = {n0, n1, n2, n3};
  double pos[] = {0.5, 9.0, -0.25, std::numeric_limits<double>::quiet_NaN()};
  sensor_msgs_msg_dds__JointState_ m{};
  m.name = {4, 4, nm, false};
  m.position = {3, 3, pos, false};  // one position short: "wrist" has none
  node::JointArray j{};
  j[2] = 7.0;
  EXPECT_EQ(drivers::ros2::read_joint_state(m, names, j), 2);
  EXPECT_DOUBLE_EQ(j[0], -0.25);
  EXPECT_DOUBLE_EQ(j[1], 0.5);
  EXPECT_DOUBLE_EQ(j[2], 7.0);  // unchanged
  // Without configured names: positional, NaN skipped.
  m.position = {4, 4, pos, false};
  node::JointArray k{};
  EXPECT_EQ(drivers::ros2::read_joint_state(m, {}, k), 3);
  EXPECT_DOUBLE_EQ(k[1], 9.0);
  EXPECT_DOUBLE_EQ(k[3], 0.0);
}

// A driver and a peer in one process, on a domain of their own, over loopback only.
class Ros2DriverTest : public ::testing::Test {
 protected:
  void SetUp() override {
    test::use_loopback_dds();
    cfg_.domain_id = test::random_domain_id();
    cfg_.cmd_rate_hz = 20;
    cfg_.odom_timeout_ms = 400;
    cfg_.stop_repeat_ms = 1000;
    cfg_.max_linear_mps = 1.0;
    cfg_.max_angular_radps = 2.0;
    cfg_.arm_topic = "arm_controller/joint_trajectory";
    cfg_.arm_joints = {"j1", "j2", "j3", "j4", "j5", "j6"};
  }
  void start() {
    auto d = Ros2Driver::create(cfg_);
    ASSERT_TRUE(d.ok()) << d.error().message;
    driver_ = std::move(d).value();
    peer_ = std::make_unique<test::Ros2Peer>(cfg_.domain_id);
    ASSERT_TRUE(peer_->ok());
    ASSERT_TRUE(peer_->wait_matched(10000)) << "no DDS match on " << driver_->cmd_vel_topic();
  }
  // Steps the driver like the safety core's loop (every 20 ms) for `ms`.
  void run_loop(int ms) {
    for (int t = 0; t < ms; t += 20) {
      driver_->step(20);
      sleep_ms(20);
    }
  }
  static size_t count_zero(const std::vector<WireTwist>& v, int64_t after_ns = 0) {
    size_t n = 0;
    for (const auto& t : v)
      if (t.zero() && t.t_ns >= after_ns) ++n;
    return n;
  }

  config::Ros2DriverConfig cfg_;
  std::unique_ptr<Ros2Driver> driver_;
  std::unique_ptr<test::Ros2Peer> peer_;
};

TEST_F(Ros2DriverTest, DescribeReportsTheConfiguredEnvelope) {
  cfg_.joint_min_rad = {-1.0, -2.0};
  cfg_.joint_max_rad = {1.0};
  start();
  const node::DriverInfo d = driver_->describe();
  EXPECT_EQ(d.name, "ros2");
  EXPECT_FALSE(d.simulated);
  EXPECT_TRUE(d.has_base);
  EXPECT_TRUE(d.has_arm);
  EXPECT_EQ(d.arm_joints, 6);
  EXPECT_FALSE(d.has_gripper);
  EXPECT_DOUBLE_EQ(d.max_linear_mps, 1.0);
  EXPECT_DOUBLE_EQ(d.joint_min_rad[1], -2.0);
  EXPECT_DOUBLE_EQ(d.joint_max_rad[0], 1.0);
  EXPECT_DOUBLE_EQ(d.joint_max_rad[1], std::numbers::pi);
  EXPECT_FALSE(driver_->at_rest());
}

TEST_F(Ros2DriverTest, StopIsSafeFromManyThreadsDuringAppliesAndSteps) {
  // The safety core calls stop() from any thread (an ESTOP on an I/O thread, the tick, a fault)
  // while apply() and step() run under its lock: nothing may race (the TSan build runs this),
  // and after the last stop() the wire ends with a zero Twist.
  start();
  std::atomic<bool> done{false};
  std::vector<std::thread> stoppers;
  for (int t = 0; t < 4; ++t)
    stoppers.emplace_back([&] {
      while (!done.load()) {
        driver_->stop();
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    });
  std::thread reader([&] {
    while (!done.load()) {
      (void)driver_->state();
      (void)driver_->health();
      std::this_thread::sleep_for(std::chrono::microseconds(300));
    }
  });
  for (int i = 0; i < 60; ++i) {
    (void)driver_->apply(node::ActuatorCommand::make_drive(0.2, 0.1, 200));
    driver_->step(5);
    sleep_ms(5);
  }
  done.store(true);
  for (auto& t : stoppers) t.join();
  reader.join();
  driver_->stop();
  // (A zero Twist already on the wire less than a period ago is not written again: the last one
  // may come from an earlier stop().)
  ASSERT_TRUE(peer_->wait([](const auto& v) { return !v.empty() && v.back().zero(); }, 2000))
      << "the wire does not end with a zero Twist";
  const size_t n = peer_->twists().size();
  run_loop(200);  // the loop keeps stepping: nothing moves again
  const auto v = peer_->twists();
  for (size_t i = n; i < v.size(); ++i) EXPECT_TRUE(v[i].zero()) << "a moving Twist after stop()";
}

TEST_F(Ros2DriverTest, ADrivePublishesAtOnceRepublishesAtTheRateAndEndsWithAZeroTwist) {
  start();
  const int64_t t0 = test::steady_ns();
  ASSERT_TRUE(driver_->apply(node::ActuatorCommand::make_drive(0.3, -0.5, 500)).ok());
  // At once, without a loop step: the Twist with the command's fields, nothing else set.
  ASSERT_TRUE(peer_->wait([](const auto& v) { return !v.empty(); }, 2000));
  const WireTwist first = peer_->twists().front();
  EXPECT_DOUBLE_EQ(first.lx, 0.3);
  EXPECT_DOUBLE_EQ(first.az, -0.5);
  EXPECT_EQ(first.ly, 0.0);
  EXPECT_EQ(first.lz, 0.0);
  EXPECT_EQ(first.ax, 0.0);
  EXPECT_EQ(first.ay, 0.0);
  // (No step() has run: only apply() itself can have published it. How fast is ros2_bench's.)
  run_loop(800);
  const auto v = peer_->twists();
  size_t moving = 0;
  size_t first_zero = v.size();
  for (size_t i = 0; i < v.size(); ++i) {
    if (v[i].zero()) {
      if (first_zero == v.size()) first_zero = i;
    } else {
      ++moving;
      EXPECT_EQ(first_zero, v.size()) << "a moving Twist after the zero one";
      EXPECT_DOUBLE_EQ(v[i].lx, 0.3);
    }
  }
  // 500 ms at 20 Hz: about 10 (the loop's 20 ms steps blur the edges; a loaded machine that
  // steps late republishes less often, never more).
  EXPECT_GE(moving, 5u);
  EXPECT_LE(moving, 12u);
  ASSERT_LT(first_zero, v.size()) << "no zero Twist when the drive ended";
  EXPECT_GE(v[first_zero].t_ns - t0, 480'000'000);
  EXPECT_LE(v[first_zero].t_ns - t0, 900'000'000);
  EXPECT_EQ(peer_->bad_twists(), 0u);
  // The state shows the drive's targets while it runs (checked after: it ended).
  EXPECT_EQ(driver_->state().target_linear_mps, 0.0);
}

TEST_F(Ros2DriverTest, SpeedsBeyondTheHardwareEnvelopeAreClampedAndNaNIsRefused) {
  start();
  ASSERT_TRUE(driver_->apply(node::ActuatorCommand::make_drive(5.0, -9.0, 200)).ok());
  ASSERT_TRUE(peer_->wait([](const auto& v) { return !v.empty(); }, 2000));
  EXPECT_DOUBLE_EQ(peer_->twists().front().lx, 1.0);
  EXPECT_DOUBLE_EQ(peer_->twists().front().az, -2.0);
  peer_->clear();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(driver_->apply(node::ActuatorCommand::make_drive(nan, 0.0, 200)).ok());
  node::JointArray bad{};
  bad[3] = nan;
  EXPECT_FALSE(driver_->apply(node::ActuatorCommand::make_arm(bad)).ok());
  sleep_ms(200);
  for (const auto& t : peer_->twists()) EXPECT_TRUE(t.zero()) << "a refused command moved";
}

TEST_F(Ros2DriverTest, StopPublishesAZeroTwistAtOnceAndAtTheRateWhileItKeepsBeingCalled) {
  start();
  ASSERT_TRUE(driver_->apply(node::ActuatorCommand::make_drive(0.5, 0.0, 10000)).ok());
  ASSERT_TRUE(peer_->wait([](const auto& v) { return !v.empty(); }, 2000));
  // stop() from another thread, no loop step: a zero Twist is on the wire at once.
  const int64_t t_stop = test::steady_ns();
  std::thread([&] { driver_->stop(); }).join();
  ASSERT_TRUE(peer_->wait([&](const auto& v) { return count_zero(v, t_stop) > 0; }, 1000));
  int64_t t_zero = 0;
  for (const auto& t : peer_->twists())
    if (t.zero() && t.t_ns >= t_stop) {
      t_zero = t.t_ns;
      break;
    }
  // No step() ran: this zero Twist can only be stop()'s own (the bound allows a busy machine).
  EXPECT_LT(t_zero - t_stop, 200'000'000) << "the zero Twist came late";
  // Latched: the core calls stop() on every 20 ms tick. Zero Twists flow at 20 Hz, not 50.
  const int64_t t1 = test::steady_ns();
  for (int i = 0; i < 50; ++i) {
    driver_->stop();
    driver_->step(20);
    sleep_ms(20);
  }
  const auto v = peer_->twists();
  const size_t zeros = count_zero(v, t1);
  // One per 50 ms of what the loop took (50 ticks of at least 20 ms; longer on a busy machine).
  const double periods = static_cast<double>(test::steady_ns() - t1) / 50e6;
  EXPECT_GE(static_cast<double>(zeros), 0.6 * periods) << "zero Twists stopped while latched";
  EXPECT_LE(static_cast<double>(zeros), periods + 2) << "zero Twists flooded at the tick rate";
  for (const auto& t : v) {
    if (t.t_ns >= t_stop) {
      EXPECT_TRUE(t.zero()) << "a moving Twist after stop()";
    }
  }
  // A drive stopped by stop() is not republished by the loop, and the state shows no target.
  EXPECT_EQ(driver_->state().target_linear_mps, 0.0);
}

TEST_F(Ros2DriverTest, ZeroTwistsStopAfterStopRepeatMsWhenStopIsNoLongerCalled) {
  cfg_.stop_repeat_ms = 300;
  start();
  driver_->stop();
  run_loop(300);
  peer_->clear();
  run_loop(400);
  EXPECT_EQ(peer_->twists().size(), 0u) << "the driver kept talking on an idle robot";
}

TEST_F(Ros2DriverTest, OdometryAndJointStatesBecomeTheStateAndBadSamplesAreDropped) {
  start();
  peer_->publish_odom(2.0, -1.0, 1.2, 0.25, 0.1);
  peer_->publish_joints({"j2", "j1", "unknown"}, {0.5, -0.3, 4.0});
  node::RobotState s;
  for (int i = 0; i < 100; ++i) {
    driver_->step(20);
    s = driver_->state();
    if (s.x == 2.0 && s.joints_rad[1] == 0.5) break;
    sleep_ms(20);
  }
  EXPECT_DOUBLE_EQ(s.x, 2.0);
  EXPECT_DOUBLE_EQ(s.y, -1.0);
  EXPECT_NEAR(s.theta, 1.2, 1e-12);
  EXPECT_DOUBLE_EQ(s.linear_mps, 0.25);
  EXPECT_DOUBLE_EQ(s.angular_radps, 0.1);
  EXPECT_DOUBLE_EQ(s.joints_rad[0], -0.3);
  EXPECT_DOUBLE_EQ(s.joints_rad[1], 0.5);
  EXPECT_FALSE(s.stopped);  // it reports motion
  // A NaN pose is dropped: the state keeps the last good one.
  nav_msgs_msg_dds__Odometry_ bad{};
  bad.header.frame_id = const_cast<char*>("odom");
  bad.child_frame_id = const_cast<char*>("");
  bad.pose.pose.position.x = std::numeric_limits<double>::quiet_NaN();
  bad.pose.pose.orientation.w = 1.0;
  peer_->publish_odom_raw(bad);
  for (int i = 0; i < 10; ++i) {
    driver_->step(20);
    sleep_ms(20);
  }
  EXPECT_DOUBLE_EQ(driver_->state().x, 2.0);
  peer_->publish_odom(2.0, -1.0, 1.2, 0.0, 0.0);
  for (int i = 0; i < 100 && !driver_->state().stopped; ++i) {
    driver_->step(20);
    sleep_ms(20);
  }
  EXPECT_TRUE(driver_->state().stopped);
}

TEST_F(Ros2DriverTest, NoOdometryForTheTimeoutIsAFaultThatClearsWhenItComesBack) {
  start();
  // None yet, but the timeout (400 ms) has not passed since start.
  EXPECT_TRUE(driver_->health().ok);
  sleep_ms(500);
  node::DriverHealth h = driver_->health();
  EXPECT_FALSE(h.ok);
  EXPECT_NE(h.fault.find("rt/odom"), std::string::npos) << h.fault;
  peer_->publish_odom(0, 0, 0, 0, 0);
  for (int i = 0; i < 100 && !driver_->health().ok; ++i) {
    driver_->step(20);
    sleep_ms(10);
  }
  EXPECT_TRUE(driver_->health().ok);
  for (int i = 0; i < 30; ++i) {
    driver_->step(20);
    sleep_ms(20);
  }
  EXPECT_FALSE(driver_->health().ok) << "600 ms without odometry";
}

TEST_F(Ros2DriverTest, AnArmCommandIsOneTrajectoryPointAndStopHoldsTheArm) {
  start();
  node::JointArray target{0.5, -0.5, 0.0, 0.0, 0.0, 1.0};
  ASSERT_TRUE(driver_->apply(node::ActuatorCommand::make_arm(target, 0.5)).ok());
  auto b = peer_->take_trajectory_bytes(3000);
  ASSERT_TRUE(b);
  // Decoded by hand: header (stamp, frame_id ""), joint_names[6], points[1] {positions[6],
  // velocities[], accelerations[], effort[], time_from_start}.
  test::CdrReader r{b->data(), b->size()};
  r.get<int32_t>();
  r.get<uint32_t>();
  uint32_t len = r.get<uint32_t>();
  EXPECT_EQ(len, 1u);
  r.off += len;
  ASSERT_EQ(r.get<uint32_t>(), 6u);
  for (int i = 0; i < 6; ++i) {
    len = r.get<uint32_t>();
    EXPECT_EQ(std::string(reinterpret_cast<const char*>(b->data() + r.off)),
              "j" + std::to_string(i + 1));
    r.off += len;
  }
  ASSERT_EQ(r.get<uint32_t>(), 1u);  // one point
  ASSERT_EQ(r.get<uint32_t>(), 6u);
  for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(r.get<double>(), target[i]);
  EXPECT_EQ(r.get<uint32_t>(), 0u);  // velocities
  EXPECT_EQ(r.get<uint32_t>(), 0u);  // accelerations
  EXPECT_EQ(r.get<uint32_t>(), 0u);  // effort
  // The longest move is 1.0 rad at 0.5 rad/s: 2 s.
  EXPECT_EQ(r.get<int32_t>(), 2);
  EXPECT_EQ(r.get<uint32_t>(), 0u);
  EXPECT_TRUE(r.ok);
  EXPECT_EQ(r.off, b->size());
  // stop() during the motion: an empty trajectory (the controller holds where it is).
  driver_->stop();
  auto hold = peer_->take_trajectory_bytes(3000);
  ASSERT_TRUE(hold);
  test::CdrReader h{hold->data(), hold->size()};
  h.get<int32_t>();
  h.get<uint32_t>();
  h.off += h.get<uint32_t>();
  ASSERT_EQ(h.get<uint32_t>(), 6u);
  for (int i = 0; i < 6; ++i) h.off += h.get<uint32_t>();
  EXPECT_EQ(h.get<uint32_t>(), 0u) << "the hold trajectory has points";
}

TEST_F(Ros2DriverTest, AHugeDurationOrATinyJointSpeedStaysWithinTheMessage) {
  start();
  node::JointArray target{0.5, 0, 0, 0, 0, 0};
  ASSERT_TRUE(driver_->apply(node::ActuatorCommand::make_arm(target, 1e-300)).ok());
  auto b = peer_->take_trajectory_bytes(3000);
  ASSERT_TRUE(b);
  // time_from_start is the last 8 bytes: at most an hour.
  test::CdrReader r{b->data(), b->size()};
  r.off = b->size() - 8;
  EXPECT_EQ(r.get<int32_t>(), 3600);
  EXPECT_EQ(r.get<uint32_t>(), 0u);
  ASSERT_TRUE(driver_->apply(node::ActuatorCommand::make_drive(0.1, 0, INT64_MAX / 2)).ok());
  driver_->step(20);
  EXPECT_GT(driver_->state().drive_remaining_ms, 0);
  driver_->stop();
}

// The generated serializer writes Odometry exactly as encoded by hand from ROS 2's layout
// (header, child_frame_id, pose with covariance[36], twist with covariance[36]).
TEST(Ros2Cdr, OdometryBytesAreRos2sLayout) {
  test::use_loopback_dds();
  const uint32_t domain = test::random_domain_id();
  const dds_entity_t pp = dds_create_participant(domain, nullptr, nullptr);
  ASSERT_GT(pp, 0);
  const dds_entity_t t =
      dds_create_topic(pp, &nav_msgs_msg_dds__Odometry__desc, "rt/odom", nullptr, nullptr);
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  const dds_entity_t rd = dds_create_reader(pp, t, q, nullptr);
  const dds_entity_t wr = dds_create_writer(pp, t, q, nullptr);
  dds_delete_qos(q);
  nav_msgs_msg_dds__Odometry_ m{};
  m.header.stamp.sec = 17;
  m.header.stamp.nanosec = 5;
  m.header.frame_id = const_cast<char*>("odom");
  m.child_frame_id = const_cast<char*>("base_link");
  m.pose.pose.position.x = 1.25;
  m.pose.pose.position.y = -3.5;
  m.pose.pose.orientation.z = 0.6;
  m.pose.pose.orientation.w = 0.8;
  m.twist.twist.linear.x = 0.5;
  m.twist.twist.angular.z = -0.25;
  ASSERT_EQ(dds_write(wr, &m), 0);
  struct ddsi_serdata* d = nullptr;
  dds_sample_info_t si;
  int n = 0;
  for (int i = 0; i < 200 && n != 1; ++i) {
    n = dds_takecdr(rd, &d, 1, &si, DDS_ANY_STATE);
    if (n != 1) sleep_ms(5);
  }
  ASSERT_EQ(n, 1);
  const auto bytes = test::serdata_bytes(d);
  ddsi_serdata_unref(d);
  EXPECT_EQ(bytes,
            test::encode_odometry(17, 5, "odom", "base_link", 1.25, -3.5, 0.6, 0.8, 0.5, -0.25));
  dds_delete(pp);
}

}  // namespace
}  // namespace rcan
