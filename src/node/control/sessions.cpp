#include "node/control/sessions.h"

#include <algorithm>

#include "rcan/errors.h"

namespace rcan::node {

std::string_view fleet_policy_name(FleetPolicy p) {
  switch (p) {
    case FleetPolicy::kRole:
      return "role";
    case FleetPolicy::kFleetWins:
      return "fleet_wins";
    case FleetPolicy::kIndividualWins:
      return "individual_wins";
  }
  return "role";
}

namespace {

// Why a session derived from a lease ended with it: the lease's end (its leasee's session) or
// the end of a grant within it (a grantee's).
std::string lease_end_reason(bool as_leasee, const std::string& lease_id) {
  return (as_leasee ? "the lease " : "the grant within lease ") + lease_id + " ended";
}

}  // namespace

std::optional<FleetPolicy> fleet_policy_from_name(std::string_view s) {
  if (s == "role") return FleetPolicy::kRole;
  if (s == "fleet_wins") return FleetPolicy::kFleetWins;
  if (s == "individual_wins") return FleetPolicy::kIndividualWins;
  return std::nullopt;
}

json::Value Lease::to_json(int64_t now_wall_ms) const {
  json::Array g;
  for (const auto& x : grants)
    g.push_back(json::Object{{"sub", x.who.sub},
                             {"iss", x.who.iss},
                             {"role", std::string(role_name(x.role))},
                             {"end_ms", x.end_wall_ms},
                             {"active", x.end_wall_ms > now_wall_ms}});
  return json::Object{{"lease_id", id},
                      {"leasee", leasee.sub},
                      {"leasee_iss", leasee.iss},
                      {"granted_by", granted_by},
                      {"start_ms", start_wall_ms},
                      {"end_ms", end_wall_ms},
                      {"remaining_s", std::max<int64_t>(0, (end_wall_ms - now_wall_ms) / 1000)},
                      {"grants", g}};
}

void SessionTable::set_options(ControlOptions o) {
  MutexLock lock(mu_);
  opts_ = o;
}

ControlState SessionTable::state_locked() const {
  if (holder_) return ControlState::kHeld;
  if (reserved_) return ControlState::kReserved;
  return ControlState::kAvailable;
}

void SessionTable::transit(ControlEvent event, ControlState to) {
  if (!control_transition_allowed(state_, event, to)) ++violations_;
  state_ = to;
  bump();
}

void SessionTable::bump() {
  ++version_;
  if (on_change_) on_change_();
}

bool SessionTable::quiet() {
  MutexLock lock(mu_);
  return !holder_ && !reserved_ && queue_.empty() && leases_.empty() && changes_.empty();
}

uint64_t SessionTable::version() {
  MutexLock lock(mu_);
  return version_;
}

const Lease* SessionTable::active_lease_locked(int64_t now_wall_ms) const {
  for (const auto& l : leases_)
    if (l.start_wall_ms <= now_wall_ms && now_wall_ms < l.end_wall_ms) return &l;
  return nullptr;
}

bool SessionTable::lease_link_locked(const PrincipalId& who, Role& role, std::string& lease_id,
                                     int64_t& end_wall, int64_t now_wall_ms) const {
  const Lease* l = active_lease_locked(now_wall_ms);
  if (!l) return true;
  if (l->leasee.is(who)) {
    lease_id = l->id;
    end_wall = l->end_wall_ms;
    return true;
  }
  for (const auto& g : l->grants) {
    if (g.who.is(who) && g.end_wall_ms > now_wall_ms) {
      if (role_level(g.role) < role_level(role)) role = g.role;  // only lowers
      lease_id = l->id;
      end_wall = std::min(g.end_wall_ms, l->end_wall_ms);
      return true;
    }
  }
  return role_level(role) >= role_level(Role::kOwner);  // the owner stays above any lease
}

namespace {
Principal claimant(const std::string& iss, const std::string& sub, Role role,
                   const ClaimToken& token) {
  Principal p;
  p.authenticated = true;
  p.issuer = iss;
  p.sub = sub;
  p.role = role;
  p.jti = token.jti;
  p.kid = token.kid;
  p.token_iat = token.iat;
  return p;
}
}  // namespace

Principal Session::as_principal() const { return claimant(iss, sub, role, token); }
Principal QueuedClaim::as_principal() const { return claimant(iss, sub, role, token); }

Session SessionTable::make_session_locked(const std::string& key, const PrincipalId& who, Role role,
                                          bool fleet, const ClaimToken& token, int64_t now_mono_ms,
                                          int64_t now_wall_ms, const std::string& id) {
  Session s;
  s.id = id.empty() ? new_uuid_v4() : id;
  s.token = token;
  s.principal_key = key;
  s.iss = who.iss;
  s.sub = who.sub;
  s.role = role;
  s.fleet = fleet;
  s.granted_mono_ms = now_mono_ms;
  s.granted_wall_ms = now_wall_ms;
  uint32_t ttl = role == Role::kGuest ? opts_.guest_session_s : session_ttl_seconds(role);
  s.expires_mono_ms = ttl ? now_mono_ms + int64_t{ttl} * 1000 : 0;
  if (opts_.max_session_ms > 0 &&
      (s.expires_mono_ms == 0 || s.expires_mono_ms > now_mono_ms + opts_.max_session_ms))
    s.expires_mono_ms = now_mono_ms + opts_.max_session_ms;
  Role r = role;
  int64_t end_wall = 0;
  if (lease_link_locked(who, r, s.lease_id, end_wall, now_wall_ms)) s.role = r;
  if (end_wall) {
    int64_t end_mono = now_mono_ms + (end_wall - now_wall_ms);
    if (s.expires_mono_ms == 0 || end_mono <= s.expires_mono_ms) {
      s.expires_mono_ms = end_mono;
      s.ends_with_lease = true;
    }
  }
  expired_.erase(key);
  return s;
}

void SessionTable::drop_holder_locked(ControlEvent event, const std::string& reason,
                                      int64_t now_mono_ms) {
  (void)now_mono_ms;
  if (!holder_) return;
  ControlChange c;
  c.event = event;
  c.session = *holder_;
  c.lease_id = holder_->lease_id;
  c.reason = reason;
  if (event == ControlEvent::kExpire || event == ControlEvent::kRevoke) {
    expired_[holder_->principal_key] = holder_->id;
    if (expired_.size() > 4096) expired_.erase(expired_.begin());
  }
  holder_.reset();
  transit(event, ControlState::kAvailable);
  changes_.push_back(std::move(c));
}

void SessionTable::promote_locked(int64_t now_mono_ms, int64_t now_wall_ms) {
  while (!holder_ && !reserved_ && !queue_.empty()) {
    QueuedClaim q = queue_.front();
    queue_.pop_front();
    Role role = q.role;
    std::string lease_id;
    int64_t end_wall = 0;
    if (now_mono_ms - q.enqueued_mono_ms > opts_.queue_wait_ms ||
        !lease_link_locked(q.who(), role, lease_id, end_wall, now_wall_ms)) {
      ControlChange c;
      c.event = ControlEvent::kQueueDrop;
      c.queued = q;
      c.reason = now_mono_ms - q.enqueued_mono_ms > opts_.queue_wait_ms ? "waited too long"
                                                                        : "the robot is leased";
      changes_.push_back(std::move(c));
      continue;
    }
    // AVAILABLE for an instant: the head of the queue claims it.
    holder_ = make_session_locked(q.principal_key, q.who(), role, q.fleet, q.token, now_mono_ms,
                                  now_wall_ms);
    transit(ControlEvent::kClaim, ControlState::kHeld);
    ControlChange c;
    c.event = ControlEvent::kPromote;
    c.session = *holder_;
    changes_.push_back(std::move(c));
  }
}

void SessionTable::expire_locked(int64_t now_mono_ms) {
  if (holder_ && holder_->expires_mono_ms != 0 && now_mono_ms >= holder_->expires_mono_ms) {
    if (holder_->ends_with_lease) {
      bool leasee = false;
      for (const auto& l : leases_)
        if (l.id == holder_->lease_id && l.leasee.is(holder_->who())) leasee = true;
      drop_holder_locked(ControlEvent::kRevoke, lease_end_reason(leasee, holder_->lease_id),
                         now_mono_ms);
    } else
      drop_holder_locked(ControlEvent::kExpire, "the session's TTL ended without renewal",
                         now_mono_ms);
  }
  if (reserved_ && now_mono_ms >= reserved_->until_mono_ms) {
    reserved_.reset();
    transit(ControlEvent::kWindowClose, ControlState::kAvailable);
    ControlChange c;
    c.event = ControlEvent::kWindowClose;
    changes_.push_back(std::move(c));
  }
}

Result<ClaimResult> SessionTable::claim(const Principal& p, std::optional<Role> requested,
                                        bool fleet, int64_t now_mono_ms, int64_t now_wall_ms) {
  Role role = p.role;
  if (requested && role_level(*requested) < role_level(role)) role = *requested;  // only lower
  MutexLock lock(mu_);
  absorb_wall_step_locked(now_mono_ms, now_wall_ms);
  last_wall_ms_ = now_wall_ms;
  expire_locked(now_mono_ms);
  promote_locked(now_mono_ms, now_wall_ms);
  ClaimResult r;
  if (holder_ && holder_->principal_key == p.key()) {
    // Explicit renewal by re-claiming: a fresh TTL, same session id; the role may be lowered,
    // never raised above the session's (a handoff's cap stays).
    if (role_level(holder_->role) < role_level(role)) role = holder_->role;
    Session s = make_session_locked(p.key(), PrincipalId::of(p), role, fleet, ClaimToken::of(p),
                                    now_mono_ms, now_wall_ms, holder_->id);
    holder_ = s;
    transit(ControlEvent::kRenew, ControlState::kHeld);
    r.outcome = ClaimOutcome::kRenewed;
    r.session = s;
    return r;
  }
  std::string lease_id;
  int64_t end_wall = 0;
  if (!lease_link_locked(PrincipalId::of(p), role, lease_id, end_wall, now_wall_ms)) {
    const Lease* l = active_lease_locked(now_wall_ms);
    return Error(ErrorCode::kControlConflict,
                 "the robot is leased to another principal for " +
                     std::to_string(l ? (l->end_wall_ms - now_wall_ms + 999) / 1000 : 0) + " s",
                 "lease");
  }
  if (reserved_) {
    if (!reserved_->target.is(p))
      return Error(ErrorCode::kControlConflict,
                   "control is reserved for a named handoff for " +
                       std::to_string((reserved_->until_mono_ms - now_mono_ms + 999) / 1000) + " s",
                   "session");
    if (reserved_->max_role && role_level(*reserved_->max_role) < role_level(role))
      role = *reserved_->max_role;
    reserved_.reset();
    holder_ = make_session_locked(p.key(), PrincipalId::of(p), role, fleet, ClaimToken::of(p),
                                  now_mono_ms, now_wall_ms);
    transit(ControlEvent::kClaim, ControlState::kHeld);
    r.session = *holder_;
    return r;
  }
  if (holder_) {
    int mine = role_level(role), theirs = role_level(holder_->role);
    bool preempt = mine > theirs;
    if (mine == theirs && fleet != holder_->fleet) {
      if (opts_.fleet_policy == FleetPolicy::kFleetWins && fleet) preempt = true;
      if (opts_.fleet_policy == FleetPolicy::kIndividualWins && !fleet) preempt = true;
    }
    if (preempt) {
      r.preempted = holder_;
      holder_ = make_session_locked(p.key(), PrincipalId::of(p), role, fleet, ClaimToken::of(p),
                                    now_mono_ms, now_wall_ms);
      transit(ControlEvent::kPreempt, ControlState::kHeld);
      r.session = *holder_;
      return r;
    }
    if (mine < theirs)
      return Error(ErrorCode::kControlConflict,
                   "Robot is controlled by higher-privilege user (" +
                       std::string(role_name(holder_->role)) + ")",
                   "role");
    // Same role: first claim wins, the others wait in line.
    for (size_t i = 0; i < queue_.size(); ++i) {
      if (queue_[i].principal_key == p.key()) {
        queue_[i].role = role;
        queue_[i].token = ClaimToken::of(p);
        r.outcome = ClaimOutcome::kQueued;
        r.queue_position = i + 1;
        return r;
      }
    }
    if (queue_.size() >= opts_.queue_max)
      return Error(ErrorCode::kControlConflict, "the control queue is full", "session");
    queue_.push_back(
        QueuedClaim{p.key(), p.issuer, p.sub, role, fleet, now_mono_ms, ClaimToken::of(p)});
    transit(ControlEvent::kQueue, ControlState::kHeld);
    r.outcome = ClaimOutcome::kQueued;
    r.queue_position = queue_.size();
    return r;
  }
  holder_ = make_session_locked(p.key(), PrincipalId::of(p), role, fleet, ClaimToken::of(p),
                                now_mono_ms, now_wall_ms);
  transit(ControlEvent::kClaim, ControlState::kHeld);
  r.session = *holder_;
  return r;
}

Result<Session> SessionTable::renew(const std::string& session_id, const Principal& p,
                                    int64_t now_mono_ms, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  absorb_wall_step_locked(now_mono_ms, now_wall_ms);
  last_wall_ms_ = now_wall_ms;
  if (holder_ && holder_->id == session_id && holder_->expires_mono_ms != 0 &&
      now_mono_ms >= holder_->expires_mono_ms) {
    expire_locked(now_mono_ms);
    promote_locked(now_mono_ms, now_wall_ms);
    return Error(ErrorCode::kSessionExpired, "the session expired; claim control again",
                 "session_id");
  }
  if (!holder_ || holder_->id != session_id) {
    auto it = expired_.find(p.key());
    if (it != expired_.end() && it->second == session_id)
      return Error(ErrorCode::kSessionExpired, "the session expired; claim control again",
                   "session_id");
    return Error(ErrorCode::kNotFound, "no such control session", "session_id");
  }
  if (holder_->principal_key != p.key())
    return Error(ErrorCode::kInsufficientPrivileges, "only the holder may renew this session",
                 "session_id");
  Role role = std::min(holder_->role, p.role);
  holder_ = make_session_locked(p.key(), PrincipalId::of(p), role, holder_->fleet,
                                ClaimToken::of(p), now_mono_ms, now_wall_ms, holder_->id);
  transit(ControlEvent::kRenew, ControlState::kHeld);
  return *holder_;
}

Result<Session> SessionTable::release(const std::string& session_id, const Principal& p,
                                      int64_t now_mono_ms, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  if (now_wall_ms == 0) now_wall_ms = last_wall_ms_;
  expire_locked(now_mono_ms);
  if (!holder_ || holder_->id != session_id)
    return Error(ErrorCode::kNotFound, "no such control session", "session_id");
  if (holder_->principal_key != p.key() && role_level(p.role) <= role_level(holder_->role))
    return Error(ErrorCode::kInsufficientPrivileges, "only the holder may release this session",
                 "session_id");
  Session s = *holder_;
  holder_.reset();
  transit(ControlEvent::kRelease, ControlState::kAvailable);
  promote_locked(now_mono_ms, now_wall_ms);
  return s;
}

Result<Session> SessionTable::handoff(const std::string& session_id, const Principal& p,
                                      PrincipalId target, std::optional<Role> target_role,
                                      int64_t window_ms, int64_t now_mono_ms) {
  MutexLock lock(mu_);
  expire_locked(now_mono_ms);
  if (!holder_ || holder_->id != session_id)
    return Error(ErrorCode::kNotFound, "no such control session", "session_id");
  if (holder_->principal_key != p.key())
    return Error(ErrorCode::kInsufficientPrivileges, "only the holder may hand control off",
                 "session_id");
  Session s = *holder_;
  holder_.reset();
  if (target.iss.empty()) target.iss = p.issuer;
  reserved_ = Reservation{std::move(target), target_role, s.id, now_mono_ms + window_ms};
  transit(ControlEvent::kHandoff, ControlState::kReserved);
  return s;
}

bool SessionTable::leave_queue(const Principal& p) {
  MutexLock lock(mu_);
  for (auto it = queue_.begin(); it != queue_.end(); ++it) {
    if (it->principal_key == p.key()) {
      queue_.erase(it);
      bump();
      return true;
    }
  }
  return false;
}

bool SessionTable::drop_queued(const std::string& principal_key, const std::string& reason) {
  MutexLock lock(mu_);
  for (auto it = queue_.begin(); it != queue_.end(); ++it) {
    if (it->principal_key != principal_key) continue;
    ControlChange c;
    c.event = ControlEvent::kQueueDrop;
    c.queued = *it;
    c.reason = reason;
    changes_.push_back(std::move(c));
    queue_.erase(it);
    bump();
    return true;
  }
  return false;
}

std::vector<QueuedClaim> SessionTable::queued() {
  MutexLock lock(mu_);
  return {queue_.begin(), queue_.end()};
}

void SessionTable::absorb_wall_step_locked(int64_t now_mono_ms, int64_t now_wall_ms) {
  if (now_wall_ms == 0) return;
  if (anchor_mono_ms_ >= 0) {
    int64_t step = (now_wall_ms - anchor_wall_ms_) - (now_mono_ms - anchor_mono_ms_);
    if (step > 2000 || step < -2000) {  // a step, not drift or slewing
      for (auto& l : leases_) {
        l.start_wall_ms += step;
        l.end_wall_ms += step;
        for (auto& g : l.grants) g.end_wall_ms += step;
      }
      if (!leases_.empty()) bump();  // persisted with the shifted times
    }
  }
  anchor_mono_ms_ = now_mono_ms;
  anchor_wall_ms_ = now_wall_ms;
}

void SessionTable::tick(int64_t now_mono_ms, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  absorb_wall_step_locked(now_mono_ms, now_wall_ms);
  last_wall_ms_ = now_wall_ms;
  // Lease ends revoke everything derived from the lease (before plain TTL expiry, so a
  // session bounded by its lease is recorded as revoked by it).
  for (auto it = leases_.begin(); it != leases_.end();) {
    if (now_wall_ms >= it->end_wall_ms) {
      if (holder_ && holder_->lease_id == it->id)
        drop_holder_locked(ControlEvent::kRevoke, lease_end_reason(true, it->id), now_mono_ms);
      ControlChange c;
      c.event = ControlEvent::kLeaseEnd;
      c.lease_id = it->id;
      c.reason = "expired";
      changes_.push_back(std::move(c));
      it = leases_.erase(it);
      bump();
    } else {
      // A grant inside a running lease can end earlier than the lease.
      if (holder_ && holder_->lease_id == it->id && !it->leasee.is(holder_->who())) {
        bool granted = false;
        for (const auto& g : it->grants)
          if (g.who.is(holder_->who()) && g.end_wall_ms > now_wall_ms) granted = true;
        if (!granted)
          drop_holder_locked(ControlEvent::kRevoke, lease_end_reason(false, it->id), now_mono_ms);
      }
      ++it;
    }
  }
  expire_locked(now_mono_ms);
  promote_locked(now_mono_ms, now_wall_ms);
}

std::vector<ControlChange> SessionTable::take_changes() {
  MutexLock lock(mu_);
  std::vector<ControlChange> out;
  out.swap(changes_);
  return out;
}

void SessionTable::revoke_all(const std::string& reason, int64_t now_mono_ms) {
  MutexLock lock(mu_);
  if (holder_) drop_holder_locked(ControlEvent::kRevoke, reason, now_mono_ms);
  if (reserved_) {
    reserved_.reset();
    transit(ControlEvent::kWindowClose, ControlState::kAvailable);
  }
  for (auto& q : queue_) {
    ControlChange c;
    c.event = ControlEvent::kQueueDrop;
    c.queued = q;
    c.reason = reason;
    changes_.push_back(std::move(c));
  }
  queue_.clear();
  for (auto& l : leases_) {
    ControlChange c;
    c.event = ControlEvent::kLeaseEnd;
    c.lease_id = l.id;
    c.reason = reason;
    changes_.push_back(std::move(c));
  }
  leases_.clear();
  expired_.clear();
  bump();
}

std::optional<Reservation> SessionTable::reservation(int64_t now_mono_ms) {
  MutexLock lock(mu_);
  if (reserved_ && now_mono_ms >= reserved_->until_mono_ms) return std::nullopt;
  return reserved_;
}

std::optional<Session> SessionTable::controller(int64_t now_mono_ms,
                                                std::vector<Session>* expired) {
  (void)expired;
  MutexLock lock(mu_);
  if (holder_ && holder_->expires_mono_ms != 0 && now_mono_ms >= holder_->expires_mono_ms)
    return std::nullopt;
  return holder_;
}

std::optional<Session> SessionTable::find(const std::string& session_id, int64_t now_mono_ms) {
  auto h = controller(now_mono_ms);
  if (h && h->id == session_id) return h;
  return std::nullopt;
}

bool SessionTable::live(const std::string& session_id, int64_t now_mono_ms) {
  return find(session_id, now_mono_ms).has_value();
}

bool SessionTable::run_if_live(const std::string& session_id, int64_t now_mono_ms,
                               const std::function<void()>& fn) {
  MutexLock lock(mu_);
  if (!holder_ || holder_->id != session_id) return false;
  if (holder_->expires_mono_ms != 0 && now_mono_ms >= holder_->expires_mono_ms) return false;
  fn();
  return true;
}

std::optional<std::string> SessionTable::expired_session_of(const std::string& principal_key) {
  MutexLock lock(mu_);
  auto it = expired_.find(principal_key);
  if (it == expired_.end()) return std::nullopt;
  return it->second;
}

ControlState SessionTable::state(int64_t now_mono_ms) {
  MutexLock lock(mu_);
  if (holder_ && holder_->expires_mono_ms != 0 && now_mono_ms >= holder_->expires_mono_ms)
    return reserved_ ? ControlState::kReserved : ControlState::kAvailable;
  if (!holder_ && reserved_ && now_mono_ms >= reserved_->until_mono_ms)
    return ControlState::kAvailable;
  return state_locked();
}

size_t SessionTable::queue_size() {
  MutexLock lock(mu_);
  return queue_.size();
}

json::Value SessionTable::to_json(int64_t now_mono_ms, bool detailed) {
  MutexLock lock(mu_);
  json::Array arr;
  if (holder_ && !(holder_->expires_mono_ms != 0 && now_mono_ms >= holder_->expires_mono_ms)) {
    json::Object o;
    o.set("session_id", detailed ? holder_->id : holder_->id.substr(0, 8));
    o.set("role", std::string(role_name(holder_->role)));
    o.set("user_id", detailed ? holder_->sub : holder_->sub.substr(0, 8));
    if (holder_->expires_mono_ms)
      o.set("expires_in", (holder_->expires_mono_ms - now_mono_ms) / 1000);
    else
      o.set("expires_in", json::Value());
    if (detailed && !holder_->lease_id.empty()) o.set("lease_id", holder_->lease_id);
    arr.push_back(std::move(o));
  }
  return arr;
}

json::Value SessionTable::queue_json(int64_t now_mono_ms) {
  MutexLock lock(mu_);
  json::Array arr;
  for (size_t i = 0; i < queue_.size(); ++i)
    arr.push_back(json::Object{{"position", static_cast<int64_t>(i + 1)},
                               {"user_id", queue_[i].sub},
                               {"role", std::string(role_name(queue_[i].role))},
                               {"waiting_s", (now_mono_ms - queue_[i].enqueued_mono_ms) / 1000}});
  return arr;
}

Result<Lease> SessionTable::grant_lease(const Principal& owner, PrincipalId leasee,
                                        int64_t duration_ms, int64_t now_wall_ms,
                                        int64_t now_mono_ms) {
  if (role_level(owner.role) < role_level(Role::kOwner))
    return Error(ErrorCode::kInsufficientPrivileges, "only an OWNER may grant a lease", "role");
  if (leasee.iss.empty()) leasee.iss = owner.issuer;
  if (leasee.sub.empty() || leasee.sub.size() > 256 || leasee.iss.size() > 256)
    return Error(ErrorCode::kSchemaValidationFailed, "leasee (a user id) is required", "leasee",
                 "missing_field");
  if (duration_ms <= 0 || duration_ms > int64_t{366} * 86'400'000)
    return Error(ErrorCode::kSchemaValidationFailed, "duration_s must be 1 s .. 366 days",
                 "duration_s");
  MutexLock lock(mu_);
  if (now_mono_ms >= 0) absorb_wall_step_locked(now_mono_ms, now_wall_ms);
  if (const Lease* l = active_lease_locked(now_wall_ms))
    return Error(ErrorCode::kControlConflict, "lease " + l->id + " is running; revoke it first",
                 "lease");
  Lease l;
  l.id = new_uuid_v4();
  l.leasee = std::move(leasee);
  l.granted_by = owner.sub;
  l.start_wall_ms = now_wall_ms;
  l.end_wall_ms = now_wall_ms + duration_ms;
  leases_.push_back(l);
  bump();
  return l;
}

Result<Lease> SessionTable::grant_within_lease(const Principal& leasee, const std::string& lease_id,
                                               PrincipalId who, Role role, int64_t duration_ms,
                                               int64_t now_wall_ms, int64_t now_mono_ms) {
  if (role != Role::kUser && role != Role::kGuest)
    return Error(ErrorCode::kSchemaValidationFailed, "a lease grants USER or GUEST access only",
                 "role");
  if (who.iss.empty()) who.iss = leasee.issuer;
  if (who.sub.empty() || who.sub.size() > 256 || who.iss.size() > 256)
    return Error(ErrorCode::kSchemaValidationFailed, "user_id is required", "user_id",
                 "missing_field");
  if (duration_ms <= 0)
    return Error(ErrorCode::kSchemaValidationFailed, "duration_s must be positive", "duration_s");
  MutexLock lock(mu_);
  if (now_mono_ms >= 0) absorb_wall_step_locked(now_mono_ms, now_wall_ms);
  for (auto& l : leases_) {
    if (l.id != lease_id || now_wall_ms >= l.end_wall_ms) continue;
    bool may = (l.leasee.is(leasee) && role_level(leasee.role) >= role_level(Role::kLeasee)) ||
               role_level(leasee.role) >= role_level(Role::kOwner);
    if (!may)
      return Error(ErrorCode::kInsufficientPrivileges,
                   "only the lease's LEASEE may grant within it", "lease_id");
    LeaseGrant g{who, role, std::min(l.end_wall_ms, now_wall_ms + duration_ms)};
    bool replaced = false;
    for (auto& x : l.grants)
      if (x.who == who) {
        x = g;
        replaced = true;
      }
    if (!replaced) l.grants.push_back(g);
    bump();
    return l;
  }
  return Error(ErrorCode::kNotFound, "no running lease " + lease_id, "lease_id");
}

Result<Lease> SessionTable::revoke_lease(const Principal& p, const std::string& lease_id,
                                         int64_t now_mono_ms, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  for (auto it = leases_.begin(); it != leases_.end(); ++it) {
    if (it->id != lease_id) continue;
    if (role_level(p.role) < role_level(Role::kOwner))
      return Error(ErrorCode::kInsufficientPrivileges, "only an OWNER may revoke a lease", "role");
    Lease l = *it;
    if (holder_ && holder_->lease_id == l.id)
      drop_holder_locked(ControlEvent::kRevoke, "the lease " + l.id + " was revoked", now_mono_ms);
    ControlChange c;
    c.event = ControlEvent::kLeaseEnd;
    c.lease_id = l.id;
    c.reason = "revoked by " + p.sub;
    changes_.push_back(std::move(c));
    leases_.erase(it);
    bump();
    promote_locked(now_mono_ms, now_wall_ms);
    return l;
  }
  return Error(ErrorCode::kNotFound, "no lease " + lease_id, "lease_id");
}

std::vector<Lease> SessionTable::leases(int64_t now_wall_ms) {
  MutexLock lock(mu_);
  std::vector<Lease> out;
  for (const auto& l : leases_)
    if (now_wall_ms < l.end_wall_ms) out.push_back(l);
  return out;
}

json::Value SessionTable::leases_json(int64_t now_wall_ms) {
  json::Array a;
  for (const auto& l : leases(now_wall_ms)) a.push_back(l.to_json(now_wall_ms));
  return a;
}

json::Value SessionTable::persist_json() {
  MutexLock lock(mu_);
  json::Array a;
  for (const auto& l : leases_) a.push_back(l.to_json(0));
  return json::Object{{"leases", a}};
}

void SessionTable::load_json(const json::Value& v, int64_t now_wall_ms) {
  const json::Value* ls = v.get("leases");
  if (!ls || !ls->is_array()) return;
  MutexLock lock(mu_);
  leases_.clear();
  for (const auto& e : ls->as_array()) {
    if (!e.is_object()) continue;
    Lease l;
    l.id = json::string_field(e, "lease_id");
    l.leasee = PrincipalId{json::string_field(e, "leasee_iss"), json::string_field(e, "leasee")};
    l.granted_by = json::string_field(e, "granted_by");
    l.start_wall_ms = json::int_field(e, "start_ms");
    l.end_wall_ms = json::int_field(e, "end_ms");
    if (l.id.empty() || l.leasee.empty() || l.end_wall_ms <= now_wall_ms) continue;
    if (const json::Value* gs = e.get("grants"); gs && gs->is_array()) {
      for (const auto& g : gs->as_array()) {
        if (!g.is_object()) continue;
        auto r = role_from_name(json::string_field(g, "role"));
        if (!r || (*r != Role::kUser && *r != Role::kGuest)) continue;
        l.grants.push_back(
            LeaseGrant{PrincipalId{json::string_field(g, "iss"), json::string_field(g, "sub")}, *r,
                       json::int_field(g, "end_ms")});
      }
    }
    leases_.push_back(std::move(l));
  }
  bump();
}

}  // namespace rcan::node
