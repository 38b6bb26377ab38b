// rcand with driver.type process, running the reference Python driver
// (examples/drivers/serial_diffbase.py) on a pseudo-terminal that plays the serial base: a move
// COMMAND arrives as the wheel-speed line, ESTOP sends the stop line at once, a killed driver
// process safe-stops the robot, is audited and recovers, and a driver that answers garbage
// faults (DRIVER_FAULT, and the ESTOP latch with safety.estop_on_driver_fault).
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <string>
#include <thread>

#include "configured_node.h"
#include "pty_base.h"

namespace rcan::test {
namespace {

const std::string kReference =
    std::string(RCAN_SOURCE_DIR) + "/examples/drivers/serial_diffbase.py";
const std::string kFake = std::string(RCAN_SOURCE_DIR) + "/tests/drivers/fake_driver.py";

std::string driver_block(const std::string& command, const std::string& extra = {}) {
  return "driver:\n  type: process\n  sim:\n    tick_hz: 100\n  process:\n    command: " + command +
         "\n    heartbeat_ms: 50\n    heartbeat_timeout_ms: 500\n    restart_backoff_ms: 100\n"
         "    restart_backoff_max_ms: 400\n    max_linear_mps: 1.0\n    max_angular_radps: 3.0\n" +
         extra;
}

std::string reference_block(const PtyBase& pty) {
  return driver_block("[\"python3\", \"" + kReference + "\", \"--port\", \"" + pty.slave_path() +
                      "\", \"--wheel-base\", \"0.3\"]");
}

using test::eventually;

std::string estop_json() {
  json::Object m{{"version", "1.0.0"},
                 {"message_id", new_uuid_v4()},
                 {"type", "SAFETY"},
                 {"timestamp_ms", now_wall_ms()},
                 {"payload", json::Object{{"safety_event", "ESTOP"}, {"reason", "test"}}}};
  return json::dump(json::Value(m));
}

int count_events(const ConfiguredNode& node, const std::string& owner, const std::string& event) {
  int n = 0;
  for (const auto& r : node.audit(owner))
    if (const json::Value* e = r.get("event"); e && e->is_string() && e->as_string() == event) ++n;
  return n;
}

// The driver process's pid, from rcand's log line driver_process_started/_restarted.
pid_t driver_pid(ConfiguredNode& node, const std::string& event) {
  auto line = node.proc().wait_for_line("\"event\":\"" + event + "\"", 10000);
  if (!line) return -1;
  json::Value v = parse_json(*line);
  const json::Value* p = v.get("pid");
  return p && p->is_int() ? static_cast<pid_t>(p->as_int()) : -1;
}

json::Value status(const ConfiguredNode& node, const std::string& tok) {
  return parse_json(node.get("/rcan/v1/status", tok).body);
}

TEST(ProcessDriverE2E, MoveArrivesAsWheelSpeedsAndEstopStopsAtOnce) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ConfiguredNode node("", 2000, false, "", reference_block(pty));
  const std::string owner = node.token("owner", {"control", "status", "safety"}, "alice");
  ASSERT_GT(driver_pid(node, "driver_process_started"), 0);
  pty.drain();
  // linear 0.2, angular 0.4, wheel base 0.3: left 0.2 - 0.06, right 0.2 + 0.06.
  HttpReply r = node.post(
      "/rcan/v1/command",
      command_json("move", {{"linear", 0.2}, {"angular", 0.4}, {"duration_ms", 2000}}), owner);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.140 0.260");
  // The safety core's limits reach the process, not the raw command: 5 m/s is clamped to the
  // configured safety.max_linear_speed_mps (0.5 by default).
  r = node.post("/rcan/v1/command", command_json("move", {{"linear", 5.0}, {"duration_ms", 2000}}),
                owner);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.500 0.500");
  // The stop line follows (how fast is bench/process_driver_bench's to say, not a test's).
  r = node.post("/rcan/v1/command", estop_json(), owner);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(pty.line_starting("V ", 2000).value_or("none"), "V 0.000 0.000");
  EXPECT_TRUE(status(node, owner).get("estop_active")->as_bool());
  // Latched: motion is refused, and the base keeps getting stops (a few a second) and
  // nothing else.
  r = node.post("/rcan/v1/command", command_json("move", {{"linear", 0.1}, {"duration_ms", 500}}),
                owner);
  EXPECT_EQ(r.status, 423) << r.body;
  int stops = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(1500);
  while (std::chrono::steady_clock::now() < end) {
    auto l = pty.line(300);
    if (!l) continue;
    EXPECT_EQ(*l, "V 0.000 0.000");
    ++stops;
  }
  EXPECT_GE(stops, 2);
  EXPECT_LE(stops, 12);
}

TEST(ProcessDriverE2E, AKilledDriverSafeStopsIsAuditedAndRecovers) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ConfiguredNode node("", 2000, false, "", reference_block(pty));
  const std::string owner = node.token("owner", {"control", "status", "safety"}, "alice");
  const pid_t pid = driver_pid(node, "driver_process_started");
  ASSERT_GT(pid, 0);
  HttpReply r = node.post("/rcan/v1/command",
                          command_json("move", {{"linear", 0.3}, {"duration_ms", 5000}}), owner);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(pty.line_starting("V 0.3", 3000).value_or("none"), "V 0.300 0.300");
  // The base's odometry becomes the robot's pose in the status.
  pty.say("O 0 0");
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  pty.say("O 0.25 0.25");
  auto core_status = [&] { return *status(node, owner).get("robot"); };
  EXPECT_TRUE(eventually(
      [&] {
        const json::Value st = core_status();  // x points into it: keep it alive
        const json::Value* robot = st.get("robot");
        const json::Value* base = robot ? robot->get("base") : nullptr;
        const json::Value* x = base ? base->get("x") : nullptr;
        return x && std::abs(x->to_double() - 0.25) < 1e-6;
      },
      3000))
      << json::dump(core_status());
  ASSERT_EQ(::kill(pid, SIGKILL), 0);
  // Fault: safe stop, audited, and the status says why.
  ASSERT_TRUE(eventually([&] { return count_events(node, owner, "DRIVER_FAULT") == 1; }, 5000));
  // A new process, healthy again: DRIVER_RECOVERED, and it starts by stopping the base.
  const pid_t second = driver_pid(node, "driver_process_restarted");
  EXPECT_GT(second, 0);
  EXPECT_NE(second, pid);
  EXPECT_EQ(pty.line_starting("V ", 5000).value_or("none"), "V 0.000 0.000");
  ASSERT_TRUE(
      eventually([&] { return count_events(node, owner, "DRIVER_RECOVERED") == 1; }, 10000));
  for (const auto& rec : node.audit(owner)) {
    if (rec.get("event")->as_string() != "DRIVER_FAULT") continue;
    const std::string d = json::dump(rec);
    EXPECT_NE(d.find("driver process"), std::string::npos) << d;
  }
  // Motion is accepted again and reaches the new process.
  pty.drain();
  r = node.post("/rcan/v1/command", command_json("move", {{"linear", 0.1}, {"duration_ms", 300}}),
                owner);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.100 0.100");
  EXPECT_FALSE(status(node, owner).get("estop_active")->as_bool());
}

TEST(ProcessDriverE2E, GarbageFromTheDriverFaultsAndLatchesEstopWhereConfigured) {
  ConfiguredNode node("", 2000, false, "",
                      driver_block("[\"python3\", \"" + kFake +
                                   "\", \"garbage\", \"--after-ms\", "
                                   "\"1500\"]"));
  const std::string owner = node.token("owner", {"control", "status", "safety"}, "alice");
  ASSERT_TRUE(eventually([&] { return count_events(node, owner, "DRIVER_FAULT") >= 1; }, 8000));
  EXPECT_EQ(node.proc().wait_for_line("bad frame", 1000).has_value(), true);
  // Without estop_on_driver_fault the latch stays clear.
  EXPECT_FALSE(status(node, owner).get("estop_active")->as_bool());
}

TEST(ProcessDriverE2E, SilenceLatchesEstopWithEstopOnDriverFault) {
  // The driver block follows the fixture's safety block: a first line indented by two spaces
  // is one more safety key.
  ConfiguredNode node(
      "", 2000, false, "",
      "  estop_on_driver_fault: true\n" +
          driver_block("[\"python3\", \"" + kFake + "\", \"silent\", \"--after-ms\", \"1500\"]"));
  const std::string owner = node.token("owner", {"control", "status", "safety"}, "alice");
  ASSERT_TRUE(eventually([&] { return count_events(node, owner, "DRIVER_FAULT") >= 1; }, 8000));
  EXPECT_TRUE(status(node, owner).get("estop_active")->as_bool());
  EXPECT_TRUE(node.proc().wait_for_line("no heartbeat", 1000).has_value());
}

// The frames the fake driver received (its --record file), one JSON object each.
std::vector<json::Value> recorded(const std::string& path) {
  std::vector<json::Value> out;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);)
    if (auto v = json::parse(line); v.ok()) out.push_back(std::move(v).value());
  return out;
}

// The last apply frame's command member carrying `key` ("arm", "gripper"), or null.
json::Value last_apply(const std::string& path, const char* key) {
  json::Value found;
  for (const auto& f : recorded(path)) {
    const json::Value* type = f.get("type");
    const json::Value* cmd = f.get("command");
    if (type && type->is_string() && type->as_string() == "apply" && cmd && cmd->get(key))
      found = *cmd->get(key);
  }
  return found;
}

TEST(ProcessDriverE2E, AnArmAndAGripperBehindTheProcessGetLimitedCommands) {
  TempDir rec;
  const std::string frames = rec.path() + "/frames.jsonl";
  ConfiguredNode node(
      "", 2000, false, "",
      driver_block("[\"python3\", \"" + kFake + "\", \"good\", \"--record\", \"" + frames + "\"]",
                   "    arm_joints: 6\n    max_joint_speed_radps: 0.5\n"
                   "    joint_min_rad: [-1.0, -1.0, -1.0, -1.0, -1.0, -1.0]\n"
                   "    joint_max_rad: [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]\n    gripper: true\n"));
  const std::string owner = node.token("owner", {"control", "status", "safety"}, "alice");
  ASSERT_GT(driver_pid(node, "driver_process_started"), 0);
  // An arm move outside the joint range and over the joint speed reaches the process limited.
  HttpReply r =
      node.post("/rcan/v1/command",
                command_json("arm_move", {{"joints", json::Array{0.2, 3.0, -2.0, 0, 0, 0}},
                                          {"max_joint_speed_radps", 2.0}}),
                owner);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_NE(r.body.find("joint_max_rad"), std::string::npos) << r.body;  // the clamp is named
  json::Value arm;
  ASSERT_TRUE(eventually(
      [&] {
        arm = last_apply(frames, "arm");
        return !arm.is_null();
      },
      3000));
  const json::Value* targets = arm.get("targets_rad");
  ASSERT_NE(targets, nullptr) << json::dump(arm);
  ASSERT_EQ(targets->as_array().size(), 6u);
  EXPECT_DOUBLE_EQ(targets->as_array()[0].to_double(), 0.2);
  EXPECT_DOUBLE_EQ(targets->as_array()[1].to_double(), 1.0);
  EXPECT_DOUBLE_EQ(targets->as_array()[2].to_double(), -1.0);
  EXPECT_LE(arm.get("max_joint_speed_radps")->to_double(), 0.5);
  // The gripper.
  r = node.post("/rcan/v1/command", command_json("gripper_close", {}), owner);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value grip;
  ASSERT_TRUE(eventually(
      [&] {
        grip = last_apply(frames, "gripper");
        return !grip.is_null();
      },
      3000));
  EXPECT_EQ(json::dump(grip), "\"close\"");
}

TEST(ProcessDriverE2E, WithoutAnArmConfiguredArmCommandsAreRefused) {
  ConfiguredNode node("", 2000, false, "",
                      driver_block("[\"python3\", \"" + kFake + "\", \"good\"]"));
  const std::string owner = node.token("owner", {"control", "status", "safety"}, "alice");
  ASSERT_GT(driver_pid(node, "driver_process_started"), 0);
  HttpReply r =
      node.post("/rcan/v1/command",
                command_json("arm_move", {{"joints", json::Array{0.2, 0, 0, 0, 0, 0}}}), owner);
  EXPECT_EQ(r.status, 422) << r.body;
  r = node.post("/rcan/v1/command", command_json("gripper_open", {}), owner);
  EXPECT_EQ(r.status, 422) << r.body;
}

}  // namespace
}  // namespace rcan::test
