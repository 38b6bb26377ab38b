// The registry's webhook deliveries (docs/REGISTRY.md "Webhooks"): record changes published by
// the routes are queued and delivered by one worker thread, never on an HTTP I/O thread. Each
// delivery is POSTed with an HMAC-SHA256 signature over "<timestamp>.<body>" under the
// subscriber's secret, retried with exponential back-off, and its outcome recorded in the
// store; a subscription with max_failures consecutive failed deliveries is skipped.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <queue>
#include <string>
#include <thread>
#include <vector>

#include "rcan/json.h"
#include "registry/store.h"

namespace rcan::registry::api {

struct WebhookOptions {
  size_t queue_capacity = 10000;  // queued events and deliveries; beyond it: dropped, counted
  int attempts = 5;               // per delivery
  int backoff_ms = 1000;          // before the 2nd attempt; doubled each time after
  int timeout_ms = 5000;          // per attempt, connect to answer
  int max_failures = 5;           // consecutive failed deliveries that switch a subscription off
  // Deliver to loopback, private, link-local… addresses too (address.h is_public_address). Off:
  // a delivery connects only to the public addresses its host resolves to, checked at connect
  // time (a name that resolves to the cloud's metadata service or the registry's own network
  // is refused then, whatever it resolved to when the subscription was made).
  bool allow_private = false;
};

// "sha256=<hex HMAC-SHA256(secret, timestamp + "." + body)>"
std::string webhook_signature(std::string_view secret, std::string_view timestamp,
                              std::string_view body);

class WebhookDispatcher {
 public:
  // `store` must outlive the dispatcher. `wall_ms` gives the time of events and signatures.
  WebhookDispatcher(Store& store, WebhookOptions o, std::function<int64_t()> wall_ms);
  // Stops the worker (an attempt under way finishes first); what is still queued is dropped.
  ~WebhookDispatcher();
  WebhookDispatcher(const WebhookDispatcher&) = delete;
  WebhookDispatcher& operator=(const WebhookDispatcher&) = delete;

  // Queues an event ("record.created", "record.updated", "record.deleted") about `rrn` for the
  // subscriptions of `prefix` ("RRN" for the root namespace). Never blocks on the network.
  void publish(const std::string& event, const std::string& rrn, const std::string& prefix,
               json::Value record);

  std::atomic<uint64_t> delivered{0}, failed{0}, attempts_failed{0}, dropped{0}, skipped{0};
  // Deliveries refused because the host resolved to no public address (counted in failed too).
  std::atomic<uint64_t> refused_address{0};

 private:
  struct Item {
    int64_t due_us = 0;  // steady clock
    uint64_t seq = 0;
    bool is_event = true;
    std::string prefix;  // event
    std::string body;    // the event's JSON (delivery body)
    std::string delivery_id;
    Webhook hook;  // delivery
    int attempt = 0;
    bool operator>(const Item& b) const {
      return due_us != b.due_us ? due_us > b.due_us : seq > b.seq;
    }
  };
  void run();
  void push_locked(Item it, bool retry);
  void expand(const Item& event);
  void attempt(Item it);

  Store& store_;
  WebhookOptions o_;
  std::function<int64_t()> wall_ms_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue_;
  uint64_t seq_ = 0;
  bool stop_ = false;
  std::map<int64_t, int> failures_;  // worker thread only: consecutive failed deliveries
  std::thread worker_;
};

}  // namespace rcan::registry::api
