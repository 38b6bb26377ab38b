// The `mqtt`, `fleet` and `swarm` configuration blocks (docs/CONFIG.md, docs/FLEET.md).
// Read by blocks/fleet.cpp; interpreted by mqtt_node.cpp, fleet.cpp and swarm.cpp.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "transport/mqtt_client.h"

namespace rcan::config {

struct MqttConfig {
  bool enabled = false;
  std::string broker = transport::kDefaultBrokerUrl;  // mqtt://host[:port] | mqtts://host[:port]
  // `mqtt.broker` given as a list: every URL in order (`broker` is the first), a cluster's nodes
  // tried round robin after a broker loss (docs/FLEET.md §Broker failover). Empty: `broker` alone.
  std::vector<std::string> brokers;
  std::vector<std::string> broker_urls() const {
    return brokers.empty() ? std::vector{broker} : brokers;
  }
  std::string client_id;  // default "rcand-<device_id>"
  std::string topic_prefix = "rcan";
  uint32_t keepalive_s = transport::kDefaultKeepaliveS;
  // Messages over MQTT need a token bound to a key (cnf) and a signature by that key: anyone
  // who can read a topic sees its tokens. false is a lab's explicit opt-out (warned at start).
  bool require_bound_tokens = true;
  std::string username;
  std::string password_file;  // 0600; required with username
  std::string ca_file;        // required with mqtts://
  std::string cert_file;      // client certificate (with key_file)
  std::string key_file;
  uint32_t reconnect_min_s = transport::kDefaultReconnectMinS;
  uint32_t reconnect_max_s = transport::kDefaultReconnectMaxS;
  uint32_t telemetry_hz = 1;  // 0 = no telemetry over MQTT
  bool publish_audit = true;  // audit records on the audit topic
  // QoS of the robot's subscription to its fleet's estop topic (docs/FLEET.md): 1 acts on the
  // first PUBLISH that arrives; 2 only after the PUBREL round trip through the broker; 0 takes
  // no acknowledgement (a large fleet on NATS, docs/FLEET.md §The fleet ESTOP at QoS 0): a copy
  // lost with the connection is made up by the retained ESTOP on the reconnect and by the
  // coordinator's sending it again to each member that has not confirmed.
  int estop_qos = 1;
  // The highest QoS of every publish and subscription (docs/FLEET.md §Brokers capped at QoS 1):
  // 1 for brokers without QoS 2. With 2, a broker's SUBACK granting less lowers it to 1.
  int max_qos = 2;
  // QoS of the robot's replies (answers and motion completions, docs/FLEET.md §Replies at QoS 0):
  // 1 is sent again after a reconnect; 0 is not, and costs a broker that keeps QoS 1 messages in
  // a replicated store (NATS: JetStream) a fraction of the work.
  int reply_qos = 1;
  // The longest a fleet member stays without its broker while it moves: past it (no URL took
  // it back) its motion is stopped, not latched, and audited, and again while the outage lasts.
  uint32_t failover_ms = 5000;
};

struct FleetConfig {
  std::string fleet_id;             // empty: the robot is in no fleet
  std::string member_id;            // this robot's name in `robots`; default the RURI device id
  std::vector<std::string> robots;  // the members (seed §2.3)
  std::string access_mode = "coordinated";  // coordinated | independent
  bool broadcast = true;                    // commands.broadcast
  bool individual = true;                   // commands.individual
  bool choreographed = true;                // commands.choreographed
};

struct SwarmConfig {     // the seed §5.2 keys of `swarm` (the other keys stay in NodeConfig::kept)
  std::string swarm_id;  // empty: no swarm
  std::string member_id;  // default the fleet member id, else the device id
  std::vector<std::string> members;
  std::string leader;  // default: the first member in sorted order
  std::string formation = "follow-leader";
  std::string join_policy = "closed";  // open | approval | closed
  uint32_t heartbeat_ms = 500;
  uint32_t leader_timeout_ms = 2000;  // a leader silent this long is replaced
  // The members' shared secret (a 0600 file, ≥ 32 bytes): announces and heartbeats carry an
  // HMAC under it, and a member drops what does not (docs/FLEET.md §Swarms). Required.
  std::string secret_file;
};

}  // namespace rcan::config
