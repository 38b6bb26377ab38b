#include "transport/mqtt_client.h"

#include <mosquitto.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <string_view>
#include <thread>

#include "base/clock.h"
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
  std::vector<std::string> url_text;      // MqttOptions::urls, or {url}
  std::vector<BrokerUrl> urls;            // parsed by start()
  std::thread net;                        // run()
  std::atomic<std::thread::id> net_id{};  // set by the network thread when it starts
  // Wakes the network thread's poll() when another thread queued a packet (a publish, a
  // subscription, the DISCONNECT of stop()). libmosquitto's own wake-up belongs to its select()
  // loop, which this client does not use (see serve()).
  int wake_fd = -1;

  ~Impl() {
    if (wake_fd >= 0) ::close(wake_fd);
  }
  void wake() const {
    if (wake_fd < 0) return;
    const uint64_t one = 1;
    ssize_t n = ::write(wake_fd, &one, sizeof one);
    (void)n;  // a full counter (never in practice) means a wake-up is pending anyway
  }
};

// jemalloc's control interface, present when the program links jemalloc (rcand does; the
// sanitizer trees and programs on another allocator do not, and then this is null).
extern "C" int mallctl(const char*, void*, size_t*, void*, size_t) __attribute__((weak));

namespace {

// The network thread allocates without jemalloc's per-thread cache. A fleet ESTOP is handled on
// this thread, and the cache (which takes objects from the arena in batches and hands them back
// later) makes the first ESTOP after a start write pages never touched before: without it, that
// ESTOP takes about half the page faults. The price is a lock of the arena's bins on each
// allocation of every message handled here (a broadcast `status` costs about a tenth more CPU),
// which is why the HTTP threads, where commands are the steady load, keep their cache;
// bench/fleet_bench and bench/load_bench measure both sides. (A jemalloc built with a symbol
// prefix exports je_mallctl: then this does nothing.)
void no_thread_cache() {
  if (mallctl == nullptr) return;
  bool enabled = false;
  (void)mallctl("thread.tcache.enabled", nullptr, nullptr, &enabled, sizeof enabled);
}

// How long the network thread sleeps with nothing to read or write: a quarter of the keepalive
// (libmosquitto then sends its PINGREQ at most a quarter late, well inside the broker's 1.5×
// keepalive), at most 5 s. A robot's idle connection wakes its thread that often, not every
// second.
int idle_poll_ms(int keepalive_s) {
  if (keepalive_s <= 0) return 5000;
  return std::clamp(keepalive_s * 250, 100, 5000);
}

bool set_cork(int fd, bool on) {
  const int v = on ? 1 : 0;
  return ::setsockopt(fd, IPPROTO_TCP, TCP_CORK, &v, sizeof v) == 0;
}

// Serves the connection of `m` until it drops or `stopped` is set: reads what arrives, writes
// what is queued, keeps the connection alive. poll() rather than mosquitto_loop(), whose
// select() refuses a socket numbered 1024 or more (a robot with many clients, files or driver
// sockets open would lose its fleet channel for good). False when the connection is gone.
bool serve(mosquitto* m, int wake_fd, bool tls, int idle_ms, const std::atomic<bool>& stopped) {
  while (!stopped.load()) {
    const int fd = mosquitto_socket(m);
    if (fd < 0) return false;
    pollfd p[2] = {{fd, static_cast<short>(POLLIN | (mosquitto_want_write(m) ? POLLOUT : 0)), 0},
                   {wake_fd, POLLIN, 0}};
    const int ready = ::poll(p, 2, idle_ms);
    if (ready < 0 && errno != EINTR) return false;
    if (p[1].revents & POLLIN) {
      uint64_t count = 0;
      ssize_t n = ::read(wake_fd, &count, sizeof count);
      (void)n;
    }
    // TLS may hold decrypted bytes that poll() cannot see: read on every turn (a read with
    // nothing there is answered EAGAIN, which is not an error).
    // What arrived is answered together: the PUBACK of a command and what handling it queued
    // (its EVENT, an ACK ready at once) leave in one TCP segment, not one each (TCP_CORK until
    // the queue is written; libmosquitto writes every packet with a write() of its own).
    bool corked = false;
    if (tls || (p[0].revents & (POLLIN | POLLERR | POLLHUP))) {
      corked = set_cork(fd, true);
      if (mosquitto_loop_read(m, 1) != MOSQ_ERR_SUCCESS) return false;
    }
    if (mosquitto_socket(m) < 0) return false;
    const bool wrote_ok =
        !mosquitto_want_write(m) || mosquitto_loop_write(m, 1) == MOSQ_ERR_SUCCESS;
    if (corked && mosquitto_socket(m) == fd) set_cork(fd, false);  // else closed, maybe reused
    if (!wrote_ok) return false;
    if (mosquitto_loop_misc(m) != MOSQ_ERR_SUCCESS) return false;  // keepalive, timeouts
  }
  return true;
}

}  // namespace

// C callbacks → the client.
struct MqttCallbacks {
  static void on_connect(mosquitto* m, void* obj, int rc) {
    auto* self = static_cast<MqttClient*>(obj);
    if (rc == 0) {
      self->connected_.store(true);
      self->connects_.fetch_add(1);
      std::vector<std::pair<std::string, int>> subs;
      {
        MutexLock lk(self->mu_);
        subs = self->subs_;
      }
      for (const auto& [filter, qos] : subs) {
        int mid = 0;
        if (mosquitto_subscribe(m, &mid, filter.c_str(), qos) == MOSQ_ERR_SUCCESS)
          self->sent_subscribe(mid, filter, qos);
      }
      MutexLock lk(self->mu_);
      ++self->ready_connects_;
      self->cv_.notify_all();
    }
    if (self->on_connection_) self->on_connection_(rc == 0, rc);
  }
  static void on_disconnect(mosquitto*, void* obj, int rc) {
    auto* self = static_cast<MqttClient*>(obj);
    self->connected_.store(false);
    {
      MutexLock lk(self->mu_);
      ++self->drops_;
      self->sub_pending_.clear();  // renewed on the next connect
      self->sub_early_.clear();
      self->cv_.notify_all();
    }
    if (self->on_connection_) self->on_connection_(false, rc);
  }
  static void on_publish(mosquitto*, void* obj, int mid) {
    auto* self = static_cast<MqttClient*>(obj);
    self->inflight_.fetch_sub(1);
    MutexLock lk(self->mu_);
    if (self->confirm_waiters_ > 0) {
      self->acked_.insert(mid);
      self->cv_.notify_all();
    }
  }
  static void on_subscribe(mosquitto*, void* obj, int mid, int count, const int* granted) {
    auto* self = static_cast<MqttClient*>(obj);
    // One filter per SUBSCRIBE: one granted QoS (0x80: refused).
    self->got_suback(mid, count > 0 && granted != nullptr ? granted[0] : 0x80);
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
  opts_.max_qos = std::clamp(opts_.max_qos, 1, 2);
  opts_.reconnect_min_s = std::max(opts_.reconnect_min_s, 1);
  opts_.reconnect_max_s = std::max(opts_.reconnect_max_s, opts_.reconnect_min_s);
  opts_.will.qos = std::min(opts_.will.qos, opts_.max_qos);
  qos_cap_.store(opts_.max_qos);
}

MqttClient::~MqttClient() {
  stop();
  if (impl_->m != nullptr) mosquitto_destroy(impl_->m);
}

void MqttClient::subscribe(const std::string& filter, int qos) {
  qos = std::min(qos, opts_.max_qos);
  {
    MutexLock lk(mu_);
    subs_.emplace_back(filter, qos);
  }
  int mid = 0;
  if (impl_->m != nullptr && connected_.load() &&
      mosquitto_subscribe(impl_->m, &mid, filter.c_str(), qos) == MOSQ_ERR_SUCCESS) {
    sent_subscribe(mid, filter, qos);
    impl_->wake();
  }
}

void MqttClient::sent_subscribe(int mid, const std::string& filter, int qos) {
  int granted = -1;
  {
    MutexLock lk(mu_);
    auto early = sub_early_.find(mid);
    if (early == sub_early_.end()) {
      sub_pending_[mid] = {filter, qos};
      return;
    }
    granted = early->second;
    sub_early_.erase(early);
    sub_pending_[mid] = {filter, qos};
  }
  got_suback(mid, granted);
}

// A broker without QoS 2 grants QoS 1 to a QoS 2 subscription (NATS, Azure IoT Hub) or refuses
// it: from then on nothing is published above QoS 1, and a refused subscription is renewed at 1.
void MqttClient::got_suback(int mid, int granted) {
  std::string renew;
  {
    MutexLock lk(mu_);
    auto it = sub_pending_.find(mid);
    if (it == sub_pending_.end()) {
      sub_early_[mid] = granted;
      return;
    }
    auto [filter, requested] = it->second;
    sub_pending_.erase(it);
    cv_.notify_all();
    if (requested == 2 && (granted == 0x80 || granted < 2) && opts_.downgrade_on_suback)
      qos_cap_.store(1);
    if (granted == 0x80 && requested == 2) {
      for (auto& s : subs_)
        if (s.first == filter) s.second = 1;
      renew = filter;
    } else if (granted == 0x80) {
      sub_refused_.push_back(filter);
    }
  }
  int again = 0;
  if (!renew.empty() && impl_->m != nullptr &&
      mosquitto_subscribe(impl_->m, &again, renew.c_str(), 1) == MOSQ_ERR_SUCCESS) {
    sent_subscribe(again, renew, 1);
    impl_->wake();
  }
}

bool MqttClient::all_subscribed() const {
  MutexLock lk(mu_);
  return connected_.load() && ready_connects_ > 0 && sub_pending_.empty() && sub_refused_.empty();
}

bool MqttClient::granted(const std::vector<std::string>& filters) const {
  MutexLock lk(mu_);
  if (!connected_.load() || ready_connects_ == 0) return false;
  for (const auto& f : filters) {
    for (const auto& [mid, sub] : sub_pending_)
      if (sub.first == f) return false;
    if (std::find(sub_refused_.begin(), sub_refused_.end(), f) != sub_refused_.end()) return false;
  }
  return true;
}

std::vector<std::string> MqttClient::refused_subscriptions() const {
  MutexLock lk(mu_);
  return sub_refused_;
}

void MqttClient::retry_refused() {
  std::vector<std::pair<std::string, int>> again;
  {
    MutexLock lk(mu_);
    for (const auto& f : sub_refused_)
      for (const auto& s : subs_)
        if (s.first == f) again.push_back(s);
    sub_refused_.clear();
  }
  for (const auto& [filter, qos] : again) {
    int mid = 0;
    if (impl_->m != nullptr && connected_.load() &&
        mosquitto_subscribe(impl_->m, &mid, filter.c_str(), qos) == MOSQ_ERR_SUCCESS) {
      sent_subscribe(mid, filter, qos);
      impl_->wake();
    }
  }
}

bool MqttClient::wait_subscribed(int timeout_ms) {
  auto deadline = steady_now() + std::chrono::milliseconds(timeout_ms);
  MutexLock lk(mu_);
  while (!(ready_connects_ > 0 && connected_.load() && sub_pending_.empty())) {
    if (cv_.wait_until(mu_, deadline) == std::cv_status::timeout)
      return ready_connects_ > 0 && connected_.load() && sub_pending_.empty();
  }
  return true;
}

Status MqttClient::start() {
  if (started_) return Error(ErrorCode::kInternal, "the MQTT client was already started");
  impl_->url_text = opts_.urls.empty() ? std::vector<std::string>{opts_.url} : opts_.urls;
  for (const auto& text : impl_->url_text) {
    auto u = parse_broker_url(text);
    if (!u.ok()) return u.error();
    // One TLS setting per client: a failover URL never drops to plaintext.
    if (!impl_->urls.empty() && u->tls != impl_->urls.front().tls)
      return bad("the broker URLs must all be mqtt:// or all mqtts://");
    impl_->urls.push_back(*u);
  }
  const BrokerUrl* url = &impl_->urls.front();
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
  mosquitto_subscribe_callback_set(m, &MqttCallbacks::on_subscribe);
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
  // Our own network thread drives mosquitto_loop (libmosquitto's loop_forever reconnects only to
  // the one host it was given): publishes from other threads are queued for it and wake it.
  mosquitto_threaded_set(m, true);
  impl_->wake_fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  if (impl_->wake_fd < 0) return Error(ErrorCode::kInternal, "cannot create the MQTT wake-up fd");
  started_ = true;
  // A broker that is down now is retried by the network thread (failover, backoff).
  impl_->net = std::thread([this] {
    impl_->net_id.store(std::this_thread::get_id());
    pthread_setname_np(pthread_self(), opts_.thread_name.substr(0, 15).c_str());
    no_thread_cache();
    run();
  });
  return Status::Ok();
}

// Connects to the URL in turn and serves the connection until it drops; then the next URL
// (round robin): the first round without delay, then each round after the backoff delay. One
// URL: the backoff before every attempt, as libmosquitto's own reconnect does.
void MqttClient::run() {
  mosquitto* m = impl_->m;
  const size_t n = impl_->urls.size();
  size_t at = 0;
  size_t fails = 0;  // attempts since the last connection that the broker accepted
  while (!stopped_.load()) {
    at_.store(at);
    const BrokerUrl& u = impl_->urls[at];
    const uint64_t before = connects_.load();
    if (mosquitto_connect(m, u.host.c_str(), u.port, opts_.keepalive_s) == MOSQ_ERR_SUCCESS)
      serve(m, impl_->wake_fd, u.tls, idle_poll_ms(opts_.keepalive_s), stopped_);
    if (stopped_.load()) break;
    if (connects_.load() != before) fails = 0;  // this one served: a new outage begins
    ++fails;
    if (n > 1) at = (at + 1) % n;
    int64_t delay_ms = 0;
    if (fails >= n) {
      size_t round = std::min<size_t>((fails - n) / n, 20);
      delay_ms =
          std::min<int64_t>(int64_t{opts_.reconnect_min_s} << round, opts_.reconnect_max_s) * 1000;
    }
    auto deadline = steady_now() + std::chrono::milliseconds(delay_ms);
    MutexLock lk(mu_);
    while (!stopped_.load() && cv_.wait_until(mu_, deadline) != std::cv_status::timeout) {
    }
  }
  // stop() asked: a clean DISCONNECT (no will), sent by this thread (up to 500 ms).
  mosquitto_disconnect(m);
  for (int i = 0; i < 10 && mosquitto_socket(m) >= 0 && mosquitto_want_write(m); ++i) {
    pollfd p{mosquitto_socket(m), POLLOUT, 0};
    (void)::poll(&p, 1, 50);
    if (mosquitto_loop_write(m, 1) != MOSQ_ERR_SUCCESS) break;
  }
}

std::string MqttClient::current_url() const {
  if (impl_->url_text.empty()) return opts_.url;
  return impl_->url_text[std::min(at_.load(), impl_->url_text.size() - 1)];
}

Status MqttClient::publish(const std::string& topic, const std::string& payload, int qos,
                           bool retain) {
  if (impl_->m == nullptr || stopped_.load())
    return Error(ErrorCode::kInternal, "the MQTT client is not running");
  qos = std::min(qos, qos_cap_.load());
  if (qos > 0) inflight_.fetch_add(1);
  int rc = mosquitto_publish(impl_->m, nullptr, topic.c_str(), static_cast<int>(payload.size()),
                             payload.data(), qos, retain);
  // From the network thread itself (a message handler's answer) the loop writes the packet when
  // the handler returns: waking it would only cost a write now and an empty turn later.
  if (rc == MOSQ_ERR_SUCCESS && std::this_thread::get_id() != impl_->net_id.load()) impl_->wake();
  if (rc != MOSQ_ERR_SUCCESS && rc != MOSQ_ERR_NO_CONN) {
    if (qos > 0) inflight_.fetch_sub(1);
    return Error(ErrorCode::kInternal, std::string("MQTT publish: ") + mosquitto_strerror(rc));
  }
  if (rc == MOSQ_ERR_NO_CONN && qos == 0)
    return Error(ErrorCode::kInternal, "MQTT publish: not connected");
  return Status::Ok();
}

Status MqttClient::publish_confirmed(const std::string& topic, const std::string& payload, int qos,
                                     bool retain, int timeout_ms, bool* dropped_out) {
  if (dropped_out != nullptr) *dropped_out = false;
  if (impl_->m == nullptr || stopped_.load())
    return Error(ErrorCode::kInternal, "the MQTT client is not running");
  if (!connected_.load()) {
    if (dropped_out != nullptr) *dropped_out = true;
    return Error(ErrorCode::kInternal, "not connected to the broker");
  }
  qos = std::clamp(qos, 1, qos_cap_.load());
  uint64_t drops = 0;
  {
    MutexLock lk(mu_);
    ++confirm_waiters_;
    drops = drops_;
  }
  inflight_.fetch_add(1);
  int mid = 0;
  int rc = mosquitto_publish(impl_->m, &mid, topic.c_str(), static_cast<int>(payload.size()),
                             payload.data(), qos, retain);
  if (rc == MOSQ_ERR_SUCCESS) impl_->wake();
  auto deadline = steady_now() + std::chrono::milliseconds(timeout_ms);
  MutexLock lk(mu_);
  if (rc == MOSQ_ERR_SUCCESS) {
    while (acked_.count(mid) == 0 && drops_ == drops &&
           cv_.wait_until(mu_, deadline) != std::cv_status::timeout) {
    }
  }
  bool acked = rc == MOSQ_ERR_SUCCESS && acked_.erase(mid) > 0;
  bool dropped = drops_ != drops;
  if (--confirm_waiters_ == 0) acked_.clear();
  if (acked) return Status::Ok();
  const std::string what = "the publish on " + topic + " at QoS " + std::to_string(qos);
  if (dropped_out != nullptr) *dropped_out = dropped || rc == MOSQ_ERR_NO_CONN;
  if (rc != MOSQ_ERR_SUCCESS) {
    if (rc != MOSQ_ERR_NO_CONN) inflight_.fetch_sub(1);
    return Error(ErrorCode::kInternal, what + " failed: " + mosquitto_strerror(rc));
  }
  if (dropped)
    return Error(ErrorCode::kInternal,
                 "the broker closed the connection before acknowledging " + what +
                     " (a broker refuses a publish by disconnecting; brokers capped at QoS 1 "
                     "refuse QoS 2)");
  return Error(ErrorCode::kInternal, "the broker did not acknowledge " + what + " within " +
                                         std::to_string(timeout_ms) + " ms");
}

bool MqttClient::flush(int timeout_ms) {
  auto deadline = steady_now() + std::chrono::milliseconds(timeout_ms);
  while (inflight_.load() > 0) {
    if (steady_now() >= deadline || !connected_.load()) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

void MqttClient::stop() {
  if (!started_ || stopped_.exchange(true)) return;
  {
    MutexLock lk(mu_);
    cv_.notify_all();  // a backoff wait ends
  }
  mosquitto_disconnect(impl_->m);  // queued; run() sends it again if it raced
  impl_->wake();
  if (impl_->net.joinable()) impl_->net.join();
  connected_.store(false);
}

}  // namespace rcan::transport
