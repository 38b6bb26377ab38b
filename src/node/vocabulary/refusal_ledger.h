// RefusalLedger — the audit log's defence against floods of requests that carry no verified
// principal (a bad body, no token, a token that does not verify). Each such refusal is still
// accounted for, but not each with a record of its own: per source address and kind (event,
// error code, route), the first in a window is recorded as usual and the rest are counted; when
// the window closes, one REFUSALS_SUMMARY record gives the count and the first and last time.
// Nothing is dropped silently, and the log grows by a bounded number of records per source and
// window however fast the requests come. The table of keys is bounded too: a refusal whose key
// finds it full is counted under one overflow key ("*" for source, event, code and route).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "base/thread_annotations.h"

namespace rcan::node {

struct RefusalKey {
  std::string source;  // the peer's address, without its port
  std::string event;   // the record's event (AUTH_FAILED, MESSAGE_REJECTED, …)
  std::string code;    // the error code
  std::string route;
  auto tie() const { return std::tie(source, event, code, route); }
  bool operator<(const RefusalKey& o) const { return tie() < o.tie(); }
};

struct RefusalSummary {
  RefusalKey key;
  uint64_t suppressed = 0;            // refusals counted here and not recorded one by one
  int64_t first_ms = 0, last_ms = 0;  // wall clock of the first and last of them
};

struct RefusalLedgerOptions {
  int64_t window_ms = 10'000;
  size_t max_keys = 4'096;
};

class RefusalLedger {
 public:
  explicit RefusalLedger(RefusalLedgerOptions o = {}) : opt_(o) {}

  // True: record this refusal as usual (the first of its key in this window). False: it is
  // counted, and appears in that key's summary.
  bool admit(RefusalKey key, int64_t now_ms) EXCLUDES(mu_);
  // The summaries of windows closed by `now_ms` (all of them when `all`); their keys are
  // forgotten. Only keys that counted something give a summary.
  std::vector<RefusalSummary> due(int64_t now_ms, bool all = false) EXCLUDES(mu_);
  uint64_t suppressed_total() const EXCLUDES(mu_);
  // True when no window is open (nothing for due() to close, however late).
  bool quiet() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return windows_.empty();
  }
  // `fn` runs (under the ledger's lock: it must not call back) when a window opens, so that
  // the node's control tick, asleep while nothing is timed, wakes to close it in time. Set
  // once, before the ledger is shared; an empty function removes it.
  void on_change(std::function<void()> fn) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    on_change_ = std::move(fn);
  }

  // "192.0.2.7:4711" → "192.0.2.7", "[::1]:80" → "::1".
  static std::string source_of(const std::string& remote);

 private:
  struct Window {
    int64_t opened_ms = 0;
    RefusalSummary summary;
  };
  RefusalLedgerOptions opt_;
  mutable Mutex mu_;
  std::map<RefusalKey, Window> windows_ GUARDED_BY(mu_);
  uint64_t suppressed_total_ GUARDED_BY(mu_) = 0;
  std::function<void()> on_change_ GUARDED_BY(mu_);
};

}  // namespace rcan::node
