// SessionTable — who controls the robot (seed §2.3, §4.3.5, §5.3; docs/SESSIONS.md).
//
//   * claim: a verified principal asks for control. AVAILABLE → GRANTED. A holder of a lower
//     role is pre-empted (higher role wins). The same role → the claimant joins a FIFO queue
//     and is told its position (first claim wins); when the holder releases or expires, the
//     head of the queue is promoted. A lower role → DENIED. Fleet vs individual claims of the
//     same role follow the configured fleet policy. The same principal re-claiming renews
//     explicitly (never implicitly).
//   * a session lasts its role's TTL (roles.h; GUEST: the guest session length), bounded by
//     the lease it was granted under; renew() is the other explicit renewal;
//   * release ends it; only its holder (or a higher role) may release it;
//   * handoff: the holder names a successor; the session ends and the robot is AVAILABLE for
//     a window reserved for that successor (other claims are DENIED until it closes). The
//     successor's role comes from its own token, lowered to the role the handoff names;
//   * leases: an OWNER grants a LEASEE a time-bound lease (one at a time); the LEASEE grants
//     USER/GUEST access inside it; while a lease runs, principals below OWNER that are neither
//     the leasee nor granted by it cannot claim; the lease's end revokes everything derived.
// The role always comes from the verified token: a body can only ask for a lower role.
//
// Every mutation that others must hear about (expiry, promotion, revocation, window close,
// lease end) is queued as a Change; the node drains them (take_changes) to announce them on
// the streams and write their audit records. Every state move is checked against
// control_transitions() (control_machine.h).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "node/control/control_machine.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

enum class FleetPolicy { kRole, kFleetWins, kIndividualWins };
std::string_view fleet_policy_name(FleetPolicy p);
std::optional<FleetPolicy> fleet_policy_from_name(std::string_view s);

struct ControlOptions {
  int64_t handoff_window_ms = 30'000;
  size_t queue_max = 16;
  int64_t queue_wait_ms = 300'000;  // a queued claim is dropped after this long
  // A queued claimant whose last stream closed (a closed tab) leaves the queue after this long
  // without a stream of its own (the node's control tick calls drop_queued).
  int64_t queue_stream_grace_ms = 5'000;
  FleetPolicy fleet_policy = FleetPolicy::kRole;
  uint32_t guest_session_s = 15 * 60;
  int64_t max_session_ms = 0;  // caps every role's TTL (control.max_session_s); 0 = role TTLs
};

// The token a claim was made with: a revocation of it (by jti, header kid or subject) ends the
// session it holds and drops its queued claim (ControlService::end_revoked).
struct ClaimToken {
  std::string jti;
  std::string kid;
  std::optional<int64_t> iat;  // unix seconds
  static ClaimToken of(const Principal& p) { return ClaimToken{p.jti, p.kid, p.token_iat}; }
};

struct Session {
  std::string id;
  std::string principal_key;
  std::string iss;
  std::string sub;
  Role role = Role::kGuest;
  int64_t granted_mono_ms = 0;
  int64_t expires_mono_ms = 0;  // 0 = never (CREATOR)
  int64_t granted_wall_ms = 0;
  std::string lease_id;  // granted under this lease (as its leasee or a grantee)
  // Its end is the lease's (or the grant's) end: reaching it is a revocation by the lease,
  // whichever clock notices first (the lease is timed on the wall clock, sessions on the
  // monotonic one).
  bool ends_with_lease = false;
  bool fleet = false;
  ClaimToken token;  // the one that claimed it or last renewed it
  PrincipalId who() const { return PrincipalId{iss, sub}; }
  // The holder as the revocation list judges it: with that token.
  Principal as_principal() const;
};

struct Reservation {
  PrincipalId target;            // issuer and subject
  std::optional<Role> max_role;  // the handoff's target_role (can only lower)
  std::string from_session;
  int64_t until_mono_ms = 0;
};

struct QueuedClaim {
  std::string principal_key;
  std::string iss;
  std::string sub;
  Role role = Role::kGuest;
  bool fleet = false;
  int64_t enqueued_mono_ms = 0;
  ClaimToken token;  // the one it last claimed with
  PrincipalId who() const { return PrincipalId{iss, sub}; }
  Principal as_principal() const;
};

struct LeaseGrant {
  PrincipalId who;          // issuer and subject
  Role role = Role::kUser;  // USER or GUEST
  int64_t end_wall_ms = 0;
};

struct Lease {
  std::string id;
  PrincipalId leasee;  // issuer and subject
  std::string granted_by;
  int64_t start_wall_ms = 0;
  int64_t end_wall_ms = 0;
  std::vector<LeaseGrant> grants;
  json::Value to_json(int64_t now_wall_ms) const;
};

enum class ClaimOutcome { kGranted, kRenewed, kQueued };

struct ClaimResult {
  ClaimOutcome outcome = ClaimOutcome::kGranted;
  Session session;                   // kGranted / kRenewed
  std::optional<Session> preempted;  // the holder this claim displaced
  size_t queue_position = 0;         // kQueued: 1-based
};

// Something the node must announce and audit.
struct ControlChange {
  ControlEvent event =
      ControlEvent::kExpire;  // EXPIRE, PROMOTE, REVOKE, WINDOW_CLOSE, QUEUE_DROP, LEASE_END
  Session session;            // the session concerned (EXPIRE, PROMOTE, REVOKE)
  QueuedClaim queued;         // QUEUE_DROP
  std::string lease_id;
  std::string reason;
};

class SessionTable {
 public:
  SessionTable() = default;
  void set_options(ControlOptions o) EXCLUDES(mu_);
  ControlOptions options() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return opts_;
  }

  // Errors: CONTROL_CONFLICT (higher role holds, reserved window, leased, queue full).
  Result<ClaimResult> claim(const Principal& p, std::optional<Role> requested, bool fleet,
                            int64_t now_mono_ms, int64_t now_wall_ms) EXCLUDES(mu_);
  // Compatibility overload (an individual claim).
  Result<ClaimResult> claim(const Principal& p, std::optional<Role> requested, int64_t now_mono_ms,
                            int64_t now_wall_ms) {
    return claim(p, requested, false, now_mono_ms, now_wall_ms);
  }
  // Explicit renewal by the holder. Errors: NOT_FOUND, INSUFFICIENT_PRIVILEGES, SESSION_EXPIRED.
  Result<Session> renew(const std::string& session_id, const Principal& p, int64_t now_mono_ms,
                        int64_t now_wall_ms) EXCLUDES(mu_);
  // Errors: NOT_FOUND (no such session), INSUFFICIENT_PRIVILEGES (not the holder).
  Result<Session> release(const std::string& session_id, const Principal& p, int64_t now_mono_ms,
                          int64_t now_wall_ms = 0) EXCLUDES(mu_);
  // Ends the holder's session and reserves control for `target` for the window (without an
  // issuer: a subject of the holder's issuer).
  Result<Session> handoff(const std::string& session_id, const Principal& p, PrincipalId target,
                          std::optional<Role> target_role, int64_t window_ms, int64_t now_mono_ms)
      EXCLUDES(mu_);
  // Leaves the queue (the claimant gave up). True when it was queued.
  bool leave_queue(const Principal& p) EXCLUDES(mu_);
  // Drops this principal's queued claim, announced and audited as CLAIM_DROPPED with `reason`
  // (take_changes). True when it was queued.
  bool drop_queued(const std::string& principal_key, const std::string& reason) EXCLUDES(mu_);
  // The queued claims, first in line first.
  std::vector<QueuedClaim> queued() EXCLUDES(mu_);

  // Expiries, window closes, lease ends. Call often (the node does every 100 ms).
  void tick(int64_t now_mono_ms, int64_t now_wall_ms) EXCLUDES(mu_);
  // True when nothing here waits for a time (no holder, reservation, queued claim, lease, or
  // change to announce): tick() would do nothing however long the node waits.
  bool quiet() EXCLUDES(mu_);
  // `fn` runs (under this object's lock: it must not call back) after every change, so that
  // the node's control tick, asleep while nothing is timed, wakes to plan again. Set once,
  // before the object is shared; an empty function removes it.
  void on_change(std::function<void()> fn) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    on_change_ = std::move(fn);
  }

  std::vector<ControlChange> take_changes() EXCLUDES(mu_);

  // Ends every session, the queue, the reservation and every lease (ownership transfer).
  void revoke_all(const std::string& reason, int64_t now_mono_ms) EXCLUDES(mu_);

  std::optional<Reservation> reservation(int64_t now_mono_ms) EXCLUDES(mu_);
  // The live controller, if any (an expired holder counts as absent; tick() ends it).
  std::optional<Session> controller(int64_t now_mono_ms, std::vector<Session>* expired = nullptr)
      EXCLUDES(mu_);
  std::optional<Session> find(const std::string& session_id, int64_t now_mono_ms);
  bool live(const std::string& session_id, int64_t now_mono_ms);
  // Runs `fn` only while the session is live, holding the table: a pre-emption, expiry or
  // revocation happens entirely before or entirely after it. False when not live.
  bool run_if_live(const std::string& session_id, int64_t now_mono_ms,
                   const std::function<void()>& fn) EXCLUDES(mu_);
  // The session this principal held that expired or was revoked (until it claims again).
  std::optional<std::string> expired_session_of(const std::string& principal_key) EXCLUDES(mu_);
  ControlState state(int64_t now_mono_ms) EXCLUDES(mu_);
  size_t queue_size() EXCLUDES(mu_);
  json::Value to_json(int64_t now_mono_ms, bool detailed) EXCLUDES(mu_);
  json::Value queue_json(int64_t now_mono_ms) EXCLUDES(mu_);

  // Leases. Errors: INSUFFICIENT_PRIVILEGES, CONTROL_CONFLICT (one already runs),
  // SCHEMA_VALIDATION_FAILED, NOT_FOUND.
  // `now_mono_ms` (optional, -1 = not given) lets a wall-clock step since the last reading be
  // absorbed first, so that a lease granted just after a step is not shifted by it later.
  // A principal named without an issuer is one of the granting principal's issuer.
  Result<Lease> grant_lease(const Principal& owner, PrincipalId leasee, int64_t duration_ms,
                            int64_t now_wall_ms, int64_t now_mono_ms = -1) EXCLUDES(mu_);
  Result<Lease> grant_within_lease(const Principal& leasee, const std::string& lease_id,
                                   PrincipalId who, Role role, int64_t duration_ms,
                                   int64_t now_wall_ms, int64_t now_mono_ms = -1) EXCLUDES(mu_);
  Result<Lease> revoke_lease(const Principal& p, const std::string& lease_id, int64_t now_mono_ms,
                             int64_t now_wall_ms) EXCLUDES(mu_);
  std::vector<Lease> leases(int64_t now_wall_ms) EXCLUDES(mu_);
  json::Value leases_json(int64_t now_wall_ms) EXCLUDES(mu_);
  // Persistence of the leases (sessions are not persisted: they die with the process).
  json::Value persist_json() EXCLUDES(mu_);
  void load_json(const json::Value& v, int64_t now_wall_ms) EXCLUDES(mu_);

  uint64_t transition_violations() const EXCLUDES(mu_) {
    MutexLock lock(mu_);
    return violations_;
  }
  uint64_t version() EXCLUDES(mu_);  // bumps on every change (persistence, mDNS status)

 private:
  void transit(ControlEvent event, ControlState to) REQUIRES(mu_);
  void bump() REQUIRES(mu_);  // a change: the version, and on_change
  ControlState state_locked() const REQUIRES(mu_);
  void expire_locked(int64_t now_mono_ms) REQUIRES(mu_);
  void drop_holder_locked(ControlEvent event, const std::string& reason, int64_t now_mono_ms)
      REQUIRES(mu_);
  void promote_locked(int64_t now_mono_ms, int64_t now_wall_ms) REQUIRES(mu_);
  Session make_session_locked(const std::string& key, const PrincipalId& who, Role role, bool fleet,
                              const ClaimToken& token, int64_t now_mono_ms, int64_t now_wall_ms,
                              const std::string& id = {}) REQUIRES(mu_);
  const Lease* active_lease_locked(int64_t now_wall_ms) const REQUIRES(mu_);
  // The lease link and role cap of a claimant; false when a lease runs and excludes it.
  bool lease_link_locked(const PrincipalId& who, Role& role, std::string& lease_id,
                         int64_t& end_wall, int64_t now_wall_ms) const REQUIRES(mu_);
  // Lease times are wall-clock (they are shown and persisted as such) but run on the
  // monotonic clock: a wall-clock step seen between two calls that carry both clocks shifts
  // every lease and grant by the step (docs/NODE.md §Faults).
  void absorb_wall_step_locked(int64_t now_mono_ms, int64_t now_wall_ms) REQUIRES(mu_);

  mutable Mutex mu_;
  ControlOptions opts_ GUARDED_BY(mu_);
  std::optional<Session> holder_ GUARDED_BY(mu_);
  std::optional<Reservation> reserved_ GUARDED_BY(mu_);
  std::deque<QueuedClaim> queue_ GUARDED_BY(mu_);
  std::map<std::string, std::string> expired_ GUARDED_BY(mu_);  // principal key → session id
  std::vector<Lease> leases_ GUARDED_BY(mu_);
  std::vector<ControlChange> changes_ GUARDED_BY(mu_);
  ControlState state_ GUARDED_BY(mu_) = ControlState::kAvailable;
  int64_t last_wall_ms_ GUARDED_BY(mu_) = 0;
  int64_t anchor_mono_ms_ GUARDED_BY(mu_) = -1;  // -1: no reading yet
  int64_t anchor_wall_ms_ GUARDED_BY(mu_) = 0;
  uint64_t violations_ GUARDED_BY(mu_) = 0;
  uint64_t version_ GUARDED_BY(mu_) = 0;
  std::function<void()> on_change_ GUARDED_BY(mu_);
};

}  // namespace rcan::node
