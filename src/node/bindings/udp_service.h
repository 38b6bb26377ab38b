// UDP service of the node (docs/TRANSPORT.md §UDP): HEARTBEAT datagrams that keep a control
// session's deadman alive, and DISCOVER → ANNOUNCE. One socket, one thread, POSIX sockets.
//
// Heartbeat keys: when heartbeats are on, start() installs ControlService's grant hook, so every
// GRANTED claim answer carries `udp_heartbeat: {port, session_id, key_id, key_b64,
// interval_ms}`. The key (32 random bytes) lives only in memory and dies with its session
// (release, expiry, pre-emption, a new claim). A heartbeat is accepted only with a known key
// id, a valid HMAC and a sequence number above every one accepted before for that key; it then
// feeds the session's deadman in the safety core (Actuation::feed_deadman) — the same
// deadman HTTP/WS/gRPC HEARTBEAT messages feed, so loss of heartbeats ends in the same
// NETWORK_LOSS_SAFE_STOP. Forged, replayed, malformed and stale datagrams are dropped
// silently and counted (metrics `rcan_udp_*`).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

class NodeServices;

struct UdpOptions {
  std::string bind_address = "127.0.0.1";
  uint16_t port = 8082;  // 0 = any free port
  bool heartbeat = true;
  bool discovery = true;
  uint32_t discovery_per_source_per_min = 30;
  uint32_t discovery_global_per_s = 50;
};

struct UdpStats {
  uint64_t heartbeats_accepted = 0;
  uint64_t heartbeats_forged = 0;    // unknown key id or bad HMAC
  uint64_t heartbeats_replayed = 0;  // sequence number not above the last accepted
  uint64_t heartbeats_stale = 0;     // valid, but the session has ended
  uint64_t malformed = 0;            // not a datagram of ours (or a kind we do not accept)
  uint64_t discover_answered = 0;
  uint64_t discover_limited = 0;
};

class UdpService {
 public:
  UdpService(UdpOptions opt, NodeServices& svc);
  ~UdpService();  // stop()
  UdpService(const UdpService&) = delete;
  UdpService& operator=(const UdpService&) = delete;

  // Binds, registers the metrics and (heartbeat on) the claim hook, starts the thread.
  Result<uint16_t> start();
  void stop();
  UdpStats stats() const;

  // Issues (or re-issues) the heartbeat key of a session: the `udp_heartbeat` object of the
  // GRANTED answer.
  json::Object grant(const std::string& session_id);

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace rcan::node
