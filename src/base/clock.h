// Clock — the node's only source of time, injectable for tests.
//
// wall_ms(): Unix milliseconds (message timestamps, audit records, token expiry).
// mono_ms(): a monotonic millisecond counter (TTLs, deadlines, rate windows, heartbeats);
// it never jumps when the wall clock is stepped.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>

namespace rcan {

// The steady clock in microseconds: the clock of received_mono_us and answered_mono_us and of
// the node's stage timers, which subtract them from one another across transport and node.
inline int64_t steady_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// The steady clock in nanoseconds (latency measurements).
inline int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

class Clock {
 public:
  virtual ~Clock() = default;
  virtual int64_t wall_ms() const = 0;
  virtual int64_t mono_ms() const = 0;
  // The process-wide system clock.
  static Clock& system();
};

// A clock tests move by hand. Thread-safe.
class ManualClock : public Clock {
 public:
  explicit ManualClock(int64_t wall_ms = 1'750'000'000'000, int64_t mono_ms = 1'000'000)
      : wall_(wall_ms), mono_(mono_ms) {}
  int64_t wall_ms() const override { return wall_.load(); }
  int64_t mono_ms() const override { return mono_.load(); }
  // Advances both clocks.
  void advance(int64_t ms) {
    wall_ += ms;
    mono_ += ms;
  }
  // Steps only the wall clock (an NTP step); the monotonic clock is unaffected.
  void step_wall(int64_t ms) { wall_ += ms; }

 private:
  std::atomic<int64_t> wall_;
  std::atomic<int64_t> mono_;
};

}  // namespace rcan
