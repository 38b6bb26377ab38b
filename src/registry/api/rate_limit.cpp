#include "registry/api/rate_limit.h"

#include <algorithm>
#include <cmath>

namespace rcan::registry::api {

int64_t RateLimiter::take(std::string_view key, int64_t now_us) {
  if (c_.rate_per_s <= 0) return 0;
  MutexLock lock(mu_);
  auto refill = [&](Bucket& b) {
    double dt = static_cast<double>(std::max<int64_t>(0, now_us - b.at_us)) / 1e6;
    b.tokens = std::min(c_.burst, b.tokens + dt * c_.rate_per_s);
    b.at_us = now_us;
  };
  auto it = buckets_.find(std::string(key));
  if (it == buckets_.end()) {
    if (buckets_.size() >= max_keys_) {
      for (auto i = buckets_.begin(); i != buckets_.end();) {
        refill(i->second);
        i = i->second.tokens >= c_.burst ? buckets_.erase(i) : std::next(i);
      }
      if (buckets_.size() >= max_keys_) buckets_.clear();
    }
    it = buckets_.emplace(std::string(key), Bucket{c_.burst, now_us}).first;
  }
  Bucket& b = it->second;
  refill(b);
  if (b.tokens >= 1.0) {
    b.tokens -= 1.0;
    return 0;
  }
  double wait = (1.0 - b.tokens) / c_.rate_per_s;
  return std::max<int64_t>(1, static_cast<int64_t>(std::ceil(wait)));
}

size_t RateLimiter::size() {
  MutexLock lock(mu_);
  return buckets_.size();
}

}  // namespace rcan::registry::api
