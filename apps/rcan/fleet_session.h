// The fleet verbs' MQTT session (apps/rcan/fleet_cmd.cpp): one client with an inbox, its
// subscriptions answered before anything is published, and a publish that survives a dropped
// connection by publishing again on a new one (docs/FLEET.md, "A fleet ESTOP never reports
// success it did not get").
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "base/clock.h"
#include "cli.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcan/mqtt_topics.h"
#include "transport/mqtt_client.h"

namespace rcan::cli::fleet {

inline int64_t mono_ms() { return steady_ms(); }

// The fleet's robots and their public keys: --members-dir DIR (or $RCAN_FLEET_MEMBERS_DIR), one
// directory per member, named by its member id, holding the public half of that robot's
// Ed25519 identity key — ed25519.pub, copied from the robot's security.key_dir
// (docs/FLEET.md, "Signed replies"). A member's reply or status counts only when that robot's key
// signed it, over the seed-shape canonical pre-image (every field: reply_to too), and it names
// the fleet and the member: anyone who can write the broker's topics can publish a reply, and
// a robot's genuine reply copied onto another member's topic, or to another ESTOP, no longer
// verifies.
class FleetMembers {
 public:
  static Result<FleetMembers> load(const std::string& dir) {
    FleetMembers out;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
      const std::string name = e.path().filename().string();
      if (!e.is_directory() || name.empty() || name[0] == '.') continue;
      if (!mqtt::valid_topic_segment(name))
        return Error(ErrorCode::kSchemaValidationFailed,
                     "--members-dir " + dir + ": " + name + " is not a valid member id");
      // Robots sign their replies with their Ed25519 key (one signature per reply, after the
      // latch): that is the key to know.
      const auto path = e.path() / "ed25519.pub";
      if (!std::filesystem::exists(path))
        return Error(ErrorCode::kSchemaValidationFailed,
                     "--members-dir " + dir + ": " + name +
                         " holds no ed25519.pub (the robot's public key, from its key_dir)");
      auto raw = read_file(path.string());
      if (!raw.ok()) return raw.error();
      if (raw->size() != 32)
        return Error(ErrorCode::kSchemaValidationFailed,
                     path.string() + " is not a raw Ed25519 public key (32 bytes)");
      msgsig::TrustedKeys k;
      k.ed25519.emplace_back(raw->begin(), raw->end());
      out.keys_[name] = std::move(k);
    }
    if (ec) return Error(ErrorCode::kNotFound, "cannot read --members-dir " + dir);
    if (out.keys_.empty())
      return Error(ErrorCode::kSchemaValidationFailed,
                   "--members-dir " + dir + " names no member (one directory per robot)");
    return out;
  }
  bool knows(const std::string& member) const { return keys_.count(member) != 0; }
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& [m, k] : keys_) out.push_back(m);
    return out;
  }
  // Whether `body`, from <fleet>/robot/<member>/(reply|status), is that robot's word.
  Status verify(const std::string& fleet_id, const std::string& member,
                const json::Value& body) const {
    auto k = keys_.find(member);
    if (k == keys_.end())
      return Error(ErrorCode::kSignatureInvalid, "no key for this member in --members-dir");
    if (!body.is_object() || msgsig::signature_member(body.as_object()) == nullptr)
      return Error(ErrorCode::kAuthRequired, "unsigned");
    // Only the pre-image that covers every field: rcan-py's covers six, reply_to not among them.
    if (msgsig::preimage_kind(body.as_object()) != msgsig::Preimage::kCanonical)
      return Error(ErrorCode::kSignatureInvalid, "not a canonical (whole-message) signature");
    if (json::string_field(body, "fleet_id") != fleet_id ||
        json::string_field(body, "member") != member)
      return Error(ErrorCode::kSignatureInvalid, "names another fleet or member");
    auto v = msgsig::verify_block(body.as_object(), k->second);
    if (!v.ok()) return Error(ErrorCode::kSignatureInvalid, "bad signature: " + v.error().message);
    return Status::Ok();
  }

 private:
  std::map<std::string, msgsig::TrustedKeys> keys_;
};

// A connected client with an inbox.
class Session {
 public:
  struct Inbound {
    std::string topic;
    json::Value body;
    bool retained = false;
  };

  // From now on a message on <base>/robot/<member>/reply or …/status reaches the inbox only when
  // `members` vouches for it (FleetMembers::verify); the others are dropped and counted per
  // member (dropped()). Null `members`: none is believed. Call before open().
  void vouched_by(const std::string& fleet_id, const std::string& base,
                  const FleetMembers* members) {
    fleet_id_ = fleet_id;
    vouch_base_ = base + "/robot/";
    members_ = members;
  }
  struct Dropped {
    int64_t count = 0;
    std::string reason;  // the last one's
  };
  std::map<std::string, Dropped> dropped() {
    std::lock_guard<std::mutex> lk(mu_);
    return dropped_;
  }

  // Connects and subscribes, each filter at QoS 2 (the broker's SUBACK shows whether it does
  // QoS 2: if it grants less, publishes stay at QoS 1) or at `forced_qos` (1 or 2; 0: auto).
  // Returns once every SUBACK is in, so the retained messages follow at once.
  Status open(const Options& o, const std::vector<std::string>& subscriptions, int forced_qos) {
    transport::MqttOptions mo;
    mo.url = o.get("broker", std::getenv("RCAN_MQTT_URL") ? std::getenv("RCAN_MQTT_URL")
                                                          : "mqtt://127.0.0.1:1883");
    mo.urls = split_list(mo.url);  // a cluster's nodes, tried in turn
    mo.ca_file = o.get("ca-file");
    mo.username = o.get("username");
    if (forced_qos != 0) {
      mo.max_qos = forced_qos;
      mo.downgrade_on_suback = false;
    }
    if (o.has("password-file")) {
      auto pw = read_file(o.get("password-file"));
      if (!pw.ok()) return pw.error();
      mo.password = *pw;
      while (!mo.password.empty() && (mo.password.back() == '\n' || mo.password.back() == '\r'))
        mo.password.pop_back();
    }
    mo_ = std::move(mo);
    subscriptions_ = subscriptions;
    return connect(mono_ms() + timeout_ms_);
  }

  // Publishes and waits for the broker's acknowledgement (PUBACK, or PUBCOMP at QoS 2). A
  // connection that drops first is replaced by a new one (to the next node of a cluster when
  // --broker lists several) and the same message — the same message_id, which a member obeys
  // once — is published again, up to kPublishAttempts times within the timeout: a node of a
  // settling cluster drops its clients, and a stop must get through if any node takes it. A
  // broker that refuses the publish drops every attempt: the error says how many were made.
  Status publish(const std::string& topic, const json::Value& v, int qos, bool retain) {
    const std::string payload = json::dump(v);
    const int64_t deadline = mono_ms() + timeout_ms_;
    for (attempts_ = 1;; ++attempts_) {
      bool dropped = false;
      Status st =
          client_->publish_confirmed(topic, payload, qos, retain, left_ms(deadline), &dropped);
      if (st.ok()) return st;
      // A new client, starting with the node after this one: the old client would send its
      // queued copy on every reconnect by itself.
      if (dropped && attempts_ < kPublishAttempts) {
        const std::string at = client_->current_url();
        client_->stop();
        auto it = std::find(mo_.urls.begin(), mo_.urls.end(), at);
        if (it != mo_.urls.end() && it + 1 != mo_.urls.end())
          std::rotate(mo_.urls.begin(), it + 1, mo_.urls.end());
      }
      if (!dropped || attempts_ >= kPublishAttempts || !connect(deadline).ok()) {
        if (attempts_ == 1) return st;
        return Error(st.error().code,
                     st.error().message + " (" + std::to_string(attempts_) + " attempts)");
      }
    }
  }
  // Queues a publish without waiting for its acknowledgement (a member's answer is what counts;
  // a drop shows in lost()).
  void publish_queued(const std::string& topic, const json::Value& v, int qos, bool retain) {
    (void)client_->publish(topic, json::dump(v), qos, retain);
  }
  // How many times the last publish() went out.
  int attempts() const { return attempts_; }
  // The QoS a publish at `qos` goes out with.
  int qos_for(int qos) const { return std::clamp(qos, 1, client_->qos_cap()); }

  // Next message, or nullopt at the deadline (monotonic ms).
  std::optional<Inbound> next(int64_t deadline) {
    std::unique_lock<std::mutex> lk(mu_);
    while (inbox_.empty()) {
      int64_t left = deadline - mono_ms();
      if (left <= 0) return std::nullopt;
      cv_.wait_for(lk, std::chrono::milliseconds(left));
    }
    Inbound m = std::move(inbox_.front());
    inbox_.pop_front();
    return m;
  }

  void close() {
    if (client_) client_->stop();
  }
  void set_timeout(int64_t ms) { timeout_ms_ = ms; }
  // The connection dropped since connects() said `connects`: what came meanwhile is lost.
  bool lost(uint64_t connects) const {
    return !client_->connected() || client_->connects() != connects;
  }
  uint64_t connects() const { return client_->connects(); }
  std::string url() const { return client_->current_url(); }

 private:
  // A new client (its inbox is this session's) connected, with every subscription answered by
  // `deadline`: retained messages follow the SUBACKs at once.
  Status connect(int64_t deadline) {
    if (client_) client_->stop();
    client_ = std::make_unique<transport::MqttClient>(mo_);
    for (const auto& s : subscriptions_) client_->subscribe(s, 2);
    client_->on_message([this](const transport::MqttMessage& m) {
      auto body = mqtt::parse_payload(m.payload);
      if (!body.ok()) return;
      if (Status v = vouch(m.topic, *body); !v.ok()) {
        std::lock_guard<std::mutex> lk(mu_);
        Dropped& d = dropped_[v.error().field];
        ++d.count;
        d.reason = v.error().message;
        return;
      }
      std::lock_guard<std::mutex> lk(mu_);
      inbox_.push_back(Inbound{m.topic, std::move(body).value(), m.retained});
      cv_.notify_all();
    });
    if (Status s = client_->start(); !s.ok()) return s;
    if (!client_->wait_subscribed(left_ms(deadline)))
      return Error(ErrorCode::kInternal, "cannot connect to the broker at " + mo_.url);
    return subscribed(deadline);
  }
  // Once the SUBACKs are in: a clustered broker refuses subscriptions for a moment while it
  // elects new stream leaders (a node died), so the refused ones are asked for again until
  // `deadline`.
  Status subscribed(int64_t deadline) {
    auto refused = client_->refused_subscriptions();
    while (!refused.empty() && mono_ms() + 500 < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      client_->retry_refused();
      client_->wait_subscribed(left_ms(deadline));
      refused = client_->refused_subscriptions();
    }
    if (!refused.empty())
      return Error(ErrorCode::kInsufficientPrivileges,
                   "the broker refused the subscription to " + refused.front());
    return Status::Ok();
  }
  // A member's reply or status that its robot did not sign: an error whose field is the member.
  Status vouch(const std::string& topic, const json::Value& body) const {
    if (vouch_base_.empty() || topic.rfind(vouch_base_, 0) != 0) return Status::Ok();
    const std::string rest = topic.substr(vouch_base_.size());
    const size_t slash = rest.find('/');
    if (slash == std::string::npos) return Status::Ok();
    const std::string kind = rest.substr(slash + 1);
    if (kind != "reply" && kind != "status") return Status::Ok();  // audit: its own HMAC chain
    const std::string member = rest.substr(0, slash);
    Status v = members_ != nullptr
                   ? members_->verify(fleet_id_, member, body)
                   : Status(Error(ErrorCode::kSignatureInvalid, "no --members-dir"));
    if (v.ok()) return v;
    return Error(v.error().code, v.error().message, member);
  }
  static int left_ms(int64_t deadline) {
    return static_cast<int>(std::max<int64_t>(1, deadline - mono_ms()));
  }

  static constexpr int kPublishAttempts = 3;
  transport::MqttOptions mo_;
  std::vector<std::string> subscriptions_;
  std::unique_ptr<transport::MqttClient> client_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Inbound> inbox_;
  std::map<std::string, Dropped> dropped_;  // member → its replies/statuses not believed
  std::string fleet_id_, vouch_base_;
  const FleetMembers* members_ = nullptr;
  int64_t timeout_ms_ = 10000;
  int attempts_ = 0;
};

}  // namespace rcan::cli::fleet
