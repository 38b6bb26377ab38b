// Token buckets keyed by a string (an API key id, a client address), for the registry's rate
// limits (docs/REGISTRY.md §Rate limits). Thread-safe; memory is bounded: when the table reaches
// max_keys, buckets that have refilled completely (idle clients) are dropped, and if that is not
// enough (a flood from that many distinct keys) the whole table is: every key starts full again.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <unordered_map>

#include "base/thread_annotations.h"

namespace rcan::registry::api {

struct BucketConfig {
  double rate_per_s = 10;  // refill; 0 = unlimited
  double burst = 20;       // capacity
};

class RateLimiter {
 public:
  explicit RateLimiter(BucketConfig c, size_t max_keys = 100000) : c_(c), max_keys_(max_keys) {}
  // Takes one token for `key` at `now_us` (a steady clock). 0: allowed; otherwise the seconds
  // to wait before a token is there (for Retry-After, at least 1).
  int64_t take(std::string_view key, int64_t now_us) EXCLUDES(mu_);
  size_t size() EXCLUDES(mu_);

 private:
  struct Bucket {
    double tokens = 0;
    int64_t at_us = 0;
  };
  BucketConfig c_;
  size_t max_keys_;
  Mutex mu_;
  std::unordered_map<std::string, Bucket> buckets_ GUARDED_BY(mu_);
};

}  // namespace rcan::registry::api
