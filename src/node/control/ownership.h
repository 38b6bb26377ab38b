// Ownership and its transfer (seed §6.2; docs/SESSIONS.md):
//   OWNED --TRANSFER_REQUEST--> TRANSFER_PENDING (window, 24 h by default)
//   TRANSFER_PENDING --TRANSFER_ACCEPT--> OWNED (new owner recorded, personal data cleared)
//   TRANSFER_PENDING --TRANSFER_CANCEL | TRANSFER_EXPIRE--> OWNED (nothing changes)
// The owner is the recorded `sub`; before any transfer none is recorded and any OWNER token
// acts as the owner. After a transfer, tokens of former owners are capped to GUEST: the
// role still comes from the verified token, ownership can only lower it.
// Personal data cleared on acceptance: control sessions, queue and leases (SessionTable::
// revoke_all), the user list kept here, pending consent, and whatever registered a clear
// hook (e.g. a thought log). The audit chain and skills are kept.
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "node/admission/authenticator.h"
#include "node/control/control_machine.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct PendingTransfer {
  std::string id;
  std::string from_sub;
  std::string to_sub;
  int64_t requested_ms = 0;
  int64_t expires_ms = 0;
  std::string note;
};

class Ownership {
 public:
  void set_window_ms(int64_t ms) { window_ms_ = ms; }
  int64_t window_ms() const { return window_ms_; }

  // Errors: INSUFFICIENT_PRIVILEGES (not the owner), CONTROL_CONFLICT (one is pending),
  // SCHEMA_VALIDATION_FAILED.
  Result<PendingTransfer> request(const Principal& p, const std::string& to_sub,
                                  const std::string& note, int64_t now_wall_ms);
  // The named new owner accepts with an agreement reference. Errors: NOT_FOUND (nothing
  // pending or another id), SESSION_EXPIRED (the window passed), INSUFFICIENT_PRIVILEGES.
  Result<PendingTransfer> accept(const Principal& p, const std::string& transfer_id,
                                 const std::string& agreement, int64_t now_wall_ms);
  // The owner withdraws, or the named new owner declines.
  Result<PendingTransfer> cancel(const Principal& p, int64_t now_wall_ms);
  // The pending transfer whose window passed (once).
  std::optional<PendingTransfer> expire(int64_t now_wall_ms);

  // Lowers the role of a former owner's token (GUEST).
  void cap(Principal& p) const;
  // A principal that used the robot (the user list, personal data).
  void note_user(const std::string& sub);
  // Hooks run when personal data is cleared (after TRANSFER_ACCEPT).
  void on_clear(std::function<void()> fn);
  void run_clear_hooks();

  OwnershipState state(int64_t now_wall_ms);
  std::string owner();
  std::optional<PendingTransfer> pending();
  json::Value to_json(int64_t now_wall_ms, bool detailed);
  json::Value persist_json();
  void load_json(const json::Value& v);
  uint64_t version();
  uint64_t transition_violations() const { return violations_; }

 private:
  void transit(OwnershipEvent event, OwnershipState to);
  bool is_owner_locked(const Principal& p) const;
  mutable std::mutex mu_;
  int64_t window_ms_ = 24 * 3600 * 1000LL;
  OwnershipState state_ = OwnershipState::kOwned;
  std::string owner_sub_;
  std::set<std::string> former_owners_;
  std::set<std::string> users_;
  std::optional<PendingTransfer> pending_;
  std::vector<std::function<void()>> clear_hooks_;
  uint64_t version_ = 0;
  uint64_t violations_ = 0;
};

}  // namespace rcan::node
