// ReplayGuard — the replay window of docs/PROTOCOL.md §Replay.
//
// A message is fresh when its timestamp is within `window_ms` of the node's wall clock
// (10 s at most for SAFETY messages) and its id has not been seen inside the window.
// Ids are remembered until their timestamp leaves the window. The memory is bounded: when
// it is full of live ids the one with the oldest timestamp is evicted and its timestamp joins
// a refused range, so an evicted id can never be replayed (a non-safety message whose
// timestamp lies in a refused range is stale). Fresh duplicate SAFETY stops are let through
// (an ESTOP is never refused for anything but authentication) and reported as duplicates.
//
// Wall-clock steps (docs/NODE.md §Faults): ids are kept and expired by their own timestamps
// in timestamp order, never by arrival order, and the refused ranges cover only the
// timestamps that were evicted. After the node's clock steps back, ids from before the step
// stay remembered until the clock has caught up with them (they could become fresh again),
// and messages stamped with the new time are not refused because of evictions that happened
// before the step; after a step forward, everything older than the window is stale anyway.
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include "base/thread_annotations.h"
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
                        int64_t now_wall_ms) EXCLUDES(mu_);

  size_t size() const EXCLUDES(mu_);
  uint64_t evictions() const EXCLUDES(mu_);

 private:
  void expire(int64_t now_wall_ms) REQUIRES(mu_);
  void note_evicted(int64_t ts) REQUIRES(mu_);
  bool refused(int64_t ts) const REQUIRES(mu_);

  ReplayOptions opts_;
  mutable Mutex mu_;
  // (timestamp, id), oldest first
  std::set<std::pair<int64_t, std::string>> by_ts_ GUARDED_BY(mu_);
  std::unordered_set<std::string> ids_ GUARDED_BY(mu_);
  // [lo, hi] timestamp ranges of evicted ids
  std::vector<std::pair<int64_t, int64_t>> refused_ GUARDED_BY(mu_);
  uint64_t evictions_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node
