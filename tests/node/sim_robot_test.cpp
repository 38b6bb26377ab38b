// SimRobot: integration numbers (unicycle with acceleration limits, arm at max joint speed),
// stop semantics, determinism, telemetry JSON and the chat helper.
#include "node/safety/sim_robot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <thread>
#include <vector>

namespace rcan::node {
namespace {

SimRobotConfig no_battery() {
  SimRobotConfig c;
  c.battery = false;
  return c;
}

void run(SimRobot& r, int64_t ms, int64_t step = 20) {
  for (int64_t t = 0; t < ms; t += step) r.step(std::min(step, ms - t));
}

TEST(SimRobot, StartsStoppedAtConfiguredPose) {
  SimRobotConfig c;
  c.x = 1.0;
  c.y = -2.0;
  c.theta = 0.5;
  SimRobot r(c);
  auto s = r.state();
  EXPECT_TRUE(s.stopped);
  EXPECT_DOUBLE_EQ(s.x, 1.0);
  EXPECT_DOUBLE_EQ(s.y, -2.0);
  EXPECT_DOUBLE_EQ(s.theta, 0.5);
  EXPECT_TRUE(s.battery_known);
  EXPECT_DOUBLE_EQ(s.battery_pct, 100.0);
}

TEST(SimRobot, DriveHalfMeterPerSecondForOneSecondWithAccelerationLimit) {
  SimRobot r(no_battery());  // accel 1 m/s^2
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(0.5, 0.0, 1000)).ok());
  EXPECT_FALSE(r.state().stopped);
  run(r, 1000);
  auto s = r.state();
  // 0.5 s ramp (0.125 m) + 0.5 s cruise (0.25 m).
  EXPECT_NEAR(s.x, 0.375, 1e-9);
  EXPECT_NEAR(s.y, 0.0, 1e-12);
  EXPECT_NEAR(s.linear_mps, 0.5, 1e-12);
  EXPECT_EQ(s.drive_remaining_ms, 0);
  EXPECT_DOUBLE_EQ(s.target_linear_mps, 0.0);  // duration elapsed → target 0
  run(r, 1000);
  s = r.state();
  // Deceleration over 0.5 s adds 0.125 m: 0.5 m in total, at rest.
  EXPECT_NEAR(s.x, 0.5, 1e-9);
  EXPECT_DOUBLE_EQ(s.linear_mps, 0.0);
  EXPECT_TRUE(s.stopped);
  EXPECT_NEAR(s.odometry_m, 0.5, 1e-9);
  EXPECT_EQ(s.t_ms, 2000);
}

TEST(SimRobot, OddStepSizesGiveTheSameAnswer) {
  SimRobot a(no_battery()), b(no_battery());
  ASSERT_TRUE(a.apply(ActuatorCommand::make_drive(0.5, 0.3, 1000)).ok());
  ASSERT_TRUE(b.apply(ActuatorCommand::make_drive(0.5, 0.3, 1000)).ok());
  run(a, 2000, 20);
  run(b, 2000, 7);
  // Different sub-step boundaries: the midpoint integrator agrees to well under a micrometre.
  EXPECT_NEAR(a.state().x, b.state().x, 1e-6);
  EXPECT_NEAR(a.state().y, b.state().y, 1e-6);
  EXPECT_NEAR(a.state().theta, b.state().theta, 1e-9);
  // Same step sizes: bit-identical (deterministic).
  SimRobot c(no_battery());
  ASSERT_TRUE(c.apply(ActuatorCommand::make_drive(0.5, 0.3, 1000)).ok());
  run(c, 2000, 7);
  EXPECT_EQ(b.state().x, c.state().x);
  EXPECT_EQ(b.state().y, c.state().y);
}

TEST(SimRobot, TurnInPlaceIntegratesHeading) {
  SimRobot r(no_battery());  // angular accel 4 rad/s^2
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(0.0, 1.0, 1000)).ok());
  run(r, 3000);
  auto s = r.state();
  // ramp 0.25 s (0.125 rad) + 0.75 s cruise + 0.25 s ramp down (0.125 rad) = 1.0 rad.
  EXPECT_NEAR(s.theta, 1.0, 1e-9);
  EXPECT_NEAR(s.x, 0.0, 1e-12);
  EXPECT_TRUE(s.stopped);
}

TEST(SimRobot, ArcFollowsUnicycleModel) {
  SimRobotConfig c = no_battery();
  c.linear_accel_mps2 = 0;  // instantaneous, to compare with the closed form
  c.angular_accel_radps2 = 0;
  SimRobot r(c);
  const double v = 0.5, w = 0.5;
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(v, w, 2000)).ok());
  run(r, 2000);
  auto s = r.state();
  const double t = 2.0;
  EXPECT_NEAR(s.x, v / w * std::sin(w * t), 1e-6);
  EXPECT_NEAR(s.y, v / w * (1 - std::cos(w * t)), 1e-6);
  EXPECT_NEAR(s.theta, w * t, 1e-9);
}

TEST(SimRobot, ArmJointsReachTargetsAtMaxSpeed) {
  SimRobot r(no_battery());  // max joint speed 2 rad/s
  JointArray target{1.0, -0.5, 0.25, 0.0, 2.0, -1.0};
  ASSERT_TRUE(r.apply(ActuatorCommand::make_arm(target, 1.0)).ok());
  run(r, 500);
  auto s = r.state();
  EXPECT_NEAR(s.joints_rad[0], 0.5, 1e-9);   // still moving at 1 rad/s
  EXPECT_NEAR(s.joints_rad[1], -0.5, 1e-9);  // reached
  EXPECT_NEAR(s.joints_rad[2], 0.25, 1e-9);
  EXPECT_NEAR(s.joints_rad[4], 0.5, 1e-9);
  EXPECT_FALSE(s.stopped);
  run(r, 1500);
  s = r.state();
  for (int i = 0; i < kArmJoints; ++i) EXPECT_DOUBLE_EQ(s.joints_rad[i], target[i]) << i;
  EXPECT_TRUE(s.stopped);
}

TEST(SimRobot, ArmSpeedCappedByHardwareAndTargetsByRange) {
  SimRobot r(no_battery());
  JointArray target{10.0, 0, 0, 0, 0, 0};                              // beyond hardware range 3.1
  ASSERT_TRUE(r.apply(ActuatorCommand::make_arm(target, 50.0)).ok());  // speed capped to 2
  run(r, 1000);
  EXPECT_NEAR(r.state().joints_rad[0], 2.0, 1e-9);
  run(r, 1000);
  EXPECT_NEAR(r.state().joints_rad[0], 3.1, 1e-9);
}

TEST(SimRobot, StopBrakesBaseAndFreezesArm) {
  SimRobot r(no_battery());
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(1.0, 0.0, 5000)).ok());
  ASSERT_TRUE(r.apply(ActuatorCommand::make_arm({1, 1, 1, 1, 1, 1}, 1.0)).ok());
  run(r, 1000);  // v = 1.0, joints = 1.0 (reached)... joints move 1 rad in 1 s
  ASSERT_TRUE(r.apply(ActuatorCommand::make_arm({2, 2, 2, 2, 1.5, 2}, 1.0)).ok());
  run(r, 200);
  const double x_before = r.state().x;
  const auto joints_before = r.state().joints_rad;
  r.stop();
  r.stop();  // idempotent
  EXPECT_EQ(r.stop_count(), 2u);
  auto s = r.state();
  EXPECT_DOUBLE_EQ(s.target_linear_mps, 0.0);
  EXPECT_EQ(s.joint_targets_rad, joints_before);
  run(r, 1000);
  s = r.state();
  EXPECT_TRUE(s.stopped);
  // Braking at 3 m/s^2 from 1 m/s: 1/6 m.
  EXPECT_NEAR(s.x - x_before, 1.0 / 6.0, 1e-6);
  EXPECT_EQ(s.joints_rad, joints_before);
}

// The safety loop rests up to a second between ticks at rest: one long step of a robot at rest
// must leave exactly the state of many short ones (clock, battery, pose), and a long step of a
// robot still braking must still brake.
TEST(SimRobot, ALongStepAtRestEqualsShortStepsAndALongStepStillBrakes) {
  SimRobot a, b;
  for (SimRobot* r : {&a, &b}) {
    ASSERT_TRUE(r->apply(ActuatorCommand::make_drive(0.5, 0.3, 400)).ok());
    run(*r, 2000, 20);  // drove, then came to rest
    ASSERT_TRUE(r->state().stopped);
  }
  const double before = a.state().battery_pct;
  const int64_t t_before = a.state().t_ms;
  run(a, 3000, 1000);
  run(b, 3000, 5);
  EXPECT_EQ(a.state().t_ms, t_before + 3000);
  EXPECT_NEAR(before - a.state().battery_pct, 0.002 * 3.0, 1e-9);  // the idle drain, 0.002 %/s
  const auto sa = a.state(), sb = b.state();
  EXPECT_EQ(sa.t_ms, sb.t_ms);
  EXPECT_EQ(sa.battery_pct, sb.battery_pct);
  EXPECT_EQ(sa.battery_v, sb.battery_v);
  EXPECT_EQ(sa.x, sb.x);
  EXPECT_EQ(sa.y, sb.y);
  EXPECT_EQ(sa.theta, sb.theta);
  EXPECT_LT(sa.battery_pct, 100.0);
  EXPECT_TRUE(sa.stopped);

  SimRobot c(no_battery());
  ASSERT_TRUE(c.apply(ActuatorCommand::make_drive(1.0, 0.0, 5000)).ok());
  run(c, 1000);
  const double x_before = c.state().x;
  c.stop();
  c.step(1000);  // one tick after a second's rest: braking at 3 m/s^2 from 1 m/s
  EXPECT_TRUE(c.state().stopped);
  EXPECT_NEAR(c.state().x - x_before, 1.0 / 6.0, 1e-6);
}

TEST(SimRobot, StopIsSafeFromManyThreads) {
  SimRobot r(no_battery());
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(1.0, 0.0, 5000)).ok());
  std::vector<std::thread> ts;
  for (int i = 0; i < 8; ++i)
    ts.emplace_back([&] {
      for (int k = 0; k < 1000; ++k) r.stop();
    });
  for (int k = 0; k < 200; ++k) r.step(5);
  for (auto& t : ts) t.join();
  EXPECT_EQ(r.stop_count(), 8000u);
  run(r, 2000);
  EXPECT_TRUE(r.state().stopped);
}

TEST(SimRobot, NewCommandAfterStopMovesAgain) {
  SimRobot r(no_battery());
  r.stop();
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(0.5, 0.0, 1000)).ok());
  run(r, 2000);
  EXPECT_NEAR(r.state().x, 0.5, 1e-9);
}

TEST(SimRobot, GripperAndStopCommand) {
  SimRobot r(no_battery());
  ActuatorCommand c;
  c.gripper = GripperAction::kClose;
  ASSERT_TRUE(r.apply(c).ok());
  EXPECT_TRUE(r.state().gripper_closed);
  c.gripper = GripperAction::kOpen;
  ASSERT_TRUE(r.apply(c).ok());
  EXPECT_FALSE(r.state().gripper_closed);
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(1.0, 0, 1000)).ok());
  ASSERT_TRUE(r.apply(ActuatorCommand::make_stop()).ok());
  run(r, 100);
  EXPECT_TRUE(r.state().stopped);
}

TEST(SimRobot, RejectsNonFiniteValues) {
  SimRobot r(no_battery());
  EXPECT_FALSE(r.apply(ActuatorCommand::make_drive(std::nan(""), 0, 100)).ok());
  JointArray bad{0, 0, std::numeric_limits<double>::infinity(), 0, 0, 0};
  EXPECT_FALSE(r.apply(ActuatorCommand::make_arm(bad)).ok());
}

TEST(SimRobot, BatteryDrainsWithMotion) {
  SimRobot idle, moving;
  ASSERT_TRUE(moving.apply(ActuatorCommand::make_drive(1.0, 0, 10000)).ok());
  run(idle, 10000);
  run(moving, 10000);
  EXPECT_LT(idle.state().battery_pct, 100.0);
  EXPECT_LT(moving.state().battery_pct, idle.state().battery_pct);
  EXPECT_GT(moving.state().battery_v, 10.5);
}

TEST(SimRobot, DescribeReportsEnvelope) {
  SimRobot r;
  auto d = r.describe();
  EXPECT_EQ(d.name, "sim");
  EXPECT_TRUE(d.simulated && d.has_base && d.has_arm && d.has_chat);
  EXPECT_EQ(d.arm_joints, 6);
  EXPECT_DOUBLE_EQ(d.max_linear_mps, 1.5);
  auto j = d.to_json();
  ASSERT_NE(j.find("capabilities"), nullptr);
  EXPECT_TRUE(j.find("capabilities")->is_array());
}

TEST(SimRobot, TelemetryJsonHasRequiredFields) {
  SimRobot r;
  auto s = r.state();
  s.ts = 1'750'000'000'000;
  s.loop_count = 7;
  s.loop_latency_ms = 0.25;
  auto o = s.to_json();
  for (const char* k :
       {"ts", "loop_latency_ms", "loop_count", "paused", "base", "arm", "battery_v"})
    EXPECT_TRUE(o.contains(k)) << k;
  EXPECT_EQ(o.find("ts")->as_int(), 1'750'000'000'000);
  EXPECT_EQ(o.find("loop_count")->as_int(), 7);
  EXPECT_TRUE(o.find("base")->get("x")->is_double());
  EXPECT_EQ(o.find("arm")->get("joints_rad")->as_array().size(), 6u);
  // Round-trips through the strict parser.
  auto parsed = json::parse(json::dump(json::Value(o)));
  ASSERT_TRUE(parsed.ok());
}

TEST(SimRobotChat, AnswersFromStatus) {
  SimRobot r(no_battery());
  ASSERT_TRUE(r.apply(ActuatorCommand::make_drive(0.5, 0.0, 1000)).ok());
  run(r, 2000);
  auto s = r.state();
  EXPECT_NE(chat("Where are you?", s).find("x=0.50"), std::string::npos);
  EXPECT_NE(chat("status", s).find("stopped"), std::string::npos);
  EXPECT_NE(chat("battery?", s).find("no battery"), std::string::npos);
  SimRobot b;
  EXPECT_NE(chat("How is the BATTERY", b.state()).find("100.0%"), std::string::npos);
  EXPECT_NE(chat("arm", s).find("Arm joints"), std::string::npos);
  ChatContext ctx;
  ctx.estop_active = true;
  ctx.estop_reason = "operator";
  EXPECT_NE(chat("status", s, ctx).find("Emergency stop is latched (operator)"), std::string::npos);
  EXPECT_NE(chat("sing me a song", s).find("I can answer"), std::string::npos);
}

}  // namespace
}  // namespace rcan::node
