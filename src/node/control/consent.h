// Consent requests (§8.5 "Consent Requests from Cloud Functions"; docs/SESSIONS.md): a party
// (human, robot or cloud function) asks the owner for access with scopes; the owner is told
// (stream + webhook) with the seed's notification payload and grants (a scoped, time-bound
// lease or grant) or denies. Pending requests expire.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct ConsentRequest {
  std::string id;
  std::string requester_sub;
  std::string requester_iss;  // with the subject, the principal a grant goes to
  PrincipalId requester() const { return PrincipalId{requester_iss, requester_sub}; }
  std::string sender_type = "human";
  std::string cloud_provider;
  std::string function_name;
  std::string on_behalf_of;
  std::string reason;
  std::vector<std::string> scopes;
  int64_t duration_s = 3600;
  int64_t created_ms = 0;
  int64_t expires_ms = 0;
  std::string status = "PENDING";  // PENDING, GRANTED, DENIED, EXPIRED
  std::string decided_by;
  int64_t decided_ms = 0;
  std::string grant_kind;  // "lease" | "grant"
  std::string lease_id;
  json::Value to_json() const;
};

// The owner notification of §8.5: for a cloud function its identity is in title, body and
// highlight; a human request says who asks.
json::Value consent_notification(const ConsentRequest& r, const std::string& robot_name);

class ConsentBook {
 public:
  void set_pending_ttl_ms(int64_t ms) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    ttl_ms_ = ms;
  }
  // Errors: CONTROL_CONFLICT when too many are pending.
  Result<ConsentRequest> add(ConsentRequest r, int64_t now_ms) EXCLUDES(mu_);
  Result<ConsentRequest> get(const std::string& id) EXCLUDES(mu_);
  // Errors: NOT_FOUND, CONTROL_CONFLICT (already decided), SESSION_EXPIRED.
  Result<ConsentRequest> decide(const std::string& id, bool grant, const std::string& by,
                                const std::string& kind, const std::string& lease_id,
                                int64_t now_ms) EXCLUDES(mu_);
  std::vector<ConsentRequest> expire(int64_t now_ms) EXCLUDES(mu_);
  // True when no request is pending (nothing for expire() to find, however late).
  bool quiet() EXCLUDES(mu_);
  // `fn` runs (under this object's lock: it must not call back) after every change, so that
  // the node's control tick, asleep while nothing is timed, wakes to plan again. Set once,
  // before the object is shared; an empty function removes it.
  void on_change(std::function<void()> fn) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    on_change_ = std::move(fn);
  }

  std::vector<ConsentRequest> list() EXCLUDES(mu_);
  void clear() EXCLUDES(mu_);
  json::Value persist_json() EXCLUDES(mu_);
  void load_json(const json::Value& v) EXCLUDES(mu_);
  uint64_t version() EXCLUDES(mu_);

 private:
  Mutex mu_;
  std::vector<ConsentRequest> items_ GUARDED_BY(mu_);
  int64_t ttl_ms_ GUARDED_BY(mu_) = 24 * 3600 * 1000LL;
  uint64_t version_ GUARDED_BY(mu_) = 0;
  std::function<void()> on_change_ GUARDED_BY(mu_);
  void bump() REQUIRES(mu_);  // a change: the version, and on_change
};

}  // namespace rcan::node
