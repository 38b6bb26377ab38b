// MdnsAdvertiser — publishes the node as `_rcan._tcp` through the Avahi daemon (seed §1.3)
// with the TXT keys of docs/PROTOCOL.md (ruri, model, caps, roles, role, version, name,
// status; plus tls=1 on an HTTPS node), and keeps `status` current: "estop" while ESTOP is
// latched, "claimed" while a control session holds the robot, else "available".
//
// The node keeps running without mDNS: when no Avahi daemon (or no D-Bus) can be reached it
// logs `mdns_unavailable` once; if the daemon appears (or restarts) later, the service is
// (re)published. Status is re-read on every node event (EventBus) and once a second.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace rcan::node {

class NodeServices;

struct MdnsInfo {
  std::string name;  // service instance name
  uint16_t port = 0;
  std::vector<std::string> txt;         // fixed "key=value" items (without status)
  std::function<std::string()> status;  // current status word
};

// The node's discovery status word: "estop", "claimed" or "available" (mDNS TXT `status` and
// GET /api/discovery).
std::string status_word(NodeServices& services);

// The fixed TXT items and status function for a node.
MdnsInfo mdns_info_for(NodeServices& services, bool tls);

class MdnsAdvertiser {
 public:
  explicit MdnsAdvertiser(MdnsInfo info);
  ~MdnsAdvertiser();
  MdnsAdvertiser(const MdnsAdvertiser&) = delete;
  MdnsAdvertiser& operator=(const MdnsAdvertiser&) = delete;

  // Starts publishing (non-blocking). Never fails the node.
  void start();
  // Re-reads the status now (called from EventBus subscribers; only signals a thread).
  void poke();
  void stop();
  // Runs once at stop() (start_mdns uses it to leave the EventBus).
  void set_on_stop(std::function<void()> fn);

  // The status last published ("" before the first publication).
  std::string published_status() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// Starts an advertiser for `services`, re-reading status on each of its events.
std::unique_ptr<MdnsAdvertiser> start_mdns(NodeServices& services, bool tls);

}  // namespace rcan::node
