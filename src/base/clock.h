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

// Every read of the process's clocks goes through here or through an injected Clock (below),
// so that one place says which clock a duration or a timestamp comes from. Header-only: the
// library and the CLI use these free functions without linking rcan_base.

// The steady clock: deadlines, condition-variable waits and intervals; it never jumps when the
// wall clock is stepped.
inline std::chrono::steady_clock::time_point steady_now() {
  return std::chrono::steady_clock::now();
}
// The wall clock: timestamps other parties read (messages, tokens, records, gRPC deadlines).
inline std::chrono::system_clock::time_point wall_now() { return std::chrono::system_clock::now(); }

template <class Unit, class TimePoint>
int64_t count_since_epoch(TimePoint t) {
  return std::chrono::duration_cast<Unit>(t.time_since_epoch()).count();
}

// The steady clock in milliseconds (a monotonic counter with no meaning across processes).
inline int64_t steady_ms() { return count_since_epoch<std::chrono::milliseconds>(steady_now()); }
// The steady clock in microseconds: the clock of received_mono_us and answered_mono_us and of
// the node's stage timers, which subtract them from one another across transport and node.
inline int64_t steady_us() { return count_since_epoch<std::chrono::microseconds>(steady_now()); }
// The steady clock in nanoseconds (latency measurements).
inline int64_t steady_ns() { return count_since_epoch<std::chrono::nanoseconds>(steady_now()); }

// Unix time: seconds (JWT iat/exp), milliseconds (message and record timestamps), microseconds.
inline int64_t unix_seconds() { return count_since_epoch<std::chrono::seconds>(wall_now()); }
inline int64_t unix_ms() { return count_since_epoch<std::chrono::milliseconds>(wall_now()); }
inline int64_t unix_us() { return count_since_epoch<std::chrono::microseconds>(wall_now()); }

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
