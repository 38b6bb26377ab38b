// rcand trusts, follows and falls back on its registry's token authority (config
// `registry.trust_tokens`; docs/SECURITY.md §Tokens from the registry).
//
//   keys         GET <registry>/.well-known/jwks.json at start (bounded) and every
//                registry.jwks_refresh_s; the keys verify tokens whose `iss` is the registry's
//                issuer next to the configured issuers, swapped in without a restart. A token
//                naming a kid the node does not know asks for one early fetch (at most one a
//                minute). Cached in <data-dir>/registry/jwks.json (0600) with the time of the
//                last successful fetch; loaded from there when the registry does not answer at
//                start. A malformed JWKS, or one without a usable key, keeps the keys in use.
//   revocations  GET <registry>/api/v1/revocations?since=<seq> every
//                registry.revocations_refresh_s, each entry added to the node's revocation
//                list (recorded TOKEN_REVOKED, persisted, streams closed); the cursor is kept
//                in <data-dir>/registry/revocations_cursor.json.
//   freshness    keys_fetched_ms() is what the partition monitor calls "keys fresh" when it
//                probes the registry (<registry>/healthz) for seed §6.1.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "config/config.h"
#include "rcan/json.h"

namespace rcan::node {
class NodeServices;
}

namespace rcan::rcand {

class RegistryTrust {
 public:
  RegistryTrust(const config::NodeConfig& cfg, node::NodeServices& svc);
  ~RegistryTrust();
  RegistryTrust(const RegistryTrust&) = delete;
  RegistryTrust& operator=(const RegistryTrust&) = delete;

  const std::string& issuer() const { return issuer_; }
  // Before the node serves: the cached keys and cursor, then one fetch of the keys (bounded by
  // `timeout_ms`); hooks the node's verification (unknown kid → early fetch), its status and
  // its metrics.
  void prime(int timeout_ms);
  void start();
  void stop();
  // Asks the background thread for an early fetch of the keys; at most one a minute. Never
  // blocks on the network (called on the authenticating thread).
  void request_early_refresh();
  // When the keys were last fetched successfully (unix ms; 0: never).
  int64_t keys_fetched_ms() const { return fetched_ms_.load(); }
  json::Value status_json() const;

 private:
  void run();
  bool fetch_jwks(int timeout_ms);
  bool poll_revocations(int timeout_ms);
  // Installs the keys of `jwks` (a JWKS object) fetched at `fetched_ms`; false when unusable.
  bool install(const json::Value& jwks, int64_t fetched_ms, const char* source);
  void failed(const std::string& what, const std::string& error);
  std::string url(const std::string& path) const;

  const config::NodeConfig& cfg_;
  node::NodeServices& svc_;
  const std::string issuer_;
  const std::string dir_;
  std::atomic<int64_t> fetched_ms_{0};
  std::atomic<int64_t> last_early_ms_{0};
  std::atomic<uint64_t> jwks_fetches_{0}, jwks_failures_{0}, rev_polls_{0}, rev_failures_{0},
      revocations_applied_{0};

  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  bool early_ = false;
  std::string installed_;  // canonical JSON of the keys in use
  size_t key_count_ = 0;
  std::vector<std::string> kids_;
  std::string keys_source_;  // "fetched" | "cache" | ""
  int64_t since_ = 0;
  int64_t last_poll_ms_ = 0;
  std::string last_error_;
  std::thread thread_;
};

}  // namespace rcan::rcand
