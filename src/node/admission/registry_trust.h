// The node trusts, follows and falls back on its registry's token authority (config
// `registry.trust_tokens`; docs/SECURITY.md §Tokens from the registry). One thread runs the
// link's parts (registry_trust_link.h):
//
//   keys         RegistryKeys (registry_keys.h): fetched at start (bounded) and every
//                jwks_refresh_s; a token naming a kid the node does not know asks for one early
//                fetch (at most one a minute). Loaded from the cache when the registry does not
//                answer at start.
//   revocations  RegistryRevocationFeed (registry_revocations.h): polled every
//                revocations_refresh_s; the cursor survives restarts.
//   introspect   a token naming the registry's issuer that its keys cannot verify (a kid still
//                unknown after the early fetch, keys not fetched yet) is refused, and queued for
//                POST <registry>/oauth/introspect (RFC 7662, the robot's own registry key, from
//                <data-dir>/registry/state.json) on this class's thread — never on a transport
//                thread. The answer is cached (IntrospectionAnswers: active until
//                min(exp, 60 s); inactive or failed: 30 s; at most 10,000 tokens), and the
//                token's next use is decided by it: the answer's claims are checked like a
//                verified token's (exp, aud against this robot, role, scopes).
//   freshness    keys_fetched_ms() is what the partition monitor calls "keys fresh" when it
//                probes the registry (<registry>/healthz) for seed §6.1.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>

#include "base/clock.h"
#include "base/metrics.h"
#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "node/admission/registry_keys.h"
#include "node/admission/registry_revocations.h"
#include "node/admission/registry_trust_link.h"
#include "node/admission/revocation.h"
#include "rcan/json.h"

namespace rcan::node {

// The registry's answers on tokens its keys could not verify, each kept until its own time
// (wall clock): the claims of an active token, or none (inactive, or the call failed). Bounded:
// past `capacity` answers, the expired ones go, then an arbitrary one. Thread-safe.
class IntrospectionAnswers {
 public:
  struct Answer {
    std::optional<json::Object> claims;  // active: the claims; inactive or failed: none
    int64_t until_ms = 0;                // wall
  };
  explicit IntrospectionAnswers(const Clock& clock, size_t capacity = 10'000)
      : clock_(clock), capacity_(capacity) {}

  // Whether `token` has an answer still in force (active or not).
  bool answered(std::string_view token) const EXCLUDES(mu_);
  // The claims of an active answer in force for `token`, else nullopt (an expired answer is
  // dropped).
  std::optional<json::Object> claims(std::string_view token) const EXCLUDES(mu_);
  void put(const std::string& token, Answer answer) EXCLUDES(mu_);
  size_t size() const EXCLUDES(mu_);

 private:
  const Clock& clock_;
  const size_t capacity_;
  mutable Mutex mu_;
  mutable std::unordered_map<std::string, Answer> answers_ GUARDED_BY(mu_);  // token → answer
};

class RegistryTrust {
 public:
  // `record` writes the link's audit records; `env` (nullptr → base::Env::posix()) its files.
  RegistryTrust(RegistryTrustOptions opts, Clock& clock, Authenticator& auth,
                RevocationList& revocations, Metrics& metrics, TrustRecorder record,
                base::Env* env = nullptr);
  ~RegistryTrust();
  RegistryTrust(const RegistryTrust&) = delete;
  RegistryTrust& operator=(const RegistryTrust&) = delete;

  const std::string& issuer() const { return link_.issuer(); }
  // Before the node serves: the cached keys and cursor, then one fetch of the keys (bounded by
  // `timeout_ms`); hooks the Authenticator (unknown kid → early fetch and introspection) and
  // the metrics.
  void prime(int timeout_ms);
  void start();
  void stop() EXCLUDES(mu_);
  // Asks the background thread for an early fetch of the keys; at most one a minute. Never
  // blocks on the network (called on the authenticating thread).
  void request_early_refresh() EXCLUDES(mu_);
  // Queues `token` for introspection unless it is queued or answered already (bounded; never
  // blocks on the network).
  void request_introspection(std::string_view token) EXCLUDES(mu_);
  // The cached answer for `token`: the claims of an active one, else nullopt.
  std::optional<json::Object> introspected(std::string_view token) const {
    return answers_.claims(token);
  }
  // When the keys were last fetched successfully (unix ms; 0: never).
  int64_t keys_fetched_ms() const { return keys_.fetched_ms(); }
  json::Value status_json() const;

 private:
  void run() EXCLUDES(mu_);
  void introspect(const std::string& token, int timeout_ms);
  void add_metrics();

  RegistryTrustLink link_;
  Authenticator& auth_;
  Metrics& metrics_;
  RegistryKeys keys_;
  RegistryRevocationFeed feed_;
  IntrospectionAnswers answers_;
  std::atomic<int64_t> last_early_ms_{0};
  std::atomic<uint64_t> introspections_{0}, introspection_failures_{0};

  Mutex mu_;
  CondVar cv_;
  bool stopping_ GUARDED_BY(mu_) = false;
  bool early_ GUARDED_BY(mu_) = false;
  std::deque<std::string> to_introspect_ GUARDED_BY(mu_);
  // The token being put to the registry now: asked for again meanwhile, it is not queued a
  // second time (its answer is stored before this is cleared).
  std::string introspecting_ GUARDED_BY(mu_);

  std::thread thread_;
};

}  // namespace rcan::node
