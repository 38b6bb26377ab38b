// ReplayGuard — the replay window of docs/PROTOCOL.md §Replay.
//
// A message is fresh when its timestamp is within `window_ms` of the node's wall clock
// (10 s at most for SAFETY messages) and its id has not been seen inside the window.
// Ids are remembered until their timestamp leaves the window. The memory is bounded: when
// it is full of live ids the oldest is evicted and the window's floor rises to its
// timestamp, so an evicted id can never be replayed (anything at or below the floor is
// stale). Fresh duplicate SAFETY stops are let through (an ESTOP is never refused for
// anything but authentication) and reported as duplicates.
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <unordered_set>

#include "rcan/result.h"

namespace rcan::node {

struct ReplayOptions {
  int64_t window_ms = 30'000;
  int64_t safety_window_ms = 10'000;
  int64_t future_tolerance_ms = 5'000;  // clock drift allowed into the future (within window)
  size_t capacity = 10'000;
};

class ReplayGuard {
 public:
  explicit ReplayGuard(ReplayOptions opts = {}) : opts_(opts) {}

  struct Verdict {
    bool duplicate_safety = false;  // a fresh SAFETY message seen before, let through
  };
  // Checks and records. Errors: kMessageStale (outside the window, or at/below the floor),
  // kReplayDetected (seen before).
  Result<Verdict> check(const std::string& message_id, int64_t timestamp_ms, bool safety,
                        int64_t now_wall_ms);

  size_t size() const;
  uint64_t evictions() const;

 private:
  struct Entry {
    int64_t ts;
    std::string id;
  };
  void expire(int64_t now_wall_ms);

  ReplayOptions opts_;
  mutable std::mutex mu_;
  std::deque<Entry> order_;  // by insertion (timestamps roughly increasing)
  std::unordered_set<std::string> ids_;
  int64_t floor_ms_ = INT64_MIN;
  uint64_t evictions_ = 0;
};

}  // namespace rcan::node
