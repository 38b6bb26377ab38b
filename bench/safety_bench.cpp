// SafetyCore benchmark (plain main; needs rcan_node at link time).
//
// 1. ESTOP latency under load: N threads (0, 4, 16, 64) call dispatch() in a loop on a
//    SafetyCore over the simulated robot (tick thread running at 50 Hz, workspace prediction
//    on). Each trial resumes, lets the hammering run ~2 ms, then calls estop() and measures
//      * call → Driver::stop() entered   (timestamp taken inside the driver)
//      * call → estop() returned         (includes the fence that waits out an in-flight apply)
//    and reports p50 / p99 / max over the trials.
// 2. dispatch() throughput with N threads (unlatched, all accepted).
// 3. One COMMAND through SafetyActuation, single-threaded: prepare() (translate, check; on the
//    I/O thread before the audit record) and apply() (dispatch; on the audit writer once the
//    record is durable), for load_bench's move with its parameters under "params".
//
// Usage: safety_bench [trials=300] [throughput_ms=1000]
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <thread>
#include <vector>

#include "base/clock.h"
#include "node/safety/actuation_safety.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"

using namespace rcan::node;
using rcan::Clock;

namespace {

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// The simulated robot, plus a timestamp of the first stop() after arm().
class TimedSim final : public Driver {
 public:
  DriverInfo describe() const override { return sim_.describe(); }
  rcan::Status apply(const ActuatorCommand& c) override { return sim_.apply(c); }
  void stop() noexcept override {
    int64_t expected = 0;
    first_stop_ns_.compare_exchange_strong(expected, now_ns(), std::memory_order_acq_rel);
    sim_.stop();
  }
  void step(int64_t dt) override { sim_.step(dt); }
  RobotState state() const override { return sim_.state(); }
  void arm() { first_stop_ns_.store(0, std::memory_order_release); }
  int64_t first_stop_ns() const { return first_stop_ns_.load(std::memory_order_acquire); }

 private:
  SimRobot sim_;
  std::atomic<int64_t> first_stop_ns_{0};
};

struct Pct {
  double p50, p99, max;
};
Pct pct(std::vector<int64_t> v) {
  if (v.empty()) return {0, 0, 0};
  std::sort(v.begin(), v.end());
  auto at = [&](double q) {
    return static_cast<double>(v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))]);
  };
  return {at(0.50) / 1000.0, at(0.99) / 1000.0, static_cast<double>(v.back()) / 1000.0};
}

ActuatorCommand command_for(int thread, uint64_t k) {
  if ((thread + k) % 3 == 0) {
    const double a = (k % 2) ? 0.3 : -0.3;
    return ActuatorCommand::make_arm({a, -a, a, 0.1, -0.1, 0.2});
  }
  const double v = (k % 2) ? 0.2 : -0.2;
  return ActuatorCommand::make_drive(v, 0.1, 500);
}

void run_latency(int threads, int trials) {
  auto drv = std::make_unique<TimedSim>();
  TimedSim* timed = drv.get();
  SafetyConfig cfg;
  SafetyCore core(std::move(drv), cfg, Clock::system());
  core.start();
  std::atomic<bool> go{true};
  std::atomic<uint64_t> accepted{0}, refused{0};
  std::vector<std::thread> ts;
  for (int i = 0; i < threads; ++i) {
    ts.emplace_back([&, i] {
      uint64_t k = 0;
      while (go.load(std::memory_order_relaxed)) {
        auto r = core.dispatch(command_for(i, k++));
        (r.ok() ? accepted : refused).fetch_add(1, std::memory_order_relaxed);
      }
    });
  }
  std::vector<int64_t> to_stop, to_return;
  int unfenced = 0;
  for (int t = 0; t < trials; ++t) {
    if (!core.resume(3, "bench").ok()) std::abort();
    timed->arm();
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    const int64_t t0 = now_ns();
    const EstopResult er = core.estop("bench", "trial");
    const int64_t t1 = now_ns();
    if (!er.fenced) ++unfenced;
    const int64_t s = timed->first_stop_ns();
    to_stop.push_back(s >= t0 ? s - t0 : 0);
    to_return.push_back(t1 - t0);
  }
  go.store(false);
  for (auto& th : ts) th.join();
  core.stop();
  const Pct a = pct(to_stop), b = pct(to_return);
  const LatencyStats internal = core.estop_latency();
  std::printf(
      "estop  threads=%-3d trials=%d  call->driver.stop(): p50 %7.2f us  p99 %8.2f us  max %8.2f "
      "us | "
      "call->return: p50 %7.2f us  p99 %8.2f us  max %8.2f us | core-recorded p99 %.2f us | "
      "fence timeouts %d | dispatches ok=%llu refused=%llu\n",
      threads, trials, a.p50, a.p99, a.max, b.p50, b.p99, b.max, internal.p99_ns / 1000.0, unfenced,
      static_cast<unsigned long long>(accepted.load()),
      static_cast<unsigned long long>(refused.load()));
}

void run_throughput(int threads, int ms) {
  auto drv = std::make_unique<SimRobot>();
  SafetyCore core(std::move(drv), SafetyConfig{}, Clock::system());
  core.start();
  std::atomic<bool> go{true};
  std::atomic<uint64_t> ok{0}, bad{0};
  std::vector<std::thread> ts;
  const int n = std::max(1, threads);
  const int64_t t0 = now_ns();
  for (int i = 0; i < n; ++i) {
    ts.emplace_back([&, i] {
      uint64_t k = 0, mine = 0, fail = 0;
      while (go.load(std::memory_order_relaxed)) {
        auto r = core.dispatch(command_for(i, k++));
        if (r.ok()) {
          ++mine;
        } else {
          ++fail;
        }
      }
      ok.fetch_add(mine);
      bad.fetch_add(fail);
    });
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(ms));
  go.store(false);
  for (auto& th : ts) th.join();
  const double secs = static_cast<double>(now_ns() - t0) / 1e9;
  core.stop();
  std::printf(
      "dispatch threads=%-3d  %10.0f dispatches/s  (%.2f us each per thread; refused %llu)\n", n,
      static_cast<double>(ok.load()) / secs,
      1e6 * secs * n / std::max<double>(1, static_cast<double>(ok.load())),
      static_cast<unsigned long long>(bad.load()));
}

}  // namespace

void run_actuation(int ms) {
  auto drv = std::make_unique<TimedSim>();
  SafetyCore core(std::move(drv), SafetyConfig{}, Clock::system());
  SafetyActuation act(core, "bench");
  rcan::Message m;
  m.type = rcan::MessageType::kCommand;
  m.payload = rcan::json::Object{
      {"action", "move"},
      {"params", rcan::json::Object{{"linear", 0.2}, {"angular", 0.1}, {"duration_ms", 200}}}};
  const rcan::ActionSpec& move = *rcan::find_action("move");
  int64_t prep_ns = 0, apply_ns = 0, n = 0;
  const int64_t end = now_ns() + int64_t{ms} * 1'000'000;
  while (now_ns() < end) {
    for (int i = 0; i < 256; ++i) {
      const int64_t t0 = now_ns();
      auto pc = act.prepare(m, move, 0, "", std::nullopt);
      const int64_t t1 = now_ns();
      if (!pc.ok()) {
        std::fprintf(stderr, "prepare failed: %s\n", pc.error().message.c_str());
        std::exit(1);
      }
      auto r = act.apply(*pc);
      const int64_t t2 = now_ns();
      if (!r.ok()) {
        std::fprintf(stderr, "apply failed: %s\n", r.error().message.c_str());
        std::exit(1);
      }
      prep_ns += t1 - t0;
      apply_ns += t2 - t1;
      ++n;
    }
  }
  std::printf("SafetyActuation move: prepare %.2f us, apply %.2f us (mean of %lld)\n",
              static_cast<double>(prep_ns) / 1e3 / static_cast<double>(n),
              static_cast<double>(apply_ns) / 1e3 / static_cast<double>(n),
              static_cast<long long>(n));
}

int main(int argc, char** argv) {
  const int trials = argc > 1 ? std::atoi(argv[1]) : 300;
  const int ms = argc > 2 ? std::atoi(argv[2]) : 1000;
  std::printf("hardware threads: %u\n", std::thread::hardware_concurrency());
  for (int n : {0, 4, 16, 64}) run_latency(n, trials);
  for (int n : {1, 4, 16, 64}) run_throughput(n, ms);
  run_actuation(ms);
  return 0;
}
