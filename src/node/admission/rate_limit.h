// RateLimiter — per-principal command budgets (docs/PROTOCOL.md §Roles): a token bucket per
// principal holding `per_minute` tokens, refilled continuously on the monotonic clock.
// SAFETY messages never reach it. Idle buckets are dropped so memory stays bounded. The node
// also keeps one keyed by source address, charged by failed token verifications
// (NodeServices::authenticate).
#pragma once

#include <cstdint>
#include <string>
#include <unordered_map>

#include "base/thread_annotations.h"

namespace rcan::node {

class RateLimiter {
 public:
  explicit RateLimiter(size_t max_principals = 100'000) : max_principals_(max_principals) {}

  struct Decision {
    bool allowed = true;
    int64_t retry_after_ms = 0;  // when refused: until one token is back
  };
  // `per_minute` 0 = unlimited.
  Decision take(const std::string& principal, uint32_t per_minute, int64_t now_mono_ms)
      EXCLUDES(mu_);
  // What take() would decide now, without taking anything (a key never seen is allowed).
  Decision peek(const std::string& principal, uint32_t per_minute, int64_t now_mono_ms) const
      EXCLUDES(mu_);
  size_t tracked() const EXCLUDES(mu_);

 private:
  struct Bucket {
    double tokens;
    int64_t last_ms;
    uint32_t per_minute;
  };
  void sweep(int64_t now_mono_ms) REQUIRES(mu_);

  size_t max_principals_;
  mutable Mutex mu_;
  std::unordered_map<std::string, Bucket> buckets_ GUARDED_BY(mu_);
  int64_t last_sweep_ms_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node
