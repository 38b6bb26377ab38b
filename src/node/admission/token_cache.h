// TokenCache — remembers tokens that passed full JWT verification, so that a client sending
// the same bearer token with every request pays one signature check, not one per request.
//
// It is never weaker than verifying: the key is the token's exact bytes (compared in full,
// not by hash), nothing but a successful verification inserts, and every hit re-applies the
// time-dependent checks of the verification (exp, nbf, iat with the same leeway) — a hit
// outside that window is dropped and the caller verifies afresh (and refuses with the
// verifier's own error). Everything else the verification depends on (trusted issuers and
// keys, audience, fleet ids) is fixed for the life of the Authenticator that owns the cache,
// which clears it when a followed issuer's keys change.
// Bounded: at most `capacity` entries; when full, an arbitrary entry is evicted. Thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"

namespace rcan::node {

class TokenCache {
 public:
  explicit TokenCache(size_t capacity) : capacity_(capacity) {}

  // The principal of `token` when it was verified before and its time window holds at `now_s`.
  std::optional<Principal> find(std::string_view token, int64_t now_s) EXCLUDES(mu_);
  // Remembers a verified token, valid for now_s in [valid_from_s, valid_until_s).
  void insert(std::string_view token, const Principal& p, int64_t valid_from_s,
              int64_t valid_until_s) EXCLUDES(mu_);

  size_t size() const EXCLUDES(mu_);
  // Forgets every entry (the keys the verification depends on changed).
  void clear() EXCLUDES(mu_);
  uint64_t hits() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return hits_;
  }

 private:
  struct Entry {
    Principal principal;
    int64_t valid_from_s = std::numeric_limits<int64_t>::min();
    int64_t valid_until_s = 0;
  };
  const size_t capacity_;
  mutable Mutex mu_;
  // Looked up by the token's view (a fleet message's token is some KiB: no copy per message).
  struct Hash {
    using is_transparent = void;
    size_t operator()(std::string_view s) const noexcept {
      return std::hash<std::string_view>{}(s);
    }
  };
  std::unordered_map<std::string, Entry, Hash, std::equal_to<>> map_ GUARDED_BY(mu_);
  uint64_t hits_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node
