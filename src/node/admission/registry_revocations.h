// The registry's revocation feed, as the node follows it (registry_trust_link.h): GET
// <registry>/api/v1/revocations?since=<seq>, each entry added to the node's revocation list
// (its feed table: persisted, the token's streams closed; recorded TOKEN_REVOKED). The cursor
// is kept in <data-dir>/registry/revocations_cursor.json, so that a restart reads on where the
// last run stopped. A full feed table skips the entry (counted, recorded) rather than stall the
// cursor. Polls are made by one thread at a time; the status and the metrics are read from any.
#pragma once

#include <atomic>
#include <cstdint>

#include "base/thread_annotations.h"
#include "node/admission/registry_trust_link.h"
#include "node/admission/revocation.h"
#include "rcan/json.h"

namespace rcan::node {

class RegistryRevocationFeed {
 public:
  RegistryRevocationFeed(RegistryTrustLink& link, RevocationList& revocations)
      : link_(link), revocations_(revocations) {}
  RegistryRevocationFeed(const RegistryRevocationFeed&) = delete;
  RegistryRevocationFeed& operator=(const RegistryRevocationFeed&) = delete;

  // Reads the cursor file, when it is of this registry.
  void load_cursor() EXCLUDES(mu_);
  // Reads the feed from the cursor on (at most 20 pages, each call bounded by `timeout_ms`),
  // applying each entry and saving the cursor after each page; false on a failure (what was
  // applied before it stays applied).
  bool poll(int timeout_ms) EXCLUDES(mu_);

  // The sequence number of the last entry read (0: none).
  int64_t since() const EXCLUDES(mu_);
  // {since, last_poll_ms, applied}.
  json::Value status_json() const EXCLUDES(mu_);

  const std::atomic<uint64_t>& polls() const { return polls_; }
  const std::atomic<uint64_t>& failures() const { return failures_; }
  const std::atomic<uint64_t>& applied() const { return applied_; }
  const std::atomic<uint64_t>& skipped() const { return skipped_; }

 private:
  // One page of the feed from the cursor: applied; its size, or -1 on a failure.
  int64_t poll_page(int timeout_ms) EXCLUDES(mu_);
  // Writes the cursor file when the cursor moved since it was last saved.
  void save_cursor() EXCLUDES(mu_);
  void advance(int64_t seq) EXCLUDES(mu_);

  RegistryTrustLink& link_;
  RevocationList& revocations_;
  std::atomic<uint64_t> polls_{0}, failures_{0}, applied_{0}, skipped_{0};

  mutable Mutex mu_;
  int64_t since_ GUARDED_BY(mu_) = 0;
  int64_t saved_since_ GUARDED_BY(mu_) = 0;  // the cursor the file holds
  int64_t last_poll_ms_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node
