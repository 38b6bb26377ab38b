// The node's link to the registry whose tokens it trusts (config `registry.trust_tokens`;
// docs/SECURITY.md §Tokens from the registry): where the registry is and how it is asked, the
// directory the link keeps its files in (<data-dir>/registry), the audit records it writes and
// the last errors its parts report. The parts — RegistryKeys (registry_keys.h),
// RegistryRevocationFeed (registry_revocations.h) and RegistryTrust (registry_trust.h), which
// runs them — all speak through one RegistryTrustLink. rcand fills RegistryTrustOptions from the
// configuration and turns each TrustRecord into a record of the node's audit log.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "rcan/base/env.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct RegistryTrustOptions {
  std::string registry_url;  // registry.registry_url
  std::string issuer;        // the `iss` of the registry's tokens (registry_url when not given)
  std::string data_dir;      // the link's files are in <data_dir>/registry
  std::string ca_file;       // https: trust anchors ("" = the system's)
  std::string rrn;           // this robot's RRN, for the status
  uint32_t jwks_refresh_s = 300;
  uint32_t revocations_refresh_s = 30;
  uint32_t max_key_age_s = 86400;
};

// An audit record of the link, written by the node itself (sender_type system).
struct TrustRecord {
  std::string event;
  std::string outcome;
  std::string reason;   // "" = none
  json::Object detail;  // in this order
};
using TrustRecorder = std::function<void(TrustRecord)>;

class RegistryTrustLink {
 public:
  // `env` (nullptr → base::Env::posix()) reads and writes the link's files.
  RegistryTrustLink(RegistryTrustOptions opts, Clock& clock, TrustRecorder record,
                    base::Env* env = nullptr);
  RegistryTrustLink(const RegistryTrustLink&) = delete;
  RegistryTrustLink& operator=(const RegistryTrustLink&) = delete;

  const RegistryTrustOptions& options() const { return opts_; }
  const std::string& issuer() const { return opts_.issuer; }
  const std::string& dir() const { return dir_; }  // <data_dir>/registry
  Clock& clock() const { return clock_; }
  base::Env* env() const { return env_; }

  // The registry's URL with `path` appended.
  std::string url(const std::string& path) const;
  // GET <registry><path>: the body of a 200 answer; else the failure in words (the URL, the
  // network, or "the registry answered <status>").
  Result<std::string> get(const std::string& path, int timeout_ms) const;
  // The link's directory (mode 0700), made when missing.
  Status make_dir() const;
  void record(TrustRecord r) const;

  // `what` failed: logged, and kept as the last error of the keys (`what` starting with
  // "registry keys") or of the rest.
  void failed(const std::string& what, const std::string& error) EXCLUDES(mu_);
  // A fetch of the keys succeeded: their last error is cleared.
  void keys_ok() EXCLUDES(mu_);
  // A poll of the revocation feed succeeded: a last error of the feed's polls is cleared.
  void feed_ok() EXCLUDES(mu_);
  // The keys' last error, else the rest's, else null.
  json::Value last_error() const EXCLUDES(mu_);

 private:
  const RegistryTrustOptions opts_;
  const std::string dir_;
  Clock& clock_;
  const TrustRecorder record_;
  base::Env* const env_;

  mutable Mutex mu_;
  std::string keys_error_ GUARDED_BY(mu_);   // "" once a fetch of the keys succeeds
  std::string other_error_ GUARDED_BY(mu_);  // the feed, its cursor, introspection
};

}  // namespace rcan::node
