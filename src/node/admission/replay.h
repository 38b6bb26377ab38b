// ReplayGuard — the replay window (docs/NODE.md §The pipeline), one memory per principal.
//
// A message is fresh when its timestamp is within `window_ms` of the node's wall clock
// (10 s at most for SAFETY messages, at most `future_tolerance_ms` ahead of it) and its
// principal has not used its id inside the window. Ids are remembered per principal (the
// issuer + subject of the verified token, Principal::key()): the token binds a message to its
// sender, so the same id from another principal is another message, acting with that
// principal's rights only — and no principal can use up, or find out, another's ids.
//
// Bounds. The memory holds at most `capacity` ids in all (security.msg_id_cache_size) and at
// most `share()` ids per principal (capacity / 16 unless set). No principal's traffic ever
// removes or ages out another principal's ids:
//   * a principal at its share makes room from its own oldest id: that id's timestamp joins the
//     principal's own refused range, so the forgotten id can never be replayed (a non-safety
//     message of that principal whose timestamp lies in one of its refused ranges is stale) —
//     the cost of a principal's volume is borne by that principal alone;
//   * when the whole memory is full (it takes 16 principals each at its full share — more than
//     the default rate limits let any role below LEASEE send in the window), a principal below
//     its share is refused RATE_LIMITED (reason `replay_memory_full`) until ids expire: never
//     made stale, and never a SAFETY stop, which then passes unremembered (a fresh duplicate
//     stop is let through anyway).
// Fresh duplicate SAFETY stops are let through (an ESTOP is never refused for anything but
// authentication and its timestamp) and reported as duplicates.
//
// peek() answers what check() would refuse (stale, or an id its principal already used)
// without remembering anything: the pipeline looks early, right after authentication, and
// remembers the id only once authorisation, the guest limits and the rate limit have passed,
// so a message refused on the way uses up nothing (docs/NODE.md §The pipeline).
//
// Wall-clock steps (docs/NODE.md §Faults): ids are kept and expired by their own timestamps
// in timestamp order, never by arrival order, and the refused ranges cover only the
// timestamps that were evicted. After the node's clock steps back, ids from before the step
// stay remembered until the clock has caught up with them (they could become fresh again),
// and messages stamped with the new time are not refused because of evictions that happened
// before the step; after a step forward, everything older than the window is stale anyway.
#pragma once

#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "base/thread_annotations.h"
#include "rcan/result.h"

namespace rcan::node {

struct ReplayOptions {
  int64_t window_ms = 30'000;
  int64_t safety_window_ms = 10'000;
  int64_t future_tolerance_ms = 5'000;  // clock drift allowed into the future (within window)
  size_t capacity = 10'000;             // ids remembered in all
  size_t principal_share = 0;           // ids one principal may hold; 0: capacity / 16
};

class ReplayGuard {
 public:
  explicit ReplayGuard(ReplayOptions opts = {});

  struct Verdict {
    bool duplicate_safety = false;  // a fresh SAFETY message seen before, let through
    bool unremembered = false;      // a SAFETY message let through with the memory full
  };
  // Checks and remembers `message_id` for `principal`. Errors: kMessageStale (outside the
  // window, or in the principal's refused range), kReplayDetected (the principal used it),
  // kRateLimited (the memory is full and the principal is below its share; retry_after_ms()).
  Result<Verdict> check(const std::string& principal, const std::string& message_id,
                        int64_t timestamp_ms, bool safety, int64_t now_wall_ms) EXCLUDES(mu_);
  // What check() would refuse for staleness or a used id; remembers nothing.
  Result<Verdict> peek(const std::string& principal, const std::string& message_id,
                       int64_t timestamp_ms, bool safety, int64_t now_wall_ms) EXCLUDES(mu_);
  // After kRateLimited: how long until the first remembered id leaves the window.
  int64_t retry_after_ms(int64_t now_wall_ms) const EXCLUDES(mu_);

  size_t share() const { return share_; }
  size_t size() const EXCLUDES(mu_);  // ids remembered in all
  size_t size_of(const std::string& principal) const EXCLUDES(mu_);
  size_t principals() const EXCLUDES(mu_);   // principals with ids or refused ranges
  uint64_t evictions() const EXCLUDES(mu_);  // ids a principal's own newer ids displaced
  uint64_t full_refusals() const EXCLUDES(mu_);

 private:
  // One principal's memory. Its ids map to their timestamps; by_ts orders them, oldest first
  // (pointing at the map's keys, which do not move).
  struct Book {
    const std::string* key = nullptr;  // the principal (the key of books_)
    std::unordered_map<std::string, int64_t> ids;
    std::set<std::pair<int64_t, const std::string*>> by_ts;
    std::vector<std::pair<int64_t, int64_t>> refused;  // [lo, hi] timestamps of evicted ids
    int64_t due = 0;                                   // its key in due_ (when indexed)
    bool indexed = false;
  };

  // The refusal for a timestamp outside the window (no lock: a function of the clock).
  std::optional<Error> outside_window(int64_t timestamp_ms, bool safety, int64_t now_wall_ms) const;
  // The principal's refused ranges and used ids (b null: a principal with nothing remembered).
  Result<Verdict> judge_locked(Book* b, const std::string& message_id, int64_t timestamp_ms,
                               bool safety) REQUIRES(mu_);
  Book* find_locked(const std::string& principal) REQUIRES(mu_);
  void expire_locked(int64_t now_wall_ms) REQUIRES(mu_);
  void expire_book_locked(Book& b, int64_t oldest) REQUIRES(mu_);
  void evict_oldest_locked(Book& b) REQUIRES(mu_);
  void reindex_locked(Book& b) REQUIRES(mu_);
  bool refused_locked(const Book& b, int64_t ts) const REQUIRES(mu_);

  const ReplayOptions opts_;
  const size_t share_;
  mutable Mutex mu_;
  std::unordered_map<std::string, Book> books_ GUARDED_BY(mu_);
  // (the earliest timestamp a book holds — an id or a refused range's end —, book): the order
  // in which books have something to expire.
  std::set<std::pair<int64_t, Book*>> due_ GUARDED_BY(mu_);
  size_t total_ GUARDED_BY(mu_) = 0;
  uint64_t evictions_ GUARDED_BY(mu_) = 0;
  uint64_t full_refusals_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node
