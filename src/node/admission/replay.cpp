#include "node/admission/replay.h"

#include <algorithm>
#include <limits>
#include <optional>

namespace rcan::node {
namespace {

size_t share_of(const ReplayOptions& o) {
  size_t cap = std::max<size_t>(o.capacity, 1);
  size_t share = o.principal_share != 0 ? o.principal_share : cap / 16;
  return std::clamp<size_t>(share, 1, cap);
}

}  // namespace

ReplayGuard::ReplayGuard(ReplayOptions opts) : opts_(opts), share_(share_of(opts)) {}

std::optional<Error> ReplayGuard::outside_window(int64_t timestamp_ms, bool safety,
                                                 int64_t now_wall_ms) const {
  int64_t window = safety ? std::min(opts_.safety_window_ms, opts_.window_ms) : opts_.window_ms;
  if (timestamp_ms < now_wall_ms - window) {
    return Error(ErrorCode::kMessageStale,
                 "timestamp_ms is " + std::to_string((now_wall_ms - timestamp_ms) / 1000) +
                     " s old; the replay window is " + std::to_string(window / 1000) + " s",
                 "timestamp_ms");
  }
  if (timestamp_ms > now_wall_ms + opts_.future_tolerance_ms) {
    return Error(ErrorCode::kMessageStale,
                 "timestamp_ms is " + std::to_string((timestamp_ms - now_wall_ms) / 1000) +
                     " s in the future",
                 "timestamp_ms");
  }
  return std::nullopt;
}

ReplayGuard::Book* ReplayGuard::find_locked(const std::string& principal) {
  auto it = books_.find(principal);
  return it == books_.end() ? nullptr : &it->second;
}

// Books leave the index in the order of their earliest timestamp; each one due is expired and
// put back under its new earliest timestamp (or dropped when nothing is left in it).
void ReplayGuard::expire_locked(int64_t now_wall_ms) {
  const int64_t oldest = now_wall_ms - opts_.window_ms;
  while (!due_.empty() && due_.begin()->first < oldest) {
    Book* b = due_.begin()->second;
    due_.erase(due_.begin());
    b->indexed = false;
    expire_book_locked(*b, oldest);
    if (b->ids.empty() && b->refused.empty()) {
      books_.erase(books_.find(*b->key));
    } else {
      reindex_locked(*b);
    }
  }
}

// Ids leave in timestamp order once their timestamp is out of the window (whatever order they
// arrived in, and however the clock has stepped since).
void ReplayGuard::expire_book_locked(Book& b, int64_t oldest) {
  while (!b.by_ts.empty() && b.by_ts.begin()->first < oldest) {
    const std::string* id = b.by_ts.begin()->second;
    b.by_ts.erase(b.by_ts.begin());
    b.ids.erase(b.ids.find(*id));
    --total_;
  }
  // A refused range whose newest timestamp is stale anyway is no longer needed.
  std::erase_if(b.refused, [&](const auto& r) { return r.second < oldest; });
}

// The principal's own oldest id makes room. Evictions take the oldest timestamp, so without
// clock steps they only ever extend one range upwards. A timestamp far from every range (the
// clock stepped) starts a range of its own, so that messages stamped with the new time are not
// refused for evictions from before the step.
void ReplayGuard::evict_oldest_locked(Book& b) {
  const int64_t ts = b.by_ts.begin()->first;
  const std::string* id = b.by_ts.begin()->second;
  b.by_ts.erase(b.by_ts.begin());
  b.ids.erase(b.ids.find(*id));
  --total_;
  ++evictions_;
  for (auto& r : b.refused) {
    if (ts >= r.first - opts_.window_ms && ts <= r.second + opts_.window_ms) {
      r.first = std::min(r.first, ts);
      r.second = std::max(r.second, ts);
      return;
    }
  }
  b.refused.emplace_back(ts, ts);
  if (b.refused.size() > 16) {  // bounded: merge the two oldest ranges (refuses more, never less)
    std::sort(b.refused.begin(), b.refused.end());
    b.refused[1].first = b.refused[0].first;
    b.refused[1].second = std::max(b.refused[0].second, b.refused[1].second);
    b.refused.erase(b.refused.begin());
  }
}

void ReplayGuard::reindex_locked(Book& b) {
  int64_t due = std::numeric_limits<int64_t>::max();
  if (!b.by_ts.empty()) due = b.by_ts.begin()->first;
  for (const auto& r : b.refused) due = std::min(due, r.second);
  if (b.indexed && b.due == due) return;
  if (b.indexed) due_.erase({b.due, &b});
  b.due = due;
  b.indexed = true;
  due_.emplace(due, &b);
}

bool ReplayGuard::refused_locked(const Book& b, int64_t ts) const {
  for (const auto& r : b.refused)
    if (ts >= r.first && ts <= r.second) return true;
  return false;
}

Result<ReplayGuard::Verdict> ReplayGuard::judge_locked(Book* b, const std::string& message_id,
                                                       int64_t timestamp_ms, bool safety) {
  Verdict v;
  if (b == nullptr) return v;
  if (!safety && refused_locked(*b, timestamp_ms)) {
    return Error(ErrorCode::kMessageStale,
                 "timestamp_ms is older than this principal's replay memory reaches under its "
                 "own load; resend with a fresh timestamp",
                 "timestamp_ms");
  }
  if (b->ids.count(message_id)) {
    if (safety) {
      v.duplicate_safety = true;
      return v;
    }
    return Error(ErrorCode::kReplayDetected, "message_id was already used", "message_id");
  }
  return v;
}

Result<ReplayGuard::Verdict> ReplayGuard::peek(const std::string& principal,
                                               const std::string& message_id, int64_t timestamp_ms,
                                               bool safety, int64_t now_wall_ms) {
  if (auto e = outside_window(timestamp_ms, safety, now_wall_ms)) return *e;
  MutexLock lock(mu_);
  expire_locked(now_wall_ms);
  return judge_locked(find_locked(principal), message_id, timestamp_ms, safety);
}

Result<ReplayGuard::Verdict> ReplayGuard::check(const std::string& principal,
                                                const std::string& message_id, int64_t timestamp_ms,
                                                bool safety, int64_t now_wall_ms) {
  if (auto e = outside_window(timestamp_ms, safety, now_wall_ms)) return *e;
  MutexLock lock(mu_);
  expire_locked(now_wall_ms);
  Book* b = find_locked(principal);
  auto v = judge_locked(b, message_id, timestamp_ms, safety);
  if (!v.ok() || v->duplicate_safety) return v;
  if (b != nullptr && b->ids.size() >= share_) {
    evict_oldest_locked(*b);  // the principal's own volume: its own oldest id makes room
  } else if (total_ >= opts_.capacity) {
    if (safety) {  // a stop is never refused for memory; a duplicate of it would pass anyway
      v->unremembered = true;
      return v;
    }
    ++full_refusals_;
    return Error(ErrorCode::kRateLimited,
                 "the replay memory is full (" + std::to_string(opts_.capacity) +
                     " message ids of the last " + std::to_string(opts_.window_ms / 1000) +
                     " s); this principal holds " + std::to_string(b ? b->ids.size() : 0) +
                     " of its share of " + std::to_string(share_) + "; retry later",
                 "message_id", "replay_memory_full");
  }
  if (b == nullptr) {
    auto it = books_.try_emplace(principal).first;
    b = &it->second;
    b->key = &it->first;
  }
  auto id = b->ids.emplace(message_id, timestamp_ms).first;
  b->by_ts.emplace(timestamp_ms, &id->first);
  ++total_;
  reindex_locked(*b);
  return v;
}

int64_t ReplayGuard::retry_after_ms(int64_t now_wall_ms) const {
  MutexLock lock(mu_);
  if (due_.empty()) return 1000;
  return std::max<int64_t>(1, due_.begin()->first + opts_.window_ms - now_wall_ms + 1);
}

size_t ReplayGuard::size() const {
  MutexLock lock(mu_);
  return total_;
}

size_t ReplayGuard::size_of(const std::string& principal) const {
  MutexLock lock(mu_);
  auto it = books_.find(principal);
  return it == books_.end() ? 0 : it->second.ids.size();
}

size_t ReplayGuard::principals() const {
  MutexLock lock(mu_);
  return books_.size();
}

uint64_t ReplayGuard::evictions() const {
  MutexLock lock(mu_);
  return evictions_;
}

uint64_t ReplayGuard::full_refusals() const {
  MutexLock lock(mu_);
  return full_refusals_;
}

}  // namespace rcan::node
