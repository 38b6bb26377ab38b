// ControlService — who holds the robot, as a policy: claims (partition modes, pre-emption,
// the deadman), renewals, release, handoff, the queue, leases, ownership transfer and consent
// requests (docs/SESSIONS.md). It owns the session table, ownership, the consent book and the
// partition monitor; it writes their audit records (AuditTrail), publishes their events
// (EventBus), arms and stops the robot through Actuation, announces what its control tick
// finds, and keeps the control state file (leases, ownership, consent, credentials).
//
// Operations take the verified principal and the request's parsed fields, and answer with a
// ControlAnswer: a refusal, or a body and the audit record to write before answering. A
// transport (the HTTP routes, node/api/control_routes.cpp) authenticates, parses, writes the
// record and answers; nothing here knows HTTP.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "node/admission/authenticator.h"
#include "node/admission/revocation.h"
#include "node/control/consent.h"
#include "node/control/ownership.h"
#include "node/control/partition.h"
#include "node/control/sessions.h"
#include "node/safety/actuation.h"
#include "node/vocabulary/audit_record.h"
#include "node/vocabulary/audit_trail.h"
#include "node/vocabulary/event_bus.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/roles.h"

namespace rcan::node {

// What control policy needs of the node's settings.
struct ControlSettings {
  std::string robot_name;  // named in the owner's consent notification
  std::string state_dir;   // the control state file's folder ("" = not kept)
  RolePolicy role_policy;
  int64_t heartbeat_timeout_ms = 0;
  int64_t handoff_window_ms = 30'000;
};

// The answer to a control operation. Refused: `error` (its audit record, if any, is written).
// Otherwise `body` with `status`, wrapped as the payload of an `envelope` message when set,
// sent once `record` (when set) is durable.
struct ControlAnswer {
  std::optional<Error> error;
  int status = 200;
  json::Value body;
  std::optional<MessageType> envelope;
  std::optional<AuditRecord> record;

  static ControlAnswer refused(Error e) {
    ControlAnswer a;
    a.error = std::move(e);
    return a;
  }
};

struct ClaimRequest {
  std::optional<Role> role;  // a lower role than the token's, if asked
  std::string fleet_id;      // a fleet claim when not empty
  bool rearm = false;        // re-arm after ESTOP (docs/NODE.md)
};

struct RenewRequest {
  std::string session_id;
  bool rearm = false;
  bool udp_heartbeat = false;  // a fresh UDP heartbeat key (on_grant)
};

struct HandoffRequest {
  std::string session_id;
  PrincipalId target;  // without an issuer: the holder's
  std::optional<Role> target_role;
  std::string reason;
};

struct TransferRequest {
  std::string action;  // request, accept, cancel
  PrincipalId new_owner;
  std::string note;
  std::string transfer_id;
  std::string agreement;
};

struct ConsentDecision {
  bool grant = false;
  std::string kind;  // grant: lease or grant ("" = lease)
  std::optional<int64_t> duration_s;
  std::string reason;
};

class ControlService {
 public:
  ControlService(ControlSettings settings, Clock& clock, AuditTrail& trail, EventBus& events,
                 Actuation& act);
  ~ControlService();
  ControlService(const ControlService&) = delete;
  ControlService& operator=(const ControlService&) = delete;

  SessionTable& sessions() { return sessions_; }
  Ownership& ownership() { return ownership_; }
  const Ownership& ownership() const { return ownership_; }
  ConsentBook& consent() { return consent_; }
  PartitionMonitor& partition() { return partition_; }
  const ControlSettings& settings() const { return settings_; }

  // What adds to a GRANTED answer (the UDP heartbeat key, src/node/bindings/udp_service.h):
  // called with the session's id and the answer's payload. Set once, before serving.
  void set_on_grant(std::function<void(const std::string& session_id, json::Object& payload)> fn) {
    on_grant_ = std::move(fn);
  }

  // Loads the control state file, starts the partition monitor; `wake` runs on every change to
  // timed control state (the node's control tick sleeps while there is none).
  void start(std::function<void()> wake) EXCLUDES(state_mu_);
  // Stops the monitor, removes the wake hooks and saves the state.
  void stop() EXCLUDES(save_mu_);
  // Expiries, promotions, lease ends, transfer and consent expiries; `streamless` are the
  // principals (keys) whose last stream closed past their grace: their queued claims go.
  void tick(const std::vector<std::string>& streamless = {}) EXCLUDES(state_mu_, save_mu_);
  // True when nothing waits for a time.
  bool quiet();
  // Writes what changed of leases, ownership, consent and credentials.
  void save() EXCLUDES(save_mu_);

  // Control sessions (POST /rcan/v1/auth/claim, renew, release; handoff; the queue).
  ControlAnswer claim(const Principal& p, const ClaimRequest& r) EXCLUDES(state_mu_, save_mu_);
  ControlAnswer renew(const Principal& p, const RenewRequest& r) EXCLUDES(state_mu_, save_mu_);
  // An empty `session_id`: the principal's own session, if it holds one.
  ControlAnswer release(const Principal& p, std::string session_id) EXCLUDES(state_mu_, save_mu_);
  ControlAnswer handoff(const Principal& p, HandoffRequest r) EXCLUDES(state_mu_, save_mu_);
  json::Value queue();
  ControlAnswer leave_queue(const Principal& p);
  // A revocation ends the control session of the token it names (by jti, header kid, or
  // subject for tokens issued up to it): the session remembers the token that claimed it or
  // last renewed it. Released as the holder would, its motion stopped: RELEASE recorded with
  // reason token_revoked, AVAILABLE or the next claimant promoted. A queued claim made with a
  // revoked token is dropped (CLAIM_DROPPED, token_revoked), never promoted to control.
  void end_revoked(const RevocationList& revocations) EXCLUDES(state_mu_, save_mu_);

  // Leases (control_grants.cpp).
  json::Value leases();
  ControlAnswer grant_lease(const Principal& owner, const PrincipalId& leasee, int64_t duration_s)
      EXCLUDES(state_mu_, save_mu_);
  ControlAnswer grant_within_lease(const Principal& leasee, const std::string& lease_id,
                                   const PrincipalId& user, Role role, int64_t duration_s)
      EXCLUDES(state_mu_, save_mu_);
  ControlAnswer revoke_lease(const Principal& owner, const std::string& lease_id)
      EXCLUDES(state_mu_, save_mu_);

  // Ownership transfer: the state (in full for OWNER), and request / accept / cancel.
  json::Value transfer_state(const Principal& p);
  ControlAnswer transfer(const Principal& p, const TransferRequest& r)
      EXCLUDES(state_mu_, save_mu_);

  // Consent requests: the pending ones, a new one (202; `added` is what was recorded) and the
  // owner's decision.
  json::Value consent_requests();
  ControlAnswer request_consent(const Principal& p, ConsentRequest c, const std::string& message_id,
                                ConsentRequest* added) EXCLUDES(save_mu_);
  ControlAnswer decide_consent(const Principal& p, const std::string& id, const ConsentDecision& d)
      EXCLUDES(state_mu_, save_mu_);

 private:
  // Audits and announces what the session table queued (take_changes), the control state's
  // change, and saves.
  void announce() EXCLUDES(state_mu_, save_mu_);
  void announce_change(const ControlChange& c);
  // A claim queued behind a holder of the same role: recorded, answered 409 with its place.
  ControlAnswer queued(const Principal& p, size_t position);
  // A higher role's claim displaced `displaced`: stopped, told and recorded.
  void preempt(const Session& displaced, const Principal& by, Role by_role, int64_t now_wall);
  void publish_to(const std::string& principal_key, json::Object ev);
  void publish(json::Object ev);
  // Publishes AVAILABLE when `released` left the robot free.
  void publish_available(const std::string& released, int64_t now_wall);
  json::Array capabilities_of(Role r) const;
  void record_partition_mode(NetMode old, NetMode now) EXCLUDES(save_mu_);

  const ControlSettings settings_;
  Clock& clock_;
  AuditTrail& trail_;
  EventBus& events_;
  Actuation& act_;
  SessionTable sessions_;
  Ownership ownership_;
  ConsentBook consent_;
  PartitionMonitor partition_;
  std::function<void(const std::string&, json::Object&)> on_grant_;
  Mutex state_mu_;
  std::string last_state_ GUARDED_BY(state_mu_);
  Mutex save_mu_;
  uint64_t saved_versions_[4] GUARDED_BY(save_mu_) = {0, 0, 0, 0};
};

}  // namespace rcan::node
