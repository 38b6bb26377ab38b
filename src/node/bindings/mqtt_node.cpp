#include "node/bindings/mqtt_node.h"

#include <pthread.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>

#include "base/clock.h"
#include "base/strings.h"
#include "config/config.h"
#include "node/api/node.h"
#include "node/fleet/swarm.h"
#include "node/services/node_services.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {

namespace {

const json::Value* field(const json::Value& v, const char* key) {
  return v.is_object() ? v.get(key) : nullptr;
}

std::string str_field(const json::Value& v, const char* key) {
  const json::Value* f = field(v, key);
  return f != nullptr && f->is_string() ? f->as_string() : std::string();
}

// Only a retained ESTOP stands on the fleet's estop topic; a retained RESUME or anything else
// is history and never acts on a robot that subscribes later.
bool is_estop_message(const json::Value& body) {
  std::string type = ascii_upper(str_field(body, "type"));
  if (type.empty()) type = ascii_upper(str_field(body, "message_type"));
  if (type != "SAFETY") return false;
  const json::Value* p = field(body, "payload");
  if (p == nullptr || !p->is_object()) return true;
  for (const char* k : {"safety_event", "action", "cmd", "command"}) {
    std::string w = ascii_upper(str_field(*p, k));
    if (!w.empty()) return w == "ESTOP" || w == "E_STOP" || w == "EMERGENCY_STOP";
  }
  return true;
}

bool is_loopback_host(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

// A secret file's text without its trailing newline: read by keys::read_secret_file (a
// regular file, 0600 or stricter), and `min`..`max` bytes long.
Result<std::string> read_private_file(const std::string& path, const std::string& what, size_t min,
                                      size_t max) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return Error(ErrorCode::kNotFound, "cannot read " + what + " " + path);
  auto secret = keys::read_secret_file(path);
  if (!secret.ok())
    return Error(secret.error().code, what + ": " + secret.error().message, what,
                 secret.error().reason);
  std::string text(reinterpret_cast<const char*>(secret->data()), secret->size());
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  if (text.size() < min || text.size() > max)
    return Error(ErrorCode::kSchemaValidationFailed, what + " must hold " + std::to_string(min) +
                                                         " to " + std::to_string(max) + " bytes");
  return text;
}

}  // namespace

Result<MqttNodeOptions> mqtt_node_options(const config::NodeConfig& cfg) {
  MqttNodeOptions o;
  o.mqtt = cfg.mqtt;
  o.fleet = cfg.fleet;
  o.swarm = cfg.swarm;
  o.ruri = cfg.ruri_parts;
  if (!cfg.mqtt.password_file.empty()) {
    auto pw = read_private_file(cfg.mqtt.password_file, "mqtt.password_file", 1, 1024);
    if (!pw.ok()) return pw.error();
    o.password = std::move(pw).value();
  }
  if (!cfg.swarm.swarm_id.empty()) {
    auto secret = read_private_file(cfg.swarm.secret_file, "swarm.secret_file", 32, 4096);
    if (!secret.ok()) return secret.error();
    o.swarm_secret = std::move(secret).value();
  }
  return o;
}

MqttNode::MqttNode(Node& node, NodeServices& services, MqttNodeOptions opts)
    : node_(node), svc_(services), opts_(std::move(opts)) {}

MqttNode::~MqttNode() { stop(); }

bool MqttNode::connected() const { return client_ && client_->connected(); }

Status MqttNode::start() {
  const auto& mq = opts_.mqtt;
  auto rt = mqtt::robot_topics(mq.topic_prefix, opts_.ruri);
  if (!rt.ok()) return rt.error();
  robot_ = *rt;
  out_ = robot_;
  const bool in_fleet = !opts_.fleet.fleet_id.empty();
  in_fleet_ = in_fleet;
  if (in_fleet) {
    fleet_ = mqtt::fleet_topics(mq.topic_prefix, opts_.fleet.fleet_id);
    out_ = fleet_.member(opts_.fleet.member_id);
  }

  transport::MqttOptions co;
  co.url = mq.broker;
  co.urls = mq.broker_urls();  // a cluster's nodes: failover, round robin
  co.client_id = mq.client_id.empty() ? "rcand-" + opts_.ruri.device_id : mq.client_id;
  co.clean_session = false;  // QoS 1 commands sent during a short absence still arrive
  co.keepalive_s = static_cast<int>(mq.keepalive_s);
  co.username = mq.username;
  co.password = opts_.password;
  co.ca_file = mq.ca_file;
  co.cert_file = mq.cert_file;
  co.key_file = mq.key_file;
  co.reconnect_min_s = static_cast<int>(mq.reconnect_min_s);
  co.reconnect_max_s = static_cast<int>(mq.reconnect_max_s);
  co.max_qos = mq.max_qos;  // every publish and subscription at most this (brokers without QoS 2)
  co.will.topic = out_.status();
  co.will.payload = json::dump(vouched(json::Value(json::Object{{"online", false},
                                                                {"ruri", svc_.settings.ruri},
                                                                {"member", opts_.fleet.member_id},
                                                                {"reason", "connection_lost"}})));
  co.will.qos = 1;
  co.will.retain = true;
  client_ = std::make_unique<transport::MqttClient>(co);
  client_->subscribe(robot_.cmd(), 1);
  if (in_fleet) {
    client_->subscribe(fleet_.cmd(), 1);
    client_->subscribe(fleet_.estop(), mq.estop_qos);  // 1 by default: act on the first copy
    client_->subscribe(out_.cmd(), 1);
  }
  if (!opts_.swarm.swarm_id.empty()) {
    swarm_ = std::make_unique<SwarmAgent>(
        svc_, opts_.swarm, opts_.swarm_secret, mq.topic_prefix,
        [this](const std::string& topic, const json::Value& body, int qos, bool retain) {
          publish_json(topic, body, qos, retain);
        },
        mq.require_bound_tokens,
        svc_.settings.state_dir.empty() ? "" : svc_.settings.state_dir + "/swarm.json");
    for (const auto& f : swarm_->subscriptions()) client_->subscribe(f, 1);
  }
  client_->on_message([this](const transport::MqttMessage& m) { on_message(m); });
  client_->on_connection([this](bool up, int code) { on_connection(up, code); });

  if (mq.publish_audit) {
    auto st = svc_.audit.stats();
    next_audit_seq_ = st.last_seq == 0 ? 1 : st.last_seq;  // from the latest record on
  }
  // The events topic is shared by whoever may subscribe to it at the broker: it carries the
  // events for everyone, never one principal's or the owners' (event_bus.h). QoS 0, like
  // telemetry: a live feed, whose durable twin is the audit topic (QoS 1). On a broker that
  // keeps QoS 1 messages in a replicated store (NATS: JetStream) an event at QoS 1 doubled what
  // a fleet ESTOP cost the cluster (docs/FLEET.md §Benchmark).
  event_sub_ = svc_.events.subscribe([this](const Event& ev) {
    if (ev.audience.is_everyone()) publish_json(out_.events(), ev.body, 0, false);
  });
  warn_about_exposure();
  running_.store(true);
  if (Status s = client_->start(); !s.ok()) {
    running_.store(false);
    svc_.events.unsubscribe(event_sub_);
    return s;
  }
  loop_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "mqtt-node");
    loop();
  });
  log(LogLevel::kInfo, "mqtt_started",
      json::Object{{"broker", mq.broker},
                   {"brokers", static_cast<int64_t>(co.urls.size())},
                   {"cmd_topic", robot_.cmd()},
                   {"status_topic", out_.status()}});
  return Status::Ok();
}

bool MqttNode::subscribed() const { return client_ && client_->all_subscribed(); }

// What a reader of the broker's traffic could do with this configuration, said once at start.
void MqttNode::warn_about_exposure() const {
  const auto& mq = opts_.mqtt;
  if (!mq.require_bound_tokens)
    log(LogLevel::kWarn, "mqtt_unbound_tokens_accepted",
        json::Object{{"note",
                      "mqtt.require_bound_tokens is false: whoever reads a topic can reuse the "
                      "tokens on it to send commands of their own (lab use only)"}});
  for (const auto& url : mq.broker_urls()) {
    auto u = transport::parse_broker_url(url);
    if (u.ok() && !u->tls && !is_loopback_host(u->host))
      log(LogLevel::kWarn, "mqtt_plaintext_broker",
          json::Object{{"broker", url},
                       {"note",
                        "mqtt:// off loopback: tokens, commands and telemetry cross the network "
                        "unencrypted; use mqtts:// with tls.ca_file"}});
  }
}

void MqttNode::stop() {
  if (!running_.exchange(false)) return;
  { MutexLock lk(loop_mu_); }
  loop_cv_.notify_all();
  if (loop_.joinable()) loop_.join();
  svc_.events.unsubscribe(event_sub_);
  if (client_->connected()) {
    publish_status(false, "shutdown");  // a clean disconnect sends no will: say it ourselves
    client_->flush(1000);
  }
  client_->stop();
}

// Runs on the client's network thread. The loss and the return of the broker are audited once
// per outage (a broker refusing every attempt writes one record, not one per attempt), with the
// URL: after a failover the return names the node the robot is on now.
void MqttNode::on_connection(bool up, int code) {
  const std::string url = client_->current_url();
  const int64_t now = svc_.clock.mono_ms();
  // The swarm hears of it before the loop is woken. The client says connected before this
  // callback runs, so a tick may come first; the swarm does not judge until it has heard.
  if (swarm_ && up) swarm_->on_connected(now);
  if (swarm_ && !up) swarm_->on_disconnected();
  {
    MutexLock wake(loop_mu_);  // the loop watches the channel from now on (tick_channel)
  }
  loop_cv_.notify_all();
  if (up) {
    publish_status(true, "connected");
    const int64_t since = lost_since_ms_.exchange(0);
    const bool again = !last_url_.empty();
    const bool failover = again && url != last_url_;
    channel_up_ = true;
    log(LogLevel::kInfo, "mqtt_connected",
        json::Object{{"connects", static_cast<int64_t>(client_->connects())},
                     {"broker", url},
                     {"failover", failover}});
    AuditRecord r = svc_.trail.record(again ? "MQTT_RECONNECTED" : "MQTT_CONNECTED").by_system();
    r.detail("broker", url).detail("connects", static_cast<int64_t>(client_->connects()));
    if (again)
      r.detail("previous_broker", last_url_)
          .detail("failover", failover)
          .detail("down_ms", now - since);
    r.write();
    last_url_ = url;
  } else if (running_.load()) {
    log(LogLevel::kWarn, "mqtt_disconnected",
        json::Object{{"broker", url},
                     {"code", static_cast<int64_t>(code)},
                     {"note", "reconnecting (failover to the next broker URL, then backoff)"}});
    if (!channel_up_) return;  // the same outage
    channel_up_ = false;
    lost_since_ms_.store(now);
    svc_.trail.record("MQTT_DISCONNECTED", "degraded")
        .by_system()
        .reason(in_fleet_ ? "fleet_channel_lost" : "broker_lost")
        .detail("broker", url)
        .detail("code", static_cast<int64_t>(code))
        .detail("failover_ms", static_cast<int64_t>(opts_.mqtt.failover_ms))
        .write();
  }
}

// A fleet member without its broker cannot hear a fleet ESTOP, nor can one whose subscriptions a
// clustered broker refused (NATS refuses them for a few seconds after losing a node, while it
// elects new stream leaders): those are asked for again every 500 ms. Past mqtt.failover_ms
// without every subscription in place, a moving robot is stopped (not latched: the fleet's
// order, if any, comes back with the channel as the retained ESTOP), and again whenever it moves
// while that lasts.
void MqttNode::tick_channel(int64_t now) {
  if (client_->connected() && !client_->refused_subscriptions().empty() &&
      now - last_retry_ms_ >= 500) {
    last_retry_ms_ = now;
    const std::string topic = client_->refused_subscriptions().front();
    log(LogLevel::kWarn, "mqtt_subscription_refused",
        json::Object{{"broker", client_->current_url()},
                     {"topic", topic},
                     {"note", topic.find('.') == std::string::npos
                                  ? "asking again every 500 ms"
                                  : "asking again every 500 ms; NATS never grants a topic with "
                                    "a '.': use fleet, member and swarm ids without one"}});
    client_->retry_refused();
  }
  if (client_->all_subscribed()) {
    deaf_since_ms_ = 0;
    return;
  }
  if (deaf_since_ms_ == 0) deaf_since_ms_ = now;
  if (!in_fleet_ || now - deaf_since_ms_ < static_cast<int64_t>(opts_.mqtt.failover_ms)) return;
  if (json::bool_field(svc_.act.telemetry(), "stopped")) return;
  svc_.act.stop("fleet_channel_lost");
  log(LogLevel::kWarn, "fleet_channel_stop",
      json::Object{{"down_ms", now - deaf_since_ms_}, {"broker", client_->current_url()}});
  svc_.trail.record("STOP", "ok")
      .by_system()
      .reason("fleet_channel_lost")
      .detail("down_ms", now - deaf_since_ms_)
      .detail("failover_ms", static_cast<int64_t>(opts_.mqtt.failover_ms))
      .detail("broker", client_->current_url())
      .detail("connected", client_->connected())
      .write();
}

void MqttNode::publish_json(const std::string& topic, const json::Value& v, int qos, bool retain) {
  if (!client_) return;
  if (Status s = client_->publish(topic, json::dump(v), qos, retain); !s.ok())
    log(LogLevel::kDebug, "mqtt_publish_failed",
        json::Object{{"topic", topic}, {"error", s.error().message}});
}

json::Value MqttNode::vouched(json::Value v) const {
  if (!v.is_object()) return v;
  json::Object& o = v.as_object();
  if (in_fleet_) {
    o.set("fleet_id", opts_.fleet.fleet_id);
    o.set("member", opts_.fleet.member_id);
  }
  if (opts_.reply_key)
    if (Status s = msgsig::sign_ed25519(o, opts_.reply_key->span()); !s.ok())
      log(LogLevel::kWarn, "mqtt_reply_unsigned", json::Object{{"error", s.error().message}});
  return v;
}

void MqttNode::publish_status(bool online, const std::string& reason) {
  json::Object o{{"online", online},
                 {"ruri", svc_.settings.ruri},
                 {"member", opts_.fleet.member_id},
                 {"fleet_id", opts_.fleet.fleet_id},
                 {"estop_active", svc_.act.estop_active()},
                 {"reason", reason},
                 {"timestamp_ms", svc_.clock.wall_ms()}};
  publish_json(out_.status(), vouched(json::Value(std::move(o))), 1, true);
}

void MqttNode::on_message(const transport::MqttMessage& msg) {
  mqtt::InboundTopic t = mqtt::parse_topic(opts_.mqtt.topic_prefix, msg.topic);
  if (t.kind == mqtt::TopicKind::kOther && msg.topic != robot_.cmd()) return;
  if (msg.payload.empty()) return;  // a cleared retained message
  const bool own_fleet = !opts_.fleet.fleet_id.empty() && t.fleet_id == opts_.fleet.fleet_id;
  std::string reply_topic;
  std::string fleet_id, fleet_mode;
  switch (t.kind) {
    case mqtt::TopicKind::kRobotCmd:
      if (msg.topic != robot_.cmd()) return;
      reply_topic = robot_.reply();
      break;
    case mqtt::TopicKind::kFleetCmd:
      if (!own_fleet) return;
      reply_topic = out_.reply();
      fleet_id = t.fleet_id;
      fleet_mode = "broadcast";
      break;
    case mqtt::TopicKind::kFleetEstop:
      if (!own_fleet) return;
      reply_topic = out_.reply();
      fleet_id = t.fleet_id;
      fleet_mode = "estop";
      break;
    case mqtt::TopicKind::kMemberCmd:
      if (!own_fleet || t.member != opts_.fleet.member_id) return;
      reply_topic = out_.reply();
      fleet_id = t.fleet_id;
      fleet_mode = "individual";
      break;
    case mqtt::TopicKind::kSwarmAnnounce:
    case mqtt::TopicKind::kSwarmHeartbeat:
    case mqtt::TopicKind::kSwarmJoin: {
      if (!swarm_ || t.swarm_id != opts_.swarm.swarm_id) return;
      auto body = mqtt::parse_payload(msg.payload);
      if (body.ok()) swarm_->on_message(t, *body, svc_.clock.mono_ms());
      return;
    }
    case mqtt::TopicKind::kOther:
      return;
  }
  auto body = mqtt::parse_payload(msg.payload);
  if (!body.ok()) {
    publish_json(reply_topic, vouched(svc_.error(body.error())), opts_.mqtt.reply_qos, false);
    return;
  }
  // Commands are never retained: a retained message on a command topic is stale history.
  bool standing = false;
  if (msg.retained) {
    if (t.kind != mqtt::TopicKind::kFleetEstop || !is_estop_message(*body)) return;
    standing = true;
  }
  submit(std::move(body).value(), msg.topic, reply_topic, fleet_id, fleet_mode, standing, msg.qos);
}

void MqttNode::submit(json::Value body, const std::string& route, const std::string& reply_topic,
                      const std::string& fleet_id, const std::string& fleet_mode,
                      bool standing_estop, int qos) {
  const bool is_command = ascii_upper(str_field(body, "type")) == "COMMAND" ||
                          ascii_upper(str_field(body, "type")) == "FLEET_COMMAND" ||
                          field(body, "cmd") != nullptr;
  Ingress in;
  in.body = std::move(body);  // a fleet message with an ML-DSA signature is some 8 KiB
  in.transport = "mqtt";
  in.route = route;
  in.remote = "mqtt";
  in.fleet_id = fleet_id;
  in.fleet_mode = fleet_mode;
  in.standing_estop = standing_estop;
  in.mqtt_qos = qos;
  in.require_bound_key = opts_.mqtt.require_bound_tokens;
  in.may_commit_audit = true;  // the client's network thread: this robot's connection alone
  in.received_mono_us = steady_us();
  node_.submit(std::move(in), [this, reply_topic, is_command](Outcome out) {
    if (!running_.load()) return;
    const json::Value& b = out.body;
    // The answer is queued on the connection before its completion can be: the loop publishes
    // COMPLETED as soon as it sees the command pending and the robot at rest (at once for a
    // `status`), and an EVENT overtaking its ACK made `rcan fleet command` report a member that
    // had acknowledged as failed.
    publish_json(reply_topic, vouched(b), opts_.mqtt.reply_qos, false);
    if (is_command && out.status == 200 && str_field(b, "type") == "ACK") {
      const json::Value* p = field(b, "payload");
      std::string cmd = p != nullptr ? str_field(*p, "command") : std::string();
      if (!cmd.empty()) {
        {
          MutexLock lk(mu_);
          pending_.push_back(
              Pending{reply_topic, str_field(b, "reply_to"), cmd, svc_.clock.mono_ms()});
        }
        { MutexLock wake(loop_mu_); }  // the loop is waiting, or sees pending_ next
        loop_cv_.notify_all();
      }
    }
  });
}

void MqttNode::loop() {
  const int64_t telemetry_period =
      opts_.mqtt.telemetry_hz > 0 ? static_cast<int64_t>(1000 / opts_.mqtt.telemetry_hz) : 0;
  int64_t last_telemetry = 0;
  MutexLock lk(loop_mu_);
  while (running_.load()) {
    // Wake often only while there is something to watch: a motion to complete (20 ms), the
    // swarm's heartbeat, telemetry, new audit records, a channel not (yet) up; otherwise every
    // 5 s (on_connection() wakes the loop at once when the broker goes or comes back).
    int64_t wait_ms = client_->all_subscribed() ? 5000 : 1000;
    {
      MutexLock plk(mu_);
      if (!pending_.empty()) wait_ms = 20;
    }
    if (swarm_)
      wait_ms = std::min<int64_t>(wait_ms, std::max<int64_t>(10, opts_.swarm.heartbeat_ms / 4));
    if (telemetry_period > 0) wait_ms = std::min<int64_t>(wait_ms, telemetry_period);
    if (opts_.mqtt.publish_audit) wait_ms = std::min<int64_t>(wait_ms, 100);
    if (deaf_since_ms_ != 0) wait_ms = std::min<int64_t>(wait_ms, 50);
    loop_cv_.wait_for(loop_mu_, std::chrono::milliseconds(wait_ms));
    if (!running_.load()) break;
    int64_t now = svc_.clock.mono_ms();
    tick_channel(now);
    tick_completions();
    if (opts_.mqtt.publish_audit) tick_audit();
    if (swarm_ && client_->connected())
      swarm_->tick(now, client_->granted(swarm_->hearing_subscriptions()));
    if (telemetry_period > 0 && now - last_telemetry >= telemetry_period && client_->connected()) {
      last_telemetry = now;
      publish_json(out_.telemetry(), svc_.act.telemetry(), 0, false);
    }
  }
}

// A motion is complete when the robot has stopped; it is aborted when an ESTOP latched first.
void MqttNode::tick_completions() {
  std::vector<Pending> done;
  {
    MutexLock lk(mu_);
    if (pending_.empty()) return;
    json::Value tel = svc_.act.telemetry();
    if (!json::bool_field(tel, "stopped") && !svc_.act.estop_active()) return;
    done.swap(pending_);
  }
  bool estop = svc_.act.estop_active();
  for (const auto& p : done) {
    json::Object payload{{"event", estop ? "ABORTED" : "COMPLETED"},
                         {"command", p.command},
                         {"member", opts_.fleet.member_id},
                         {"ruri", svc_.settings.ruri}};
    if (estop) payload.set("reason", "estop_active");
    publish_json(p.reply_topic,
                 vouched(svc_.envelope(MessageType::kEvent, std::move(payload), p.message_id)),
                 opts_.mqtt.reply_qos, false);
  }
}

void MqttNode::tick_audit() {
  if (!client_->connected()) return;
  uint64_t last = svc_.audit.stats().last_seq;
  for (int n = 0; next_audit_seq_ <= last && n < 256; ++n, ++next_audit_seq_) {
    auto line = svc_.audit.get(next_audit_seq_);
    if (!line.ok()) continue;  // removed by retention
    std::string text = *line;
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
    if (Status s = client_->publish(out_.audit(), text, 1, false); !s.ok()) return;
  }
}

}  // namespace rcan::node
