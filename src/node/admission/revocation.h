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
// Persisted as `revocations.json` in the node's state directory (one JSON object, through
// audit::Env::write_file_atomic, mode 0600): an entry is in force only once the file holds it.
// Bounded: at most `capacity` entries (10,000 by default, about 200 bytes each); a full list
// first drops jti entries whose token has expired, then refuses the new entry (revoke by
// subject or kid instead). Thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "rcan/audit/env.h"
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

  json::Value to_json() const;
  // One entry of the file or of a request. Errors: SCHEMA_VALIDATION_FAILED naming the field.
  static Result<Revocation> from_json(const json::Value& v);
};

std::string_view revocation_kind_name(Revocation::Kind k);  // "jti" | "sub" | "kid"

class RevocationList {
 public:
  static constexpr size_t kDefaultCapacity = 10'000;
  static constexpr size_t kMaxFieldBytes = 512;

  // `path` empty: nothing is persisted (tests). `leeway_s`: the verifier's clock leeway, kept
  // after a jti entry's `exp` before it is dropped.
  explicit RevocationList(std::string path = {}, size_t capacity = kDefaultCapacity,
                          int64_t leeway_s = 60, audit::Env* env = nullptr);

  // Reads the file (absent: an empty list). Errors: SCHEMA_VALIDATION_FAILED naming the file
  // and what is wrong with it; the list is then unchanged.
  Status load(int64_t now_s) EXCLUDES(mu_, write_mu_);
  // The whole file's content: {"version":1,"revocations":[…]}. Errors as from_json.
  static Result<std::vector<Revocation>> parse(const json::Value& doc, size_t capacity);

  // Adds `r` and writes the file. False when an equal entry is already in force (nothing
  // changes). Errors: COMMAND_REJECTED `revocation_list_full`; INTERNAL when the file could not
  // be written (the entry is then not in force).
  Result<bool> add(Revocation r, int64_t now_s) EXCLUDES(mu_, write_mu_);

  // Why `p` is revoked ("jti", "sub", "kid"), or nullopt.
  std::optional<std::string> revoked(const Principal& p) const EXCLUDES(mu_);
  // The entries in force (oldest first) and the count.
  std::vector<Revocation> list() const EXCLUDES(mu_);
  size_t size() const EXCLUDES(mu_);
  size_t capacity() const { return capacity_; }

  // Called (on the revoking thread, after the file holds the entry) for every new entry, so
  // that transports close the streams of principals it revokes. Must only enqueue or close.
  using Listener = std::function<void(const Revocation&)>;
  uint64_t subscribe(Listener fn) EXCLUDES(lmu_);
  void unsubscribe(uint64_t id) EXCLUDES(lmu_);

 private:
  void install(std::vector<Revocation> entries) EXCLUDES(mu_);
  std::vector<Revocation> pruned(int64_t now_s) const EXCLUDES(mu_);
  // The entry's second for (k, iss, value), else for (k, any issuer, value); null when neither.
  const int64_t* find_locked(Revocation::Kind k, std::string_view iss, std::string_view value) const
      REQUIRES(mu_);

  const std::string path_;
  const size_t capacity_;
  const int64_t leeway_s_;
  audit::Env* env_;
  Mutex write_mu_;  // one writer of the file at a time; lookups never wait for a write
  mutable Mutex mu_;
  std::vector<Revocation> entries_ GUARDED_BY(mu_);
  // "<kind>\x1f<iss>\x1f<value>" → the entry's second (kSubject: the `iat` bound).
  std::unordered_map<std::string, int64_t> index_ GUARDED_BY(mu_);
  Mutex lmu_;
  std::map<uint64_t, Listener> listeners_ GUARDED_BY(lmu_);
  uint64_t next_listener_ GUARDED_BY(lmu_) = 0;
};

}  // namespace rcan::node
