// RevocationList — tokens the node no longer accepts, whatever their signature and expiry say.
//
// An entry names tokens in one of three ways:
//   by jti      one token: its `jti` (and issuer, when known) — kept with the token's `exp`
//               and dropped once the token would have expired anyway;
//   by subject  every token of one principal (issuer + `sub`; an empty issuer: that `sub` at
//               any issuer) issued at or before the revocation (`iat` ≤ the revocation's
//               second, or no `iat`): the owner can mint the subject a new token afterwards;
//   by kid      every token whose header names that issuer key id, whenever issued (a leaked
//               key can mint tokens with any `iat`).
// Each entry says when and by whom. NodeServices::authenticate checks every principal, fresh or
// from the token cache, and the pipeline checks a stream's CONNECT principal with every message.
//
// Persisted in the node's state directory, mode 0600: `revocations.json`, a snapshot (one JSON
// object, written atomically), and `revocations.json.journal`, one JSON line per entry added
// since, appended and synced (docs/THREATS.md T4: an entry costs one short append, not a rewrite
// of the whole list). An entry is in force only once the journal holds it. The start folds the
// journal into the snapshot, as does every kCompactEvery-th entry; a torn last line (a crash
// during its append: never acknowledged) is dropped.
// Bounded, in two tables that never crowd each other out: the node's own entries (its OWNER's
// revocations, `capacity`) and those copied from a registry's feed (`feed_capacity`). A full
// table first drops jti entries whose token has expired, then refuses the new entry
// (revocation_list_full; a feed entry: revocation_feed_full). Thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "rcan/base/env.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct Revocation {
  enum class Kind { kJti, kSubject, kKid };
  Kind kind = Kind::kJti;
  std::string iss;             // the issuer; empty: any issuer
  std::string value;           // the jti, the sub or the kid
  std::optional<int64_t> exp;  // kJti: the token's expiry (unix s); absent: kept until removed
  int64_t at_ms = 0;           // when (unix ms)
  PrincipalId by;              // who
  std::string reason;          // free text, optional
  bool feed = false;           // copied from a registry's revocation feed (its own table)

  json::Value to_json() const;
  // One entry of the file or of a request. Errors: SCHEMA_VALIDATION_FAILED naming the field.
  static Result<Revocation> from_json(const json::Value& v);
};

std::string_view revocation_kind_name(Revocation::Kind k);  // "jti" | "sub" | "kid"

class RevocationList {
 public:
  static constexpr size_t kDefaultCapacity = 10'000;
  static constexpr size_t kMaxFieldBytes = 512;
  static constexpr size_t kCompactEvery = 1024;  // journal lines before they are folded in

  // `path` empty: nothing is persisted (tests). `leeway_s`: the verifier's clock leeway, kept
  // after a jti entry's `exp` before it is dropped.
  explicit RevocationList(std::string path = {}, size_t capacity = kDefaultCapacity,
                          int64_t leeway_s = 60, base::Env* env = nullptr,
                          size_t feed_capacity = kDefaultCapacity);

  // Reads the snapshot and the journal (absent: an empty list; an entry in both counts once) and
  // folds the journal in (where that cannot be written it is logged, and the list runs on the
  // journal). Errors: SCHEMA_VALIDATION_FAILED naming the file and what is wrong with it (the
  // list is then unchanged).
  Status load(int64_t now_s) EXCLUDES(mu_, write_mu_);
  // The whole file's content: {"version":1,"revocations":[…]}. Errors as from_json.
  static Result<std::vector<Revocation>> parse(const json::Value& doc, size_t capacity);

  // Adds `r` (to the feed's table when r.feed) and appends it to the journal. False when an
  // equal entry is already in force (nothing changes). Errors: COMMAND_REJECTED
  // `revocation_list_full` / `revocation_feed_full`; INTERNAL when the journal could not hold it
  // (the entry is then not in force).
  Result<bool> add(Revocation r, int64_t now_s) EXCLUDES(mu_, write_mu_);

  // Why `p` is revoked ("jti", "sub", "kid"), or nullopt.
  std::optional<std::string> revoked(const Principal& p) const EXCLUDES(mu_);
  // The entries in force (oldest first) and the count.
  std::vector<Revocation> list() const EXCLUDES(mu_);
  size_t size() const EXCLUDES(mu_);
  size_t capacity() const { return capacity_; }
  size_t feed_capacity() const { return feed_capacity_; }
  std::string journal_path() const { return path_.empty() ? path_ : path_ + ".journal"; }

  // Called (on the revoking thread, after the file holds the entry) for every new entry, so
  // that transports close the streams of principals it revokes. Must only enqueue or close.
  using Listener = std::function<void(const Revocation&)>;
  uint64_t subscribe(Listener fn) EXCLUDES(lmu_);
  void unsubscribe(uint64_t id) EXCLUDES(lmu_);

 private:
  void install(std::vector<Revocation> entries) EXCLUDES(mu_);
  // Adds one entry in memory.
  void insert(const Revocation& r) EXCLUDES(mu_);
  // Drops the jti entries whose token has expired.
  void prune(int64_t now_s) EXCLUDES(mu_);
  // The journal's entries (a torn last line dropped). Errors as load().
  Result<std::vector<Revocation>> read_journal() const;
  // Writes the snapshot of the entries in force and empties the journal.
  Status compact() REQUIRES(write_mu_) EXCLUDES(mu_);
  // Appends `r` to the journal and syncs it.
  Status append(const Revocation& r) REQUIRES(write_mu_);
  // The entry's second for (k, iss, value), else for (k, any issuer, value); null when neither.
  const int64_t* find_locked(Revocation::Kind k, std::string_view iss, std::string_view value) const
      REQUIRES(mu_);

  const std::string path_;
  const size_t capacity_;
  const int64_t leeway_s_;
  base::Env* env_;
  const size_t feed_capacity_;
  Mutex write_mu_;  // one writer of the files at a time; lookups never wait for a write
  std::unique_ptr<base::WritableFile> journal_ GUARDED_BY(write_mu_);
  size_t journal_lines_ GUARDED_BY(write_mu_) = 0;
  // A failed append may have left part of a line: the next entry goes in by a compaction.
  bool journal_torn_ GUARDED_BY(write_mu_) = false;
  mutable Mutex mu_;
  std::vector<Revocation> entries_ GUARDED_BY(mu_);
  size_t own_count_ GUARDED_BY(mu_) = 0, feed_count_ GUARDED_BY(mu_) = 0;
  // "<kind>\x1f<iss>\x1f<value>" → the entry's second (kSubject: the `iat` bound).
  std::unordered_map<std::string, int64_t> index_ GUARDED_BY(mu_);
  Mutex lmu_;
  std::map<uint64_t, Listener> listeners_ GUARDED_BY(lmu_);
  uint64_t next_listener_ GUARDED_BY(lmu_) = 0;
};

}  // namespace rcan::node
