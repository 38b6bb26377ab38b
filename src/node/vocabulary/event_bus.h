// EventBus: fan-out of node events (ESTOP, safe-stop, control changes, PENDING_AUTH, …) to the
// transports that forward them: WebSocket and gRPC streams, the MQTT events topic.
//
// Every event says who may receive it (an `Audience`). The decision is made once, here, and
// every transport asks `Audience::admits` before forwarding: an event for one principal
// (PROMOTED, PREEMPTED, a held command's outcome) or for owners (PENDING_AUTH) never reaches a
// stream of anyone else, and only events for everyone go to a shared channel such as an MQTT
// topic, whose readers the node cannot tell apart.
//
//   bus.publish(json::Object{{"type", "EVENT"}, {"event", "ESTOP"}});        // everyone
//   bus.publish(body, Audience::principal(p.key()));                         // one principal
//   bus.subscribe([](const Event& ev) { if (ev.audience.admits(who)) send(ev.body); });
//
// Subscribers are called synchronously on the publishing thread and must only enqueue.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "rcan/json.h"
#include "rcan/roles.h"

namespace rcan::node {

// Who may receive an event.
class Audience {
 public:
  // Every stream, and shared channels (the MQTT events topic).
  static Audience everyone() { return Audience(Kind::kEveryone, {}, Role::kGuest); }
  // The streams of one principal (`Principal::key()`) only.
  static Audience principal(std::string key) {
    return Audience(Kind::kPrincipal, std::move(key), Role::kGuest);
  }
  // The streams of principals holding `role` or a higher one.
  static Audience at_least(Role role) { return Audience(Kind::kMinRole, {}, role); }

  // True for events a shared channel may carry.
  bool is_everyone() const { return kind_ == Kind::kEveryone; }
  // May a stream authenticated as `who` receive the event? `who` is null for a stream that
  // has not authenticated, which receives events for everyone only.
  bool admits(const Principal* who) const {
    switch (kind_) {
      case Kind::kEveryone:
        return true;
      case Kind::kPrincipal:
        return who && who->key() == key_;
      case Kind::kMinRole:
        return who && role_level(who->role) >= role_level(min_role_);
    }
    return false;
  }

 private:
  enum class Kind { kEveryone, kPrincipal, kMinRole };
  Audience(Kind k, std::string key, Role r) : kind_(k), key_(std::move(key)), min_role_(r) {}
  Kind kind_;
  std::string key_;
  Role min_role_;
};

struct Event {
  json::Value body;  // what goes on the wire, as it is
  Audience audience = Audience::everyone();
};

class EventBus {
 public:
  using Fn = std::function<void(const Event& event)>;
  uint64_t subscribe(Fn fn) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    subs_[++next_] = std::move(fn);
    return next_;
  }
  void unsubscribe(uint64_t id) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    subs_.erase(id);
  }
  void publish(json::Value body, Audience audience = Audience::everyone()) EXCLUDES(mu_) {
    Event ev{std::move(body), std::move(audience)};
    std::map<uint64_t, Fn> copy;
    {
      MutexLock lock(mu_);
      copy = subs_;
    }
    for (auto& [id, fn] : copy) fn(ev);
  }
  size_t size() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return subs_.size();
  }

 private:
  mutable Mutex mu_;
  std::map<uint64_t, Fn> subs_ GUARDED_BY(mu_);
  uint64_t next_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node
