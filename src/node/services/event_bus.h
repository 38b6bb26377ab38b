// EventBus — fan-out of node events (ESTOP, safe-stop, session changes, PENDING_AUTH …) to
// every open stream. Subscribers are called synchronously and must only enqueue.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>

#include "rcan/json.h"

namespace rcan::node {

class EventBus {
 public:
  using Fn = std::function<void(const json::Value& event)>;
  uint64_t subscribe(Fn fn) {
    std::lock_guard<std::mutex> lock(mu_);
    subs_[++next_] = std::move(fn);
    return next_;
  }
  void unsubscribe(uint64_t id) {
    std::lock_guard<std::mutex> lock(mu_);
    subs_.erase(id);
  }
  void publish(const json::Value& event) {
    std::map<uint64_t, Fn> copy;
    {
      std::lock_guard<std::mutex> lock(mu_);
      copy = subs_;
    }
    for (auto& [id, fn] : copy) fn(event);
  }
  size_t size() const {
    std::lock_guard<std::mutex> lock(mu_);
    return subs_.size();
  }

 private:
  mutable std::mutex mu_;
  std::map<uint64_t, Fn> subs_;
  uint64_t next_ = 0;
};

}  // namespace rcan::node
