// The registry's signing keys, as the node follows them (registry_trust_link.h): fetched from
// GET <registry>/.well-known/jwks.json, handed to the Authenticator as the followed issuer's
// keys (swapped in without a restart), and cached in <data-dir>/registry/jwks.json (0600) with
// the time of the last successful fetch, so that a restart while the registry does not answer
// still verifies its tokens. A malformed JWKS, or one without a usable key, keeps the keys in
// use (recorded REGISTRY_KEYS_REJECTED). Fetches are made by one thread at a time (the
// caller's: RegistryTrust's thread, or start-up before it runs); the status and the metrics
// are read from any thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "node/admission/registry_trust_link.h"
#include "rcan/json.h"

namespace rcan::node {

class RegistryKeys {
 public:
  RegistryKeys(RegistryTrustLink& link, Authenticator& auth) : link_(link), auth_(auth) {}
  RegistryKeys(const RegistryKeys&) = delete;
  RegistryKeys& operator=(const RegistryKeys&) = delete;

  // Fetches the keys (bounded by `timeout_ms`), installs them and writes the cache; false when
  // the registry did not answer with a usable JWKS (the keys in use kept, the failure reported).
  bool fetch(int timeout_ms);
  // Installs the keys of the cache file when it is of this registry and issuer; false when
  // there is no such cache or its keys are not usable.
  bool load_cache();

  // When the keys were last fetched successfully (unix ms; 0: never).
  int64_t fetched_ms() const { return fetched_ms_.load(); }
  size_t key_count() const EXCLUDES(mu_);
  // {fetched_at_ms, fresh_until_ms, key_count, kids, source}.
  json::Value status_json() const EXCLUDES(mu_);

  const std::atomic<uint64_t>& fetches() const { return fetches_; }
  const std::atomic<uint64_t>& failures() const { return failures_; }

 private:
  // Installs the keys of the JWKS `text` fetched at `fetched_ms`; false (the keys in use kept,
  // the refusal recorded) when it is not a usable JWKS.
  bool install(const std::string& text, int64_t fetched_ms, const char* source) EXCLUDES(mu_);

  RegistryTrustLink& link_;
  Authenticator& auth_;
  std::atomic<int64_t> fetched_ms_{0};
  std::atomic<uint64_t> fetches_{0}, failures_{0};

  mutable Mutex mu_;
  std::string installed_ GUARDED_BY(mu_);  // canonical JSON of the keys in use
  size_t key_count_ GUARDED_BY(mu_) = 0;
  std::vector<std::string> kids_ GUARDED_BY(mu_);
  std::string source_ GUARDED_BY(mu_);  // "fetched" | "cache" | ""
};

}  // namespace rcan::node
