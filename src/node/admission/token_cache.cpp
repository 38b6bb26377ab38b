#include "node/admission/token_cache.h"

namespace rcan::node {

std::optional<Principal> TokenCache::find(std::string_view token, int64_t now_s) {
  if (capacity_ == 0) return std::nullopt;
  MutexLock lock(mu_);
  auto it = map_.find(token);
  if (it == map_.end()) return std::nullopt;
  if (now_s < it->second.valid_from_s || now_s >= it->second.valid_until_s) {
    map_.erase(it);  // outside its window: the caller verifies (and refuses) afresh
    return std::nullopt;
  }
  ++hits_;
  return it->second.principal;
}

void TokenCache::insert(std::string_view token, const Principal& p, int64_t valid_from_s,
                        int64_t valid_until_s) {
  if (capacity_ == 0 || valid_until_s <= valid_from_s) return;
  MutexLock lock(mu_);
  if (map_.size() >= capacity_ && map_.find(token) == map_.end()) map_.erase(map_.begin());
  map_.insert_or_assign(std::string(token), Entry{p, valid_from_s, valid_until_s});
}

size_t TokenCache::size() const {
  MutexLock lock(mu_);
  return map_.size();
}

void TokenCache::clear() {
  MutexLock lock(mu_);
  map_.clear();
}

}  // namespace rcan::node
