#include "registry/api/webhooks.h"

#include <chrono>

#include "base/clock.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "registry/api/address.h"
#include "registry/api/registry_api.h"
#include "runtime/http_client.h"
#include "runtime/log.h"

namespace rcan::registry::api {

std::string webhook_signature(std::string_view secret, std::string_view timestamp,
                              std::string_view body) {
  std::string signed_part;
  signed_part.reserve(timestamp.size() + 1 + body.size());
  signed_part.append(timestamp).append(".").append(body);
  return "sha256=" + hmac_sha256_hex(secret, signed_part);
}

WebhookDispatcher::WebhookDispatcher(Store& store, WebhookOptions o,
                                     std::function<int64_t()> wall_ms)
    : store_(store), o_(o), wall_ms_(std::move(wall_ms)) {
  worker_ = std::thread([this] { run(); });
}

WebhookDispatcher::~WebhookDispatcher() {
  size_t left = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
    left = queue_.size();
  }
  cv_.notify_all();
  if (worker_.joinable()) worker_.join();
  if (left > 0)
    log(LogLevel::kWarn, "registry_webhooks_dropped_at_stop",
        json::Object{{"queued", static_cast<int64_t>(left)}});
}

void WebhookDispatcher::push_locked(Item it, bool retry) {
  // A retry takes the place its delivery held; new work beyond the capacity is dropped.
  if (!retry && queue_.size() >= o_.queue_capacity) {
    uint64_t n = dropped.fetch_add(1) + 1;
    if (n == 1 || n % 1000 == 0)
      log(LogLevel::kWarn, "registry_webhook_queue_full",
          json::Object{{"capacity", static_cast<int64_t>(o_.queue_capacity)},
                       {"dropped_total", static_cast<int64_t>(n)}});
    return;
  }
  it.seq = seq_++;
  queue_.push(std::move(it));
}

void WebhookDispatcher::publish(const std::string& event, const std::string& rrn,
                                const std::string& prefix, json::Value record) {
  Item it;
  it.is_event = true;
  it.prefix = prefix;
  it.delivery_id = new_uuid_v4();
  it.body = json::dump(json::Object{{"event", event},
                                    {"rrn", rrn},
                                    {"record", std::move(record)},
                                    {"timestamp", iso_utc(wall_ms_())},
                                    {"delivery_id", it.delivery_id}});
  it.due_us = steady_us();
  {
    std::lock_guard<std::mutex> lock(mu_);
    push_locked(std::move(it), false);
  }
  cv_.notify_one();
}

void WebhookDispatcher::run() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stop_) {
    if (queue_.empty()) {
      cv_.wait(lock);
      continue;
    }
    int64_t now = steady_us();
    if (queue_.top().due_us > now) {
      cv_.wait_for(lock, std::chrono::microseconds(queue_.top().due_us - now));
      continue;
    }
    Item it = queue_.top();
    queue_.pop();
    lock.unlock();
    if (it.is_event)
      expand(it);
    else
      attempt(std::move(it));
    lock.lock();
  }
}

void WebhookDispatcher::expand(const Item& event) {
  auto hooks = store_.webhooks_for(event.prefix);
  if (!hooks.ok()) {
    log(LogLevel::kError, "registry_webhook_lookup_failed",
        json::Object{{"prefix", event.prefix}, {"error", hooks.error().message}});
    return;
  }
  std::lock_guard<std::mutex> lock(mu_);
  for (Webhook& h : *hooks) {
    int& f = failures_[h.id];
    f = std::max(f, h.failure_count);
    if (f >= o_.max_failures) {
      skipped.fetch_add(1);
      continue;
    }
    Item d;
    d.is_event = false;
    d.body = event.body;
    d.delivery_id = event.delivery_id;
    d.hook = std::move(h);
    d.attempt = 1;
    d.due_us = steady_us();
    push_locked(std::move(d), false);
  }
}

void WebhookDispatcher::attempt(Item it) {
  const Webhook& h = it.hook;
  if (failures_[h.id] >= o_.max_failures) {  // switched off while this one waited
    skipped.fetch_add(1);
    return;
  }
  std::string error;
  int status = 0;
  bool refused = false;  // no public address: no use trying again
  auto url = parse_web_url(h.url);
  if (!url.ok()) {
    error = url.error().message;
  } else {
    std::string ts = std::to_string(wall_ms_() / 1000);
    HttpRequestOptions ro;
    ro.max_body = 4096;
    ro.headers = {{"X-RCAN-Delivery", "webhook/1.0"},
                  {"X-RCAN-Delivery-Id", it.delivery_id},
                  {"X-RCAN-Timestamp", ts},
                  {"X-RCAN-Signature", webhook_signature(h.secret, ts, it.body)}};
    if (!o_.allow_private)
      ro.allow_address = [](const sockaddr* sa) {
        auto a = ip_of(sa);
        return a && is_public_address(*a);
      };
    auto answer = http_request("POST", *url, it.body, o_.timeout_ms, ro);
    if (!answer.ok() && answer.error().message.rfind("refused: ", 0) == 0) {
      refused = true;
      error = answer.error().message + " (a webhook goes to public addresses only)";
      refused_address.fetch_add(1);
      log(LogLevel::kWarn, "registry_webhook_refused_address",
          json::Object{{"webhook_id", h.id}, {"delivery_id", it.delivery_id}, {"host", url->host}});
    } else if (!answer.ok())
      error = answer.error().message;
    else if ((status = answer->status) < 200 || status > 299)
      error = "HTTP " + std::to_string(status);
  }
  bool ok = error.empty();
  bool last = !ok && (it.attempt >= o_.attempts || !url.ok() || refused);
  if (!ok) attempts_failed.fetch_add(1);
  if (ok || last) {
    if (ok) {
      delivered.fetch_add(1);
      failures_[h.id] = 0;
    } else {
      failed.fetch_add(1);
      ++failures_[h.id];
      log(LogLevel::kWarn, "registry_webhook_failed",
          json::Object{{"webhook_id", h.id},
                       {"delivery_id", it.delivery_id},
                       {"attempts", it.attempt},
                       {"error", error}});
    }
    if (Status s = store_.record_delivery(h.id, ok, iso_utc(wall_ms_())); !s.ok())
      log(LogLevel::kError, "registry_webhook_record_failed",
          json::Object{{"webhook_id", h.id}, {"error", s.error().message}});
    return;
  }
  int64_t wait_ms = static_cast<int64_t>(o_.backoff_ms) << std::min(it.attempt - 1, 20);
  it.attempt++;
  it.due_us = steady_us() + wait_ms * 1000;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stop_) return;
    push_locked(std::move(it), true);
  }
}

}  // namespace rcan::registry::api
