// MqttNode — rcand's MQTT transport (docs/FLEET.md): connects to a broker, subscribes to the
// robot's command topics (its RURI topics, and its fleet's), hands every inbound message to
// the one pipeline (Node::submit; the JWT travels in the envelope's auth_token) and publishes
// the answer on the matching reply topic. It also publishes the robot's retained status (the
// will says "offline"), telemetry, events, motion completions and the audit records, and runs
// the swarm agent (swarm.h) when a swarm is configured.
//
// Broker loss: the client fails over to the next `mqtt.broker` URL (a cluster's nodes), renews
// the subscriptions (the broker delivers a retained fleet ESTOP again) and the loss and the
// return are audited (MQTT_DISCONNECTED, MQTT_RECONNECTED with the URL). A fleet member still
// without a broker after `mqtt.failover_ms` has its motion stopped (STOP, audited).
//
// Delivery: commands and replies use QoS 1 on a persistent session (clean_session false), so a
// command published while the robot is briefly away still arrives; a redelivered or
// re-published command is refused by the replay window (REPLAY_DETECTED), never run twice.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "base/thread_annotations.h"
#include "config/fleet_config.h"
#include "rcan/crypto/keys.h"
#include "rcan/mqtt_topics.h"
#include "rcan/result.h"
#include "rcan/ruri.h"
#include "transport/mqtt_client.h"

namespace rcan::config {
struct NodeConfig;
}

namespace rcan::node {

class Node;
class NodeServices;
class SwarmAgent;

struct MqttNodeOptions {
  config::MqttConfig mqtt;
  config::FleetConfig fleet;
  config::SwarmConfig swarm;
  Ruri ruri;
  std::string password;      // read from mqtt.password_file
  std::string swarm_secret;  // read from swarm.secret_file
  // The robot's Ed25519 identity seed (<key_dir>/ed25519.seed): every reply, completion and
  // status it publishes is signed with it, so a coordinator believes no confirmation a topic
  // writer made up (docs/FLEET.md, "Signed replies"). Null: published unsigned.
  std::shared_ptr<const keys::SecretBytes> reply_key;
};

// The options from a validated configuration; reads mqtt.password_file and swarm.secret_file
// (neither may be group/world accessible).
Result<MqttNodeOptions> mqtt_node_options(const config::NodeConfig& cfg);

class MqttNode {
 public:
  MqttNode(Node& node, NodeServices& services, MqttNodeOptions opts);
  ~MqttNode();  // stop()
  MqttNode(const MqttNode&) = delete;
  MqttNode& operator=(const MqttNode&) = delete;

  // Connects (asynchronously: a broker that is down is retried with backoff) and starts the
  // publishing thread. Errors: bad topics, TLS setup.
  Status start();
  // Publishes "offline" (retained), disconnects, joins the threads. Idempotent.
  void stop() EXCLUDES(loop_mu_);

  bool connected() const;
  // Connected and every subscription granted (the fleet channel is up).
  bool subscribed() const;
  const mqtt::RobotTopics& robot() const { return robot_; }
  // The topics the robot publishes its status, telemetry, events and audit on: its fleet
  // member topics when it is in a fleet, else its RURI topics.
  const mqtt::RobotTopics& out() const { return out_; }

 private:
  void on_message(const transport::MqttMessage& msg);
  void on_connection(bool up, int code);
  void tick_channel(int64_t now_mono_ms);
  void submit(json::Value body, const std::string& route, const std::string& reply_topic,
              const std::string& fleet_id, const std::string& fleet_mode, bool standing_estop,
              int qos);
  void publish_json(const std::string& topic, const json::Value& v, int qos, bool retain);
  // A reply, completion or status as the robot vouches for it: its fleet and member named in it
  // and signed by its key (seed-shape canonical pre-image: reply_to and every field covered).
  json::Value vouched(json::Value v) const;
  void publish_status(bool online, const std::string& reason);
  void warn_about_exposure() const;
  void loop() EXCLUDES(loop_mu_, mu_);
  void tick_completions() EXCLUDES(mu_);
  void tick_audit();

  Node& node_;
  NodeServices& svc_;
  MqttNodeOptions opts_;
  mqtt::RobotTopics robot_;
  mqtt::RobotTopics out_;
  mqtt::FleetTopics fleet_;
  std::unique_ptr<transport::MqttClient> client_;
  std::unique_ptr<SwarmAgent> swarm_;

  struct Pending {
    std::string reply_topic;
    std::string message_id;
    std::string command;
    int64_t since_mono_ms = 0;
  };
  Mutex mu_;
  // Motions acknowledged, completion not yet published.
  std::vector<Pending> pending_ GUARDED_BY(mu_);
  uint64_t next_audit_seq_ = 0;  // the loop's (set by start() before it runs)
  uint64_t event_sub_ = 0;

  bool in_fleet_ = false;                  // set by start()
  std::atomic<int64_t> lost_since_ms_{0};  // mono ms the broker was lost at; 0: connected
  std::string last_url_;       // the network thread's: the URL last connected to (empty: never)
  bool channel_up_ = false;    // the network thread's
  int64_t deaf_since_ms_ = 0;  // the loop's: since when not every subscription is in place
  int64_t last_retry_ms_ = 0;  // the loop's: refused subscriptions last asked for again
  std::atomic<bool> running_{false};
  Mutex loop_mu_;
  CondVar loop_cv_;
  std::thread loop_;
};

}  // namespace rcan::node
