#include "node/replay.h"

#include <algorithm>

namespace rcan::node {

void ReplayGuard::expire(int64_t now_wall_ms) {
  // Entries leave in insertion order once their timestamp is out of the window. An entry
  // with a far-future timestamp keeps the ones behind it a little longer: harmless.
  while (!order_.empty() && order_.front().ts < now_wall_ms - opts_.window_ms) {
    ids_.erase(order_.front().id);
    order_.pop_front();
  }
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
  std::lock_guard<std::mutex> lock(mu_);
  expire(now_wall_ms);
  if (timestamp_ms <= floor_ms_ && !safety) {
    return Error(ErrorCode::kMessageStale,
                 "timestamp_ms is older than the replay memory under this load; resend with a fresh timestamp",
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
  if (ids_.size() >= opts_.capacity && !order_.empty()) {
    floor_ms_ = std::max(floor_ms_, order_.front().ts);
    ids_.erase(order_.front().id);
    order_.pop_front();
    ++evictions_;
  }
  ids_.insert(message_id);
  order_.push_back(Entry{timestamp_ms, message_id});
  return v;
}

size_t ReplayGuard::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return ids_.size();
}

uint64_t ReplayGuard::evictions() const {
  std::lock_guard<std::mutex> lock(mu_);
  return evictions_;
}

}  // namespace rcan::node
