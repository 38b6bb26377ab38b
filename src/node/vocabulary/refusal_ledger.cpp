// The refusal ledger (refusal_ledger.h).
#include "node/vocabulary/refusal_ledger.h"

namespace rcan::node {

std::string RefusalLedger::source_of(const std::string& remote) {
  if (!remote.empty() && remote.front() == '[') {
    size_t close = remote.find(']');
    return close == std::string::npos ? remote : remote.substr(1, close - 1);
  }
  size_t colon = remote.rfind(':');
  if (colon != std::string::npos && remote.find(':') == colon) return remote.substr(0, colon);
  return remote;  // no port, or a bare IPv6 address
}

bool RefusalLedger::admit(RefusalKey key, int64_t now_ms) {
  MutexLock lock(mu_);
  auto it = windows_.find(key);
  if (it == windows_.end()) {
    if (windows_.size() >= opt_.max_keys) {
      // The table is full: counted under one overflow key (source, event, code, route "*").
      const RefusalKey overflow{"*", "*", "*", "*"};
      it = windows_.find(overflow);
      if (it == windows_.end()) {
        it = windows_.emplace(overflow, Window{now_ms, RefusalSummary{overflow, 0, 0, 0}}).first;
        if (on_change_) on_change_();
      }
    } else {
      windows_.emplace(key, Window{now_ms, RefusalSummary{key, 0, 0, 0}});
      if (on_change_) on_change_();
      return true;  // the first of its kind in this window: recorded as usual
    }
  }
  RefusalSummary& s = it->second.summary;
  if (s.suppressed == 0) s.first_ms = now_ms;
  s.last_ms = now_ms;
  ++s.suppressed;
  ++suppressed_total_;
  return false;
}

std::vector<RefusalSummary> RefusalLedger::due(int64_t now_ms, bool all) {
  std::vector<RefusalSummary> out;
  MutexLock lock(mu_);
  for (auto it = windows_.begin(); it != windows_.end();) {
    if (all || now_ms - it->second.opened_ms >= opt_.window_ms) {
      if (it->second.summary.suppressed > 0) out.push_back(it->second.summary);
      it = windows_.erase(it);
    } else {
      ++it;
    }
  }
  return out;
}

uint64_t RefusalLedger::suppressed_total() const {
  MutexLock lock(mu_);
  return suppressed_total_;
}

}  // namespace rcan::node
