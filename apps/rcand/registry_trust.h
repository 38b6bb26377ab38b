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
//   introspect   a token naming the registry's issuer that its keys cannot verify (a kid still
//                unknown after the early fetch, keys not fetched yet) is refused, and queued for
//                POST <registry>/oauth/introspect (RFC 7662, the robot's own registry key) on
//                this class's thread — never on a transport thread. The answer is cached (active:
//                until min(exp, 60 s); inactive or failed: 30 s; at most 10,000 tokens), and the
//                token's next use is decided by it: the answer's claims are checked like a
//                verified token's (exp, aud against this robot, role, scopes).
//   freshness    keys_fetched_ms() is what the partition monitor calls "keys fresh" when it
//                probes the registry (<registry>/healthz) for seed §6.1.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>

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
  // Queues `token` for introspection unless it is queued or answered already (bounded; never
  // blocks on the network).
  void request_introspection(std::string_view token);
  // The cached answer for `token`: the claims of an active one, else nullopt.
  std::optional<json::Object> introspected(std::string_view token) const;
  // When the keys were last fetched successfully (unix ms; 0: never).
  int64_t keys_fetched_ms() const { return fetched_ms_.load(); }
  json::Value status_json() const;

 private:
  void run();
  bool fetch_jwks(int timeout_ms);
  bool poll_revocations(int timeout_ms);
  void save_cursor();
  void introspect(const std::string& token, int timeout_ms);
  // Installs the keys of the JWKS `text` fetched at `fetched_ms`; false (the keys in use kept,
  // the refusal recorded) when it is not a usable JWKS.
  bool install(const std::string& text, int64_t fetched_ms, const char* source);
  void failed(const std::string& what, const std::string& error);
  std::string url(const std::string& path) const;

  const config::NodeConfig& cfg_;
  node::NodeServices& svc_;
  const std::string issuer_;
  const std::string dir_;
  std::atomic<int64_t> fetched_ms_{0};
  std::atomic<int64_t> last_early_ms_{0};
  std::atomic<uint64_t> jwks_fetches_{0}, jwks_failures_{0}, rev_polls_{0}, rev_failures_{0},
      revocations_applied_{0}, revocations_skipped_{0}, introspections_{0},
      introspection_failures_{0};

  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  bool early_ = false;
  std::string installed_;  // canonical JSON of the keys in use
  size_t key_count_ = 0;
  std::vector<std::string> kids_;
  std::string keys_source_;  // "fetched" | "cache" | ""
  int64_t since_ = 0;
  int64_t saved_since_ = 0;  // the cursor the file holds
  int64_t last_poll_ms_ = 0;
  std::string keys_error_;  // the last failure of the keys ("" once a fetch succeeds)
  std::string revs_error_;  // the last failure of the revocation feed
  std::deque<std::string> to_introspect_;  // guarded by mu_
  // The token being put to the registry now (guarded by mu_): asked for again meanwhile, it is
  // not queued a second time (its answer is stored before this is cleared).
  std::string introspecting_;

  struct Answer {
    std::optional<json::Object> claims;  // active: the claims; inactive or failed: none
    int64_t until_ms = 0;                // wall
  };
  mutable std::mutex answers_mu_;
  mutable std::unordered_map<std::string, Answer> answers_;  // token → answer

  std::thread thread_;
};

}  // namespace rcan::rcand
