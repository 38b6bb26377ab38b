#include "transport/mqtt_client.h"

#include <mosquitto.h>
#include <pthread.h>

#include <cctype>
#include <chrono>
#include <cstdlib>
#include <string_view>
#include <thread>

#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace rcan::transport {

namespace {

std::once_flag g_lib_once;

Error bad(std::string msg, std::string field = "url") {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field));
}

}  // namespace

Result<BrokerUrl> parse_broker_url(std::string_view url) {
  BrokerUrl b;
  std::string_view rest;
  if (url.rfind("mqtt://", 0) == 0) {
    rest = url.substr(7);
  } else if (url.rfind("mqtts://", 0) == 0) {
    rest = url.substr(8);
    b.tls = true;
    b.port = 8883;
  } else {
    return bad("a broker URL starts with mqtt:// or mqtts://");
  }
  if (!rest.empty() && rest.back() == '/') rest.remove_suffix(1);
  std::string_view host = rest, port;
  if (!rest.empty() && rest.front() == '[') {
    size_t close = rest.find(']');
    if (close == std::string_view::npos) return bad("unterminated IPv6 literal in the broker URL");
    host = rest.substr(1, close - 1);
    std::string_view after = rest.substr(close + 1);
    if (!after.empty()) {
      if (after.front() != ':') return bad("unexpected text after the IPv6 literal");
      port = after.substr(1);
    }
  } else if (size_t colon = rest.rfind(':'); colon != std::string_view::npos) {
    host = rest.substr(0, colon);
    port = rest.substr(colon + 1);
  }
  if (host.empty() || host.size() > 253) return bad("the broker URL needs a host");
  for (char c : host)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_' ||
          c == ':'))
      return bad("the broker host has an invalid character");
  if (!port.empty() || rest.find(':') != std::string_view::npos) {
    if (port.empty() || port.size() > 5) return bad("the broker port must be 1..65535");
    unsigned v = 0;
    for (char c : port) {
      if (c < '0' || c > '9') return bad("the broker port must be 1..65535");
      v = v * 10 + static_cast<unsigned>(c - '0');
    }
    if (v == 0 || v > 65535) return bad("the broker port must be 1..65535");
    b.port = static_cast<uint16_t>(v);
  }
  b.host = std::string(host);
  return b;
}

struct MqttClient::Impl {
  mosquitto* m = nullptr;
};

// C callbacks → the client.
struct MqttCallbacks {
  static void on_connect(mosquitto* m, void* obj, int rc) {
    auto* self = static_cast<MqttClient*>(obj);
    pthread_setname_np(pthread_self(), "mqtt-io");  // libmosquitto's network thread
    if (rc == 0) {
      self->connected_.store(true);
      self->connects_.fetch_add(1);
      std::vector<std::pair<std::string, int>> subs;
      {
        MutexLock lk(self->mu_);
        subs = self->subs_;
      }
      for (const auto& [filter, qos] : subs) mosquitto_subscribe(m, nullptr, filter.c_str(), qos);
    }
    if (self->on_connection_) self->on_connection_(rc == 0, rc);
  }
  static void on_disconnect(mosquitto*, void* obj, int rc) {
    auto* self = static_cast<MqttClient*>(obj);
    self->connected_.store(false);
    if (self->on_connection_) self->on_connection_(false, rc);
  }
  static void on_publish(mosquitto*, void* obj, int) {
    auto* self = static_cast<MqttClient*>(obj);
    self->inflight_.fetch_sub(1);
  }
  static void on_message(mosquitto*, void* obj, const mosquitto_message* msg) {
    auto* self = static_cast<MqttClient*>(obj);
    if (!self->on_message_ || msg == nullptr || msg->topic == nullptr) return;
    MqttMessage out;
    out.topic = msg->topic;
    if (msg->payload != nullptr && msg->payloadlen > 0)
      out.payload.assign(static_cast<const char*>(msg->payload),
                         static_cast<size_t>(msg->payloadlen));
    out.qos = msg->qos;
    out.retained = msg->retain;
    self->on_message_(out);
  }
};

MqttClient::MqttClient(MqttOptions opts) : opts_(std::move(opts)), impl_(std::make_unique<Impl>()) {
  std::call_once(g_lib_once, [] { mosquitto_lib_init(); });
}

MqttClient::~MqttClient() {
  stop();
  if (impl_->m != nullptr) mosquitto_destroy(impl_->m);
}

void MqttClient::subscribe(const std::string& filter, int qos) {
  {
    MutexLock lk(mu_);
    subs_.emplace_back(filter, qos);
  }
  if (impl_->m != nullptr && connected_.load())
    mosquitto_subscribe(impl_->m, nullptr, filter.c_str(), qos);
}

Status MqttClient::start() {
  if (started_) return Error(ErrorCode::kInternal, "the MQTT client was already started");
  auto url = parse_broker_url(opts_.url);
  if (!url.ok()) return url.error();
  std::string id = opts_.client_id;
  bool clean = opts_.clean_session;
  if (id.empty()) {
    uint8_t b[8];
    if (!random_bytes(b, sizeof b)) return Error(ErrorCode::kInternal, "no randomness");
    id = "rcan-" + to_hex(b, sizeof b);
    clean = true;
  }
  impl_->m = mosquitto_new(id.c_str(), clean, this);
  if (impl_->m == nullptr) return Error(ErrorCode::kInternal, "mosquitto_new failed");
  mosquitto* m = impl_->m;
  mosquitto_int_option(m, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
  // Small packets (a QoS 2 ESTOP is PUBLISH/PUBREC/PUBREL/PUBCOMP) must not wait for
  // Nagle's algorithm behind the peer's delayed ACK (~40 ms per exchange on Linux).
  mosquitto_int_option(m, MOSQ_OPT_TCP_NODELAY, 1);
  mosquitto_connect_callback_set(m, &MqttCallbacks::on_connect);
  mosquitto_disconnect_callback_set(m, &MqttCallbacks::on_disconnect);
  mosquitto_message_callback_set(m, &MqttCallbacks::on_message);
  mosquitto_publish_callback_set(m, &MqttCallbacks::on_publish);
  mosquitto_reconnect_delay_set(m, static_cast<unsigned>(opts_.reconnect_min_s),
                                static_cast<unsigned>(opts_.reconnect_max_s), true);
  if (!opts_.username.empty()) {
    if (mosquitto_username_pw_set(m, opts_.username.c_str(),
                                  opts_.password.empty() ? nullptr : opts_.password.c_str()) !=
        MOSQ_ERR_SUCCESS)
      return Error(ErrorCode::kInternal, "cannot set the MQTT credentials");
  }
  if (url->tls) {
    if (opts_.ca_file.empty())
      return Error(ErrorCode::kSchemaValidationFailed, "an mqtts:// broker needs a CA file",
                   "tls.ca_file");
    int rc = mosquitto_tls_set(m, opts_.ca_file.c_str(), nullptr,
                               opts_.cert_file.empty() ? nullptr : opts_.cert_file.c_str(),
                               opts_.key_file.empty() ? nullptr : opts_.key_file.c_str(), nullptr);
    if (rc != MOSQ_ERR_SUCCESS)
      return Error(ErrorCode::kInternal, std::string("MQTT TLS setup: ") + mosquitto_strerror(rc));
    mosquitto_tls_opts_set(m, 1, "tlsv1.2", nullptr);  // verify the broker's certificate
  }
  if (!opts_.will.topic.empty()) {
    int rc =
        mosquitto_will_set(m, opts_.will.topic.c_str(), static_cast<int>(opts_.will.payload.size()),
                           opts_.will.payload.data(), opts_.will.qos, opts_.will.retain);
    if (rc != MOSQ_ERR_SUCCESS)
      return Error(ErrorCode::kInternal, std::string("MQTT will: ") + mosquitto_strerror(rc));
  }
  int rc = mosquitto_loop_start(m);
  if (rc != MOSQ_ERR_SUCCESS)
    return Error(ErrorCode::kInternal,
                 std::string("MQTT network thread: ") + mosquitto_strerror(rc));
  started_ = true;
  // A broker that is down now is retried by the network thread with the backoff above.
  rc = mosquitto_connect_async(m, url->host.c_str(), url->port, opts_.keepalive_s);
  if (rc != MOSQ_ERR_SUCCESS && rc != MOSQ_ERR_ERRNO && rc != MOSQ_ERR_CONN_REFUSED) {
    stop();
    return Error(ErrorCode::kInternal, std::string("MQTT connect: ") + mosquitto_strerror(rc));
  }
  if (rc != MOSQ_ERR_SUCCESS) mosquitto_reconnect_async(m);
  return Status::Ok();
}

Status MqttClient::publish(const std::string& topic, const std::string& payload, int qos,
                           bool retain) {
  if (impl_->m == nullptr || stopped_.load())
    return Error(ErrorCode::kInternal, "the MQTT client is not running");
  if (qos > 0) inflight_.fetch_add(1);
  int rc = mosquitto_publish(impl_->m, nullptr, topic.c_str(), static_cast<int>(payload.size()),
                             payload.data(), qos, retain);
  if (rc != MOSQ_ERR_SUCCESS && rc != MOSQ_ERR_NO_CONN) {
    if (qos > 0) inflight_.fetch_sub(1);
    return Error(ErrorCode::kInternal, std::string("MQTT publish: ") + mosquitto_strerror(rc));
  }
  if (rc == MOSQ_ERR_NO_CONN && qos == 0)
    return Error(ErrorCode::kInternal, "MQTT publish: not connected");
  return Status::Ok();
}

bool MqttClient::flush(int timeout_ms) {
  auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (inflight_.load() > 0) {
    if (std::chrono::steady_clock::now() >= deadline || !connected_.load()) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

void MqttClient::stop() {
  if (!started_ || stopped_.exchange(true)) return;
  mosquitto_disconnect(impl_->m);
  mosquitto_loop_stop(impl_->m, false);
  connected_.store(false);
}

}  // namespace rcan::transport
