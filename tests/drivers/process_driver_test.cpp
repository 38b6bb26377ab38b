// ProcessDriver (src/drivers/process): the reference Python driver (examples/drivers/
// serial_diffbase.py) on a pseudo-terminal playing the base, misbehaving driver processes
// (tests/drivers/fake_driver.py), and a process played by the test itself over driver.process
// socket to show that a stop jumps the queue.
#include "drivers/process/process_driver.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <functional>
#include <mutex>
#include <thread>

#include "pty_base.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan::drivers {
namespace {

using node::ActuatorCommand;
using test::PtyBase;

const std::string kReference =
    std::string(RCAN_SOURCE_DIR) + "/examples/drivers/serial_diffbase.py";
const std::string kFake = std::string(RCAN_SOURCE_DIR) + "/tests/drivers/fake_driver.py";

using test::eventually;

ProcessDriverOptions options(std::vector<std::string> command) {
  ProcessDriverOptions o;
  o.file.command = std::move(command);
  o.file.heartbeat_ms = 50;
  o.file.heartbeat_timeout_ms = 400;
  o.file.startup_timeout_ms = 10000;
  o.file.restart_backoff_ms = 100;
  o.file.restart_backoff_max_ms = 400;
  o.kill_grace_ms = 300;
  o.info.name = "process";
  o.info.has_base = true;
  o.info.max_linear_mps = 1.0;
  o.info.max_angular_radps = 2.0;
  return o;
}

ProcessDriverOptions reference_on(const PtyBase& pty) {
  return options({"python3", kReference, "--port", pty.slave_path(), "--wheel-base", "0.3",
                  "--max-wheel-mps", "1.0"});
}

// A fault whose text contains `needle` is reported within `timeout_ms`.
bool faults_with(const ProcessDriver& d, const std::string& needle, int timeout_ms,
                 std::string* seen = nullptr) {
  return eventually(
      [&] {
        auto h = d.health();
        if (!h.ok && seen) *seen = h.fault;
        return !h.ok && h.fault.find(needle) != std::string::npos;
      },
      timeout_ms);
}

TEST(ProcessDriver, ReferenceDriverTurnsADriveIntoWheelSpeedsForItsDuration) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ProcessDriver d(reference_on(pty));
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy()) << d.health().fault;
  EXPECT_TRUE(d.health().ok);
  EXPECT_EQ(d.describe().name, "process");
  pty.drain();
  // v = 0.2, w = 0.5, b = 0.3: left = 0.2 - 0.075, right = 0.2 + 0.075.
  ASSERT_TRUE(d.apply(ActuatorCommand::make_drive(0.2, 0.5, 300)).ok());
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.125 0.275");
  ASSERT_TRUE(eventually([&] { return d.state().target_linear_mps == 0.2; }, 2000));
  // The duration ends: the driver stops the base by itself.
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.000 0.000");
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(150));
  EXPECT_TRUE(eventually([&] { return d.state().target_linear_mps == 0.0; }, 2000));
  // Both wheels over the limit: scaled down together (the curvature is kept).
  ASSERT_TRUE(d.apply(ActuatorCommand::make_drive(1.0, 4.0, 200)).ok());
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.250 1.000");
}

TEST(ProcessDriver, StopReachesTheBaseAtOnceFromAnyThread) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ProcessDriver d(reference_on(pty));
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy());
  pty.drain();
  ASSERT_TRUE(d.apply(ActuatorCommand::make_drive(0.3, 0, 10000)).ok());
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.300 0.300");
  const auto t0 = std::chrono::steady_clock::now();
  std::thread([&] { d.stop(); }).join();
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.000 0.000");
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(1000));
  EXPECT_GE(d.stop_frames_sent(), 1u);
  // Repeated stops with nothing moved since are not a flood on the socket.
  const uint64_t frames = d.stop_frames_sent();
  for (int i = 0; i < 100; ++i) d.stop();
  EXPECT_LE(d.stop_frames_sent(), frames + 1);
}

TEST(ProcessDriver, OdometryLinesBecomeThePose) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ProcessDriver d(reference_on(pty));
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy());
  pty.say("O 0 0");
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  pty.say("O 0.1 0.1");
  ASSERT_TRUE(eventually([&] { return std::abs(d.state().x - 0.1) < 1e-9; }, 3000)) << d.state().x;
  EXPECT_NEAR(d.state().odometry_m, 0.1, 1e-9);
  EXPECT_NEAR(d.state().theta, 0.0, 1e-9);
  // A base fault line becomes a driver fault; clearing it recovers.
  pty.say("E motor driver overcurrent");
  EXPECT_TRUE(faults_with(d, "overcurrent", 3000));
  EXPECT_FALSE(d.apply(ActuatorCommand::make_drive(0.1, 0, 100)).ok());
  pty.say("E");
  EXPECT_TRUE(eventually([&] { return d.health().ok; }, 3000));
}

TEST(ProcessDriver, AKilledProcessIsAFaultThenRestartsAndRecovers) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ProcessDriver d(reference_on(pty));
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy());
  const pid_t first = d.child_pid();
  ASSERT_GT(first, 0);
  ASSERT_EQ(::kill(first, SIGKILL), 0);
  std::string seen;
  EXPECT_TRUE(faults_with(d, "driver process", 3000, &seen)) << seen;
  EXPECT_FALSE(d.apply(ActuatorCommand::make_drive(0.1, 0, 100)).ok());
  EXPECT_TRUE(d.apply(ActuatorCommand::make_stop()).ok());  // a stop is always accepted
  ASSERT_TRUE(eventually([&] { return d.healthy() && d.health().ok; }, 10000));
  EXPECT_EQ(d.restarts(), 1u);
  EXPECT_NE(d.child_pid(), first);
  pty.drain();
  ASSERT_TRUE(d.apply(ActuatorCommand::make_drive(0.1, 0, 500)).ok());
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.100 0.100");
}

struct Misbehaviour {
  const char* mode;
  const char* fault;
};

class ProcessDriverMisbehaving : public ::testing::TestWithParam<Misbehaviour> {};

TEST_P(ProcessDriverMisbehaving, IsAFaultAndIsRestarted) {
  const Misbehaviour& m = GetParam();
  ProcessDriver d(options({"python3", kFake, m.mode, "--after-ms", "300"}));
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy()) << d.health().fault;
  std::string seen;
  EXPECT_TRUE(faults_with(d, m.fault, 5000, &seen)) << m.mode << ": " << seen;
  EXPECT_FALSE(d.apply(ActuatorCommand::make_drive(0.1, 0, 100)).ok());
  if (std::string(m.mode) != "fault") {  // a process that reports a fault is alive: no restart
    EXPECT_TRUE(eventually([&] { return d.restarts() >= 1; }, 5000)) << m.mode;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Modes, ProcessDriverMisbehaving,
    ::testing::Values(Misbehaviour{"garbage", "bad frame"},
                      Misbehaviour{"oversize", "frame length 16777216"},
                      Misbehaviour{"badtype", "state.base.x must be a finite number"},
                      Misbehaviour{"unknown", "unknown frame type"},
                      Misbehaviour{"silent", "no heartbeat"}, Misbehaviour{"exit", "exit status 3"},
                      Misbehaviour{"fault", "motor overheated"}),
    [](const auto& p) { return std::string(p.param.mode); });

TEST(ProcessDriver, ANarrowerHardwareEnvelopeThanConfiguredIsAFault) {
  ProcessDriver d(options({"python3", kFake, "narrow"}));
  ASSERT_TRUE(d.start().ok());
  EXPECT_FALSE(d.healthy());
  EXPECT_TRUE(faults_with(d, "narrower envelope", 3000));
}

TEST(ProcessDriver, AProgramThatCannotStartIsAFault) {
  ProcessDriver d(options({"/nonexistent/driver"}));
  ASSERT_TRUE(d.start().ok());
  EXPECT_FALSE(d.healthy());
  EXPECT_TRUE(faults_with(d, "cannot start the driver process", 3000));
}

TEST(ProcessDriver, ReferenceDriverServesASocketForAnAlreadyRunningProcess) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  test::TempDir dir;
  const std::string path = dir.file("drv.sock");
  test::Process py;
  ASSERT_TRUE(py.start(
      {"/usr/bin/env", "python3", kReference, "--port", pty.slave_path(), "--listen", path}));
  struct stat st {};
  ASSERT_TRUE(eventually([&] { return ::stat(path.c_str(), &st) == 0; }, 10000));
  EXPECT_EQ(st.st_mode & 0777, 0600u);  // only rcand's user may pose as the hardware
  ProcessDriverOptions o = options({});
  o.file.socket = path;
  ProcessDriver d(o);
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy()) << d.health().fault;
  pty.drain();
  ASSERT_TRUE(d.apply(ActuatorCommand::make_drive(0.4, 0, 500)).ok());
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.400 0.400");
  py.stop(SIGTERM, 5000);
  EXPECT_TRUE(faults_with(d, "driver process", 3000));
  EXPECT_TRUE(faults_with(d, "cannot connect", 3000));  // nothing listens any more
}

// The other side of the contract: the reference driver stops the base by itself when rcand
// falls silent for the heartbeat timeout it announced (the test plays a hung rcand).
TEST(ProcessDriver, ReferenceDriverStopsTheBaseWhenRcandFallsSilent) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  test::TempDir dir;
  const std::string path = dir.file("drv.sock");
  test::Process py;
  ASSERT_TRUE(py.start(
      {"/usr/bin/env", "python3", kReference, "--port", pty.slave_path(), "--listen", path}));
  // The socket file appears at bind(), a moment before the driver listens: connect until it
  // is accepted.
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  int fd = -1;
  ASSERT_TRUE(eventually(
      [&] {
        if (fd >= 0) ::close(fd);
        fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
        return ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
      },
      10000));
  auto send_frame = [&](const std::string& f) {
    return ::send(fd, f.data(), f.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(f.size());
  };
  ASSERT_TRUE(send_frame(encode_describe(1, 50, 300)));
  pty.drain();
  ASSERT_TRUE(send_frame(encode_apply(2, ActuatorCommand::make_drive(0.2, 0, 10000))));
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.200 0.200");
  const auto t0 = std::chrono::steady_clock::now();  // silence from here on
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.000 0.000");
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_GE(waited, std::chrono::milliseconds(200));
  EXPECT_LT(waited, std::chrono::milliseconds(2000));
  ::close(fd);
}

// The test plays the driver process on driver.process.socket: it answers the handshake, keeps
// heartbeating, but stops reading, so that rcand's frames pile up in the socket and its queue.
TEST(ProcessDriver, AStopJumpsTheQueueAndDropsTheAppliesBeforeIt) {
  test::TempDir dir;
  const std::string path = dir.file("drv.sock");
  int srv = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  ASSERT_EQ(::bind(srv, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ASSERT_EQ(::listen(srv, 1), 0);
  auto send_frame = [](int fd, const std::string& json) {
    const std::string f = encode_frame(json);
    return ::send(fd, f.data(), f.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(f.size());
  };
  std::atomic<bool> reading{true}, quit{false};
  std::atomic<int> conn{-1};
  std::mutex mu;
  std::string received;  // everything read after `reading` went back to true
  std::thread peer([&] {
    const int c = ::accept(srv, nullptr, nullptr);
    conn = c;
    send_frame(c, R"({"type":"describe","protocol":1,"name":"peer"})");
    while (!quit) {
      send_frame(c, R"({"type":"heartbeat"})");
      if (reading) {
        char b[65536];
        const ssize_t n = ::recv(c, b, sizeof b, MSG_DONTWAIT);
        std::lock_guard<std::mutex> lock(mu);
        if (n > 0) received.append(b, static_cast<size_t>(n));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  ProcessDriverOptions o = options({});
  o.file.socket = path;
  ProcessDriver d(o);
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy());
  reading = false;
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  {
    std::lock_guard<std::mutex> lock(mu);
    received.clear();
  }
  int accepted = 0;
  Status last;
  for (int i = 0; i < 100000; ++i) {
    last = d.apply(ActuatorCommand::make_drive(0.1 + 1e-6 * i, 0, 100));
    if (!last.ok()) break;
    ++accepted;
  }
  ASSERT_FALSE(last.ok());  // the queue filled up: refused, never blocked
  EXPECT_NE(last.error().message.find("not reading"), std::string::npos) << last.error().message;
  d.stop();
  reading = true;
  ASSERT_TRUE(eventually(
      [&] {
        std::lock_guard<std::mutex> lock(mu);
        return received.find("\"stop\"") != std::string::npos;
      },
      5000));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  quit = true;
  peer.join();
  // Split what arrived into frames: applies, then the stop, and no apply after it.
  FrameDecoder dec;
  dec.feed(received.data(), received.size());
  int applies = 0, stops = 0, applies_after_stop = 0;
  while (true) {
    auto f = dec.next();
    ASSERT_TRUE(f.ok());
    if (!*f) break;
    auto v = json::parse(**f);
    ASSERT_TRUE(v.ok());
    const std::string type = v->get("type")->as_string();
    if (type == "apply") (stops ? applies_after_stop : applies)++;
    if (type == "stop") ++stops;
  }
  EXPECT_EQ(stops, 1);
  EXPECT_EQ(applies_after_stop, 0);
  // The frames still queued in rcand when the stop came (up to 32) were dropped unsent.
  EXPECT_LE(applies, accepted - 30) << accepted;
  ::close(conn);
  ::close(srv);
}

TEST(ProcessDriver, StopIsSafeFromManyThreadsDuringAppliesAndRestarts) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  ProcessDriver d(reference_on(pty));
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(d.healthy());
  std::atomic<bool> quit{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t)
    threads.emplace_back([&] {
      while (!quit) d.stop();
    });
  threads.emplace_back([&] {
    while (!quit) {
      (void)d.apply(ActuatorCommand::make_drive(0.2, 0, 50));
      (void)d.state();
      (void)d.health();
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  });
  threads.emplace_back([&] {  // the base reads what it is sent
    while (!quit) (void)pty.line(50);
  });
  for (uint64_t k = 0; k < 2; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const pid_t pid = d.child_pid();
    EXPECT_GT(pid, 0);
    if (pid <= 0) break;
    ::kill(pid, SIGKILL);
    const bool back = eventually(
        [&] { return d.restarts() == k + 1 && d.healthy() && d.child_pid() > 0; }, 10000);
    EXPECT_TRUE(back) << d.health().fault;
    if (!back) break;
  }
  quit = true;
  for (auto& t : threads) t.join();
  d.stop();
  EXPECT_GE(d.restarts(), 2u);
}

TEST(ProcessDriver, DestroyingTheDriverStopsTheBaseAndEndsTheProcess) {
  PtyBase pty;
  ASSERT_TRUE(pty.ok());
  pid_t pid = -1;
  {
    ProcessDriver d(reference_on(pty));
    ASSERT_TRUE(d.start().ok());
    ASSERT_TRUE(d.healthy());
    pid = d.child_pid();
    ASSERT_TRUE(d.apply(ActuatorCommand::make_drive(0.3, 0, 10000)).ok());
    EXPECT_EQ(pty.line_starting("V 0.3", 3000).value_or("none"), "V 0.300 0.300");
  }
  EXPECT_EQ(pty.line_starting("V ", 3000).value_or("none"), "V 0.000 0.000");
  EXPECT_NE(::kill(pid, 0), 0);  // reaped
}

}  // namespace
}  // namespace rcan::drivers
