// Ownership and its transfer (seed §6.2; docs/SESSIONS.md):
//   OWNED --TRANSFER_REQUEST--> TRANSFER_PENDING (window, 24 h by default)
//   TRANSFER_PENDING --TRANSFER_ACCEPT--> OWNED (new owner recorded, personal data cleared)
//   TRANSFER_PENDING --TRANSFER_CANCEL | TRANSFER_EXPIRE--> OWNED (nothing changes)
// The owner is the recorded principal (issuer and subject, PrincipalId); before any transfer
// none is recorded and any OWNER token acts as the owner. After a transfer, tokens of former
// owners are capped to GUEST: the role still comes from the verified token, ownership can only
// lower it. A subject of another issuer is another principal: it neither accepts a transfer
// named for this one nor acts as its owner.
// Personal data cleared on acceptance: control sessions, queue and leases (SessionTable::
// revoke_all), the user list kept here, pending consent, and whatever registered a clear
// hook (e.g. a thought log). The audit chain and skills are kept.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "node/control/control_machine.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct PendingTransfer {
  std::string id;
  PrincipalId from;
  PrincipalId to;
  int64_t requested_ms = 0;
  int64_t expires_ms = 0;
  std::string note;
};

class Ownership {
 public:
  void set_window_ms(int64_t ms) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    window_ms_ = ms;
  }
  int64_t window_ms() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return window_ms_;
  }

  // `to` without an issuer names a subject of the requester's own issuer.
  // Errors: INSUFFICIENT_PRIVILEGES (not the owner), CONTROL_CONFLICT (one is pending),
  // SCHEMA_VALIDATION_FAILED.
  Result<PendingTransfer> request(const Principal& p, PrincipalId to, const std::string& note,
                                  int64_t now_wall_ms) EXCLUDES(mu_);
  // The named new owner accepts with an agreement reference. Errors: NOT_FOUND (nothing
  // pending or another id), SESSION_EXPIRED (the window passed), INSUFFICIENT_PRIVILEGES.
  Result<PendingTransfer> accept(const Principal& p, const std::string& transfer_id,
                                 const std::string& agreement, int64_t now_wall_ms) EXCLUDES(mu_);
  // The owner withdraws, or the named new owner declines.
  Result<PendingTransfer> cancel(const Principal& p, int64_t now_wall_ms) EXCLUDES(mu_);
  // The pending transfer whose window passed (once).
  std::optional<PendingTransfer> expire(int64_t now_wall_ms) EXCLUDES(mu_);
  // True when no transfer is pending (nothing for expire() to find, however late).
  bool quiet() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return !pending_;
  }
  // `fn` runs (under this object's lock: it must not call back) after every change, so that
  // the node's control tick, asleep while nothing is timed, wakes to plan again. Set once,
  // before the object is shared; an empty function removes it.
  void on_change(std::function<void()> fn) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    on_change_ = std::move(fn);
  }

  // Lowers the role of a former owner's token (GUEST).
  void cap(Principal& p) const;
  // A principal that used the robot (the user list, personal data).
  void note_user(const std::string& sub) EXCLUDES(mu_) EXCLUDES(mu_);
  // Hooks run when personal data is cleared (after TRANSFER_ACCEPT).
  void on_clear(std::function<void()> fn) EXCLUDES(mu_);
  void run_clear_hooks() EXCLUDES(mu_);

  OwnershipState state(int64_t now_wall_ms) EXCLUDES(mu_);
  PrincipalId owner() EXCLUDES(mu_);
  std::optional<PendingTransfer> pending() EXCLUDES(mu_);
  json::Value to_json(int64_t now_wall_ms, bool detailed) EXCLUDES(mu_);
  json::Value persist_json() EXCLUDES(mu_);
  void load_json(const json::Value& v) EXCLUDES(mu_);
  uint64_t version() EXCLUDES(mu_);
  uint64_t transition_violations() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return violations_;
  }

 private:
  void transit(OwnershipEvent event, OwnershipState to) REQUIRES(mu_);
  void bump() REQUIRES(mu_);  // a change: the version, and on_change
  bool is_owner_locked(const Principal& p) const REQUIRES(mu_);
  mutable Mutex mu_;
  int64_t window_ms_ GUARDED_BY(mu_) = 24 * 3600 * 1000LL;
  OwnershipState state_ GUARDED_BY(mu_) = OwnershipState::kOwned;
  PrincipalId owner_ GUARDED_BY(mu_);
  std::set<PrincipalId> former_owners_ GUARDED_BY(mu_);
  std::set<std::string> users_ GUARDED_BY(mu_);
  std::optional<PendingTransfer> pending_ GUARDED_BY(mu_);
  std::vector<std::function<void()>> clear_hooks_ GUARDED_BY(mu_);
  uint64_t version_ GUARDED_BY(mu_) = 0;
  uint64_t violations_ GUARDED_BY(mu_) = 0;
  std::function<void()> on_change_ GUARDED_BY(mu_);
};

}  // namespace rcan::node
