// RobotDirectory — the other robots the dashboard's Robots view lists (config `dashboard.robots`,
// docs/DASHBOARD.md §Robots): their state, read from each node's public GET /api/discovery
// every `dashboard.poll_ms`, and a stop relayed to them.
//
// A relayed stop is POST /api/stop on the robot, carrying the operator's own Authorization
// header: the robot decides, by its own issuers and audiences, whether that token may stop it
// (any authenticated role may). A token goes only to the URLs of the configuration, never to a
// URL a request names. Both the poll and the relay block on the network: they run on their own
// threads, never on a transport thread.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "config/config.h"
#include "node/discovery/mdns_browse.h"
#include "rcan/json.h"
#include "runtime/http_client.h"

namespace rcan::node {

class RobotDirectory {
 public:
  // What one robot answered to a relayed stop.
  struct StopResult {
    std::string url;
    std::string result;  // "confirmed" (200, ESTOP latched), "refused", "unreachable", "timeout"
    int http_status = 0;
    std::string error_code;  // the robot's error code when it refused
    std::string detail;      // what went wrong, in words
    int64_t elapsed_ms = 0;
  };

  // `clock` (the node's) stamps the state and times the answers; it must outlive this.
  RobotDirectory(const config::DashboardConfig& cfg, const Clock& clock);
  ~RobotDirectory();
  RobotDirectory(const RobotDirectory&) = delete;
  RobotDirectory& operator=(const RobotDirectory&) = delete;

  // Starts the poll thread (when robots are configured) and the mDNS browser (dashboard.mdns).
  void start() EXCLUDES(mu_);
  void stop() EXCLUDES(mu_);

  bool configured(const std::string& url) const;
  const std::vector<std::string>& urls() const { return urls_; }
  // Each configured robot as last read: {url, name, ruri, model, version, status, reachable,
  // error, checked_ms, latency_ms}; status "unknown" before the first answer.
  json::Array snapshot() const EXCLUDES(mu_);
  // The rcand nodes announcing _rcan._tcp (dashboard.mdns), without the one whose RURI is
  // `self_ruri` and those already configured: {url, name, ruri, model, version, status,
  // interface, source: "mdns"}. Listed only: a stop is never relayed to them.
  json::Array discovered(const std::string& self_ruri) const;
  // "off" (dashboard.mdns false), "on", or why browsing is not possible.
  std::string mdns_state() const;
  // POST /api/stop on each of `urls` (configured ones only: the caller checked) at once, with
  // `authorization` and `reason`; returns when every robot answered or stop_timeout_ms passed.
  std::vector<StopResult> relay_stop(const std::vector<std::string>& urls,
                                     const std::string& authorization,
                                     const std::string& reason) const;

 private:
  struct State {
    std::string name, ruri, model, version;
    std::string status = "unknown";
    bool reachable = false;
    std::string error;
    int64_t checked_ms = 0;
    int64_t latency_ms = 0;
  };
  void loop() EXCLUDES(mu_);
  State read_one(const HttpUrl& base) const;

  config::DashboardConfig cfg_;
  const Clock& clock_;
  std::vector<std::string> urls_;
  std::vector<HttpUrl> bases_;
  mutable Mutex mu_;
  CondVar cv_;  // wakes the poller on stop()
  std::vector<State> states_ GUARDED_BY(mu_);
  bool quit_ GUARDED_BY(mu_) = false;
  std::thread poller_;
  std::unique_ptr<MdnsBrowser> mdns_;
};

}  // namespace rcan::node
