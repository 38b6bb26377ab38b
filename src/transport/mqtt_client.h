// MqttClient — a small MQTT 3.1.1 client over libmosquitto, used by rcand's MQTT transport
// (src/node/bindings/mqtt_node.h) and by `rcan fleet` (docs/FLEET.md).
//
// The client runs one network thread (libmosquitto's mosquitto_loop, driven by us): it keeps the
// connection, answers keep-alives and reconnects after a broker loss. With one broker URL it
// retries that broker with exponential backoff (reconnect_min_s doubling up to reconnect_max_s).
// With several (MqttOptions::urls, a cluster's nodes) it fails over: after a loss it tries the
// next URL at once, round robin, each URL of the first round without delay, then every round
// after a backoff delay (reconnect_min_s doubling up to reconnect_max_s). Subscriptions are
// renewed on every (re)connect, so a broker delivers its retained messages again. The callbacks
// run on that thread; publish() may be called from any thread.
//
// QoS: every publish and subscription is capped at MqttOptions::max_qos. A broker without QoS 2
// grants QoS 1 to a QoS 2 subscription, or refuses it, and may drop the connection on a QoS 2
// PUBLISH (NATS 2.9 does both): a SUBACK that grants less than QoS 2 to a QoS 2
// request lowers the cap to 1 for the rest of the client's life (qos_cap()), and a refused QoS 2
// subscription is renewed at QoS 1. publish_confirmed() reports whether the broker
// acknowledged one publish (PUBACK / PUBCOMP) before the connection dropped.
//
// This header includes no libmosquitto: keep it that way.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "rcan/result.h"

namespace rcan::transport {

struct BrokerUrl {
  std::string host;
  uint16_t port = 1883;
  bool tls = false;
};
// "mqtt://host[:port]" (default 1883) or "mqtts://host[:port]" (default 8883). IPv6 literals
// in brackets. Errors: kSchemaValidationFailed.
Result<BrokerUrl> parse_broker_url(std::string_view url);

struct MqttWill {
  std::string topic;  // empty: no will
  std::string payload;
  int qos = 1;
  bool retain = true;
};

// Defaults, also those of rcand's `mqtt` block (config/fleet_config.h).
inline constexpr const char* kDefaultBrokerUrl = "mqtt://127.0.0.1:1883";
inline constexpr int kDefaultKeepaliveS = 10;
inline constexpr int kDefaultReconnectMinS = 1;
inline constexpr int kDefaultReconnectMaxS = 30;

struct MqttOptions {
  std::string url = kDefaultBrokerUrl;
  // Failover: the broker URLs tried in turn (all mqtt:// or all mqtts://); empty → {url}.
  std::vector<std::string> urls;
  std::string client_id;  // empty → random (a clean session is then forced)
  bool clean_session = true;
  int keepalive_s = kDefaultKeepaliveS;
  std::string username;
  std::string password;   // read from a 0600 file by the caller
  std::string ca_file;    // TLS: CA bundle (required with mqtts)
  std::string cert_file;  // TLS client certificate (optional, with key_file)
  std::string key_file;
  int reconnect_min_s = kDefaultReconnectMinS;
  int reconnect_max_s = kDefaultReconnectMaxS;
  MqttWill will;
  int max_qos = 2;  // 1 for brokers capped at QoS 1 (config mqtt.max_qos, `rcan fleet --qos`)
  // A SUBACK granting less than a requested QoS 2 lowers qos_cap() to 1. False: QoS 2 stays,
  // whatever the broker grants (`rcan fleet --qos 2` forces it).
  bool downgrade_on_suback = true;
  std::string thread_name = "mqtt-io";  // the network thread's name (at most 15 characters)
};

struct MqttMessage {
  std::string topic;
  std::string payload;
  int qos = 0;
  bool retained = false;
};

class MqttClient {
 public:
  using OnMessage = std::function<void(const MqttMessage&)>;
  using OnConnection = std::function<void(bool connected, int code)>;

  explicit MqttClient(MqttOptions opts);
  ~MqttClient();  // stop()
  MqttClient(const MqttClient&) = delete;
  MqttClient& operator=(const MqttClient&) = delete;

  // Set before start().
  void on_message(OnMessage cb) { on_message_ = std::move(cb); }
  void on_connection(OnConnection cb) { on_connection_ = std::move(cb); }
  // Adds a subscription (renewed on every connect; subscribed now when connected).
  void subscribe(const std::string& filter, int qos) EXCLUDES(mu_);

  // Starts the network thread and connects asynchronously (a broker that is not up yet is
  // retried with backoff). Errors: bad options, TLS files unreadable.
  Status start();
  // Publishes (queued by libmosquitto while disconnected for QoS > 0). Errors when the
  // payload is too large or the client is stopped.
  Status publish(const std::string& topic, const std::string& payload, int qos, bool retain);
  // Publishes at QoS min(qos, qos_cap()) (at least 1) and waits up to `timeout_ms` for the
  // broker's acknowledgement of this message: PUBACK at QoS 1, PUBCOMP at QoS 2. Errors
  // (kInternal) when not connected, when the connection drops first (a broker refusing the
  // publish closes it: MQTT 3.1.1 has no negative acknowledgement) or at the timeout.
  // `dropped`, when given, tells a lost or missing connection apart: the caller may publish
  // again once reconnected.
  Status publish_confirmed(const std::string& topic, const std::string& payload, int qos,
                           bool retain, int timeout_ms, bool* dropped = nullptr);
  // Waits up to `timeout_ms` until connected and every subscription sent so far is answered by
  // a SUBACK. False on timeout.
  bool wait_subscribed(int timeout_ms);
  // The highest QoS publishes use: max_qos, lowered to 1 by a SUBACK that granted less than a
  // requested QoS 2.
  int qos_cap() const { return qos_cap_.load(); }
  // Connected, and every subscription answered by a SUBACK that did not refuse it.
  bool all_subscribed() const EXCLUDES(mu_);
  // The same for `filters` alone (subscribed earlier with subscribe()).
  bool granted(const std::vector<std::string>& filters) const EXCLUDES(mu_);
  // Subscriptions the broker refused (SUBACK 0x80) at QoS 1 or 0.
  std::vector<std::string> refused_subscriptions() const EXCLUDES(mu_);
  // Sends the refused subscriptions again (a clustered broker refuses while it elects a new
  // leader for its session and retained-message streams); wait_subscribed() then waits for them.
  void retry_refused() EXCLUDES(mu_);
  // Waits up to `timeout_ms` until every QoS 1/2 message published so far is acknowledged by
  // the broker. False on timeout.
  bool flush(int timeout_ms);
  // Disconnects cleanly (no will) and joins the network thread. Idempotent.
  void stop();

  bool connected() const { return connected_.load(); }
  uint64_t connects() const { return connects_.load(); }
  // The URL the client is connected to, or trying now.
  std::string current_url() const;

  struct Impl;

 private:
  MqttOptions opts_;
  OnMessage on_message_;
  OnConnection on_connection_;
  mutable Mutex mu_;
  std::vector<std::pair<std::string, int>> subs_ GUARDED_BY(mu_);
  void sent_subscribe(int mid, const std::string& filter, int qos) EXCLUDES(mu_);
  void got_suback(int mid, int granted) EXCLUDES(mu_);
  std::atomic<int> qos_cap_{2};
  CondVar cv_;
  std::map<int, std::pair<std::string, int>> sub_pending_ GUARDED_BY(mu_);  // mid → filter, QoS
  std::map<int, int> sub_early_ GUARDED_BY(mu_);  // SUBACKs that arrived before their mid was noted
  std::vector<std::string> sub_refused_ GUARDED_BY(mu_);
  uint64_t ready_connects_ GUARDED_BY(mu_) = 0;  // connects whose subscriptions were all sent
  std::set<int> acked_ GUARDED_BY(mu_);          // acknowledged mids, kept while someone waits
  int confirm_waiters_ GUARDED_BY(mu_) = 0;
  uint64_t drops_ GUARDED_BY(mu_) = 0;  // connection losses
  std::atomic<bool> connected_{false};
  std::atomic<uint64_t> connects_{0};
  std::atomic<bool> stopped_{false};
  std::atomic<int64_t> inflight_{0};  // QoS > 0 publishes not yet acknowledged
  std::atomic<size_t> at_{0};         // index of the URL in use (Impl::urls)
  bool started_ = false;
  std::unique_ptr<Impl> impl_;
  void run();  // the network thread
  friend struct MqttCallbacks;
};

}  // namespace rcan::transport
