// Network partition (seed §6.1; docs/SESSIONS.md). The node's token issuers are local keys;
// what can become unreachable is the issuer's published endpoint (`offline.issuer_url`, e.g.
// its JWKS URL), which the node probes. A credential cache holds the time of the last good
// probe (the issuer keys are "fresh" for `offline.max_key_ttl_s` after it) and the principals
// whose tokens were validated while the issuer was reachable (each until min(token exp,
// validation + key TTL)).
//   reachable                        → NORMAL
//   unreachable, keys still fresh    → OFFLINE_AUTONOMOUS: cached principals keep working, new
//                                      ones cannot start sessions; every audit record is
//                                      tagged (partition_mode, sync_pending) for later sync
//   unreachable, cache expired/empty → LOCKDOWN: no new sessions, existing ones are kept
// With no issuer_url configured the node has nothing to reach and stays NORMAL.
// An issuer whose keys the node fetches (rcand's registry link, docs/SECURITY.md) sets
// `keys_fetched_ms`: the keys are then fresh for key_ttl_ms after their last successful fetch,
// not after the last good probe.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <thread>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "rcan/json.h"

namespace rcan::node {

enum class NetMode { kNormal = 0, kOfflineAutonomous = 1, kLockdown = 2 };
std::string_view net_mode_name(NetMode m);

struct PartitionOptions {
  std::string issuer_url;  // empty: partition detection off
  int64_t poll_interval_ms = 5000;
  int timeout_ms = 1000;
  int64_t key_ttl_ms = 86'400'000;  // offline.max_key_ttl_s
  std::string ca_file;              // https: trust anchors (empty: the system's)
  // When set: when the issuer's keys were last fetched (unix ms; 0: never). Must not block.
  std::function<int64_t()> keys_fetched_ms;
};

class PartitionMonitor {
 public:
  ~PartitionMonitor();
  void configure(PartitionOptions o);
  bool enabled() const { return !opts_.issuer_url.empty(); }
  const PartitionOptions& options() const { return opts_; }

  // Starts the probe thread (no-op when disabled). `on_change(old, now)` runs on it.
  void start(std::function<int64_t()> wall_now, std::function<void(NetMode, NetMode)> on_change)
      EXCLUDES(run_mu_);
  void stop() EXCLUDES(run_mu_);
  // One probe now (the thread calls it; tests may too). Returns the resulting mode.
  NetMode probe_once() EXCLUDES(mu_);
  // Records a probe result and recomputes the mode; returns {old, new}.
  std::pair<NetMode, NetMode> record(bool reachable, int64_t now_wall_ms) EXCLUDES(mu_);

  NetMode mode() const { return static_cast<NetMode>(mode_.load()); }
  // The principal's token was validated while the issuer was reachable.
  void note_validated(const Principal& p, int64_t now_wall_ms) EXCLUDES(mu_);
  bool cached(const Principal& p, int64_t now_wall_ms) EXCLUDES(mu_);
  json::Value status_json(int64_t now_wall_ms) EXCLUDES(mu_);
  json::Value persist_json() EXCLUDES(mu_);
  void load_json(const json::Value& v, int64_t now_wall_ms) EXCLUDES(mu_);
  uint64_t version() EXCLUDES(mu_);

 private:
  NetMode compute_locked(int64_t now_wall_ms) const REQUIRES(mu_);
  // The time the issuer's keys are fresh from (0: never).
  int64_t keys_base_locked() const REQUIRES(mu_);
  PartitionOptions opts_;  // set by configure(), before start()
  Mutex mu_;
  std::atomic<int> mode_{0};
  bool reachable_ GUARDED_BY(mu_) = true;
  int64_t last_ok_ms_ GUARDED_BY(mu_) = 0;
  int64_t offline_since_ms_ GUARDED_BY(mu_) = 0;
  std::map<std::string, int64_t> cache_ GUARDED_BY(mu_);  // principal key → valid until (wall ms)
  uint64_t version_ GUARDED_BY(mu_) = 0;
  std::function<int64_t()> wall_;                    // set by start(), before the thread
  std::function<void(NetMode, NetMode)> on_change_;  // set by start(), before the thread
  std::thread thread_;
  Mutex run_mu_;
  CondVar run_cv_;
  bool running_ GUARDED_BY(run_mu_) = false;
};

}  // namespace rcan::node
