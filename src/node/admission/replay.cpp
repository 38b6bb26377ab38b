#include "node/admission/replay.h"

#include <algorithm>

namespace rcan::node {

void ReplayGuard::expire(int64_t now_wall_ms) {
  // Entries leave in timestamp order once their timestamp is out of the window (whatever
  // order they arrived in, and however the clock has stepped since).
  const int64_t oldest = now_wall_ms - opts_.window_ms;
  while (!by_ts_.empty() && by_ts_.begin()->first < oldest) {
    ids_.erase(by_ts_.begin()->second);
    by_ts_.erase(by_ts_.begin());
  }
  // A refused range whose newest timestamp is stale anyway is no longer needed.
  std::erase_if(refused_, [&](const auto& r) { return r.second < oldest; });
}

// Evictions take the oldest timestamp, so without clock steps they only ever extend one range
// upwards. A timestamp far from every range (the clock stepped) starts a range of its own, so
// that messages stamped with the new time are not refused for evictions from before the step.
void ReplayGuard::note_evicted(int64_t ts) {
  ++evictions_;
  for (auto& r : refused_) {
    if (ts >= r.first - opts_.window_ms && ts <= r.second + opts_.window_ms) {
      r.first = std::min(r.first, ts);
      r.second = std::max(r.second, ts);
      return;
    }
  }
  refused_.emplace_back(ts, ts);
  if (refused_.size() > 16) {  // bounded: merge the two oldest ranges (refuses more, never less)
    std::sort(refused_.begin(), refused_.end());
    refused_[1].first = refused_[0].first;
    refused_[1].second = std::max(refused_[0].second, refused_[1].second);
    refused_.erase(refused_.begin());
  }
}

bool ReplayGuard::refused(int64_t ts) const {
  for (const auto& r : refused_)
    if (ts >= r.first && ts <= r.second) return true;
  return false;
}

Result<ReplayGuard::Verdict> ReplayGuard::check(const std::string& message_id, int64_t timestamp_ms,
                                                bool safety, int64_t now_wall_ms) {
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
  MutexLock lock(mu_);
  expire(now_wall_ms);
  if (!safety && refused(timestamp_ms)) {
    return Error(ErrorCode::kMessageStale,
                 "timestamp_ms is older than the replay memory under this load; resend with a "
                 "fresh timestamp",
                 "timestamp_ms");
  }
  Verdict v;
  if (ids_.count(message_id)) {
    if (safety) {
      v.duplicate_safety = true;
      return v;
    }
    return Error(ErrorCode::kReplayDetected, "message_id was already used", "message_id");
  }
  if (ids_.size() >= opts_.capacity && !by_ts_.empty()) {
    auto oldest = by_ts_.begin();
    note_evicted(oldest->first);
    ids_.erase(oldest->second);
    by_ts_.erase(oldest);
  }
  ids_.insert(message_id);
  by_ts_.emplace(timestamp_ms, message_id);
  return v;
}

size_t ReplayGuard::size() const {
  MutexLock lock(mu_);
  return ids_.size();
}

uint64_t ReplayGuard::evictions() const {
  MutexLock lock(mu_);
  return evictions_;
}

}  // namespace rcan::node
