// Federation sync (docs/REGISTRY.md "Federation sync"): a root pulls the robots of the nodes it
// delegated prefixes to from their GET /api/v1/sync, on its own thread, into the store
// (Store::upsert_synced_robot), so that it resolves their RRNs itself. A node's records are
// taken only for the prefixes delegated to that node's URL, only under the node's own host, and
// never in place of a record of this registry's own.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "rcan/json.h"
#include "registry/store.h"

namespace rcan::registry::api {

// "YYYY-MM-DDTHH:MM:SS[.f…][Z]" → "YYYY-MM-DDTHH:MM:SS.mmmZ" (the store's form); nullopt else.
std::optional<std::string> normalize_iso(std::string_view s);

// A record of a sync answer → a robot (nullopt when a field is missing, malformed or oversized).
std::optional<Robot> robot_from_sync(const json::Value& record);

// A deletion in a sync answer (`deleted: true` or `status: "deleted"`, as a tombstone or as a
// whole record from an older node) → its RRN; nullopt for a live record or a malformed one.
std::optional<std::string> deletion_from_sync(const json::Value& record);

class SyncPuller {
 public:
  // `store` must outlive the puller. The first pull is one interval after start.
  // With `delegations`, every delegation's node_url is pulled too.
  // Called (on the puller's thread) for each record it wrote: the registry audits the change.
  using Imported = std::function<void(const Robot& robot, const std::string& from_url)>;
  SyncPuller(Store& store, std::vector<std::string> urls, int interval_ms, bool allow_http,
             bool delegations = false, Imported on_imported = {});
  ~SyncPuller();
  SyncPuller(const SyncPuller&) = delete;
  SyncPuller& operator=(const SyncPuller&) = delete;

  std::atomic<uint64_t> pulls{0}, failures{0}, imported{0}, refused{0};

 private:
  void run();
  void pull(const std::string& url);
  // Whether the copy `r` of a record of the node at `node_host` may be written (docs/THREATS.md
  // T2): "" when it may (its tier and times then set to this registry's own), else the reason
  // it is refused (uri_not_under_node, rrn_is_local, uri_taken).
  Result<std::string> judge(Robot& r, const std::string& node_host);
  // Applies the deletion of `rrn` told by the node at `url`: this registry's copy of it (pulled
  // before from that node, judged as above) is marked deleted and keeps none of its content.
  // "" when done or when there is no copy here, else the reason it is refused.
  Result<std::string> forget(const std::string& rrn, const std::string& node_host,
                             const std::string& url);

  Store& store_;
  std::vector<std::string> urls_;
  int interval_ms_;
  bool allow_http_;
  bool delegations_;
  Imported on_imported_;
  std::map<std::string, std::string> since_;        // per URL: next_since of its last answer
  std::map<std::string, std::string> fingerprint_;  // per URL: the prefixes delegated to it
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread worker_;
};

}  // namespace rcan::registry::api
