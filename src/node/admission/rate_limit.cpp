#include "node/admission/rate_limit.h"

#include <algorithm>
#include <cmath>

namespace rcan::node {

void RateLimiter::sweep(int64_t now_mono_ms) {
  // A bucket idle for a minute is full again: forgetting it changes nothing.
  for (auto it = buckets_.begin(); it != buckets_.end();) {
    if (now_mono_ms - it->second.last_ms > 60'000)
      it = buckets_.erase(it);
    else
      ++it;
  }
  last_sweep_ms_ = now_mono_ms;
}

RateLimiter::Decision RateLimiter::take(const std::string& principal, uint32_t per_minute,
                                        int64_t now_mono_ms) {
  Decision d;
  if (per_minute == 0) return d;
  MutexLock lock(mu_);
  if (now_mono_ms - last_sweep_ms_ > 10'000 || buckets_.size() >= max_principals_)
    sweep(now_mono_ms);
  auto it = buckets_.find(principal);
  if (it == buckets_.end()) {
    if (buckets_.size() >= max_principals_) {
      // Under a flood of distinct principals, refuse new ones rather than grow without bound.
      d.allowed = false;
      d.retry_after_ms = 1000;
      return d;
    }
    it = buckets_
             .emplace(principal, Bucket{static_cast<double>(per_minute), now_mono_ms, per_minute})
             .first;
  }
  Bucket& b = it->second;
  double rate_per_ms = per_minute / 60'000.0;
  if (b.per_minute != per_minute) {
    b.per_minute = per_minute;
    b.tokens = std::min(b.tokens, static_cast<double>(per_minute));
  }
  b.tokens = std::min(static_cast<double>(per_minute),
                      b.tokens + static_cast<double>(now_mono_ms - b.last_ms) * rate_per_ms);
  b.last_ms = now_mono_ms;
  if (b.tokens >= 1.0) {
    b.tokens -= 1.0;
    return d;
  }
  d.allowed = false;
  d.retry_after_ms = static_cast<int64_t>(std::ceil((1.0 - b.tokens) / rate_per_ms));
  return d;
}

RateLimiter::Decision RateLimiter::peek(const std::string& principal, uint32_t per_minute,
                                        int64_t now_mono_ms) const {
  Decision d;
  if (per_minute == 0) return d;
  MutexLock lock(mu_);
  auto it = buckets_.find(principal);
  if (it == buckets_.end()) return d;
  const Bucket& b = it->second;
  double rate_per_ms = per_minute / 60'000.0;
  double tokens = std::min(static_cast<double>(per_minute),
                           b.tokens + static_cast<double>(now_mono_ms - b.last_ms) * rate_per_ms);
  if (tokens >= 1.0) return d;
  d.allowed = false;
  d.retry_after_ms = static_cast<int64_t>(std::ceil((1.0 - tokens) / rate_per_ms));
  return d;
}

size_t RateLimiter::tracked() const {
  MutexLock lock(mu_);
  return buckets_.size();
}

}  // namespace rcan::node
