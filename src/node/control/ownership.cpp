#include "node/control/ownership.h"

#include "rcan/errors.h"

namespace rcan::node {

void Ownership::bump() {
  ++version_;
  if (on_change_) on_change_();
}

void Ownership::transit(OwnershipEvent event, OwnershipState to) {
  if (!ownership_transition_allowed(state_, event, to)) ++violations_;
  state_ = to;
  bump();
}

bool Ownership::is_owner_locked(const Principal& p) const {
  if (role_level(p.role) >= role_level(Role::kCreator)) return true;
  if (role_level(p.role) < role_level(Role::kOwner)) return false;
  return owner_.empty() || owner_.is(p);
}

namespace {

json::Value id_json(const PrincipalId& id) {
  return json::Object{{"iss", id.iss}, {"sub", id.sub}};
}

// A stored principal: {"iss","sub"}, or a bare subject (state written before issuers were kept).
PrincipalId id_from(const json::Value& v) {
  if (v.is_string()) return PrincipalId{"", v.as_string()};
  return PrincipalId{json::string_field(v, "iss"), json::string_field(v, "sub")};
}

}  // namespace

Result<PendingTransfer> Ownership::request(const Principal& p, PrincipalId to,
                                           const std::string& note, int64_t now_wall_ms) {
  if (to.iss.empty()) to.iss = p.issuer;
  if (to.sub.empty() || to.sub.size() > 256 || to.iss.size() > 256)
    return Error(ErrorCode::kSchemaValidationFailed, "new_owner (a user id) is required",
                 "new_owner", "missing_field");
  MutexLock lock(mu_);
  if (!is_owner_locked(p))
    return Error(ErrorCode::kInsufficientPrivileges, "only the robot's owner may transfer it",
                 "role");
  if (pending_ && now_wall_ms < pending_->expires_ms)
    return Error(ErrorCode::kControlConflict, "transfer " + pending_->id + " is already pending",
                 "transfer_id");
  if (to == PrincipalId::of(p))
    return Error(ErrorCode::kSchemaValidationFailed, "the new owner is the owner", "new_owner");
  PendingTransfer t{new_uuid_v4(), PrincipalId::of(p),       std::move(to),
                    now_wall_ms,   now_wall_ms + window_ms_, note.substr(0, 512)};
  pending_ = t;
  transit(OwnershipEvent::kTransferRequest, OwnershipState::kTransferPending);
  return t;
}

Result<PendingTransfer> Ownership::accept(const Principal& p, const std::string& transfer_id,
                                          const std::string& agreement, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  if (!pending_ || (!transfer_id.empty() && transfer_id != pending_->id))
    return Error(ErrorCode::kNotFound, "no such pending transfer", "transfer_id");
  if (now_wall_ms >= pending_->expires_ms)
    return Error(ErrorCode::kSessionExpired, "the transfer window has passed", "transfer_id");
  if (!pending_->to.is(p))
    return Error(ErrorCode::kInsufficientPrivileges,
                 "only the named new owner (issuer and subject) may accept", "sub");
  if (agreement.empty())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "agreement (payment or agreement reference) is required", "agreement",
                 "missing_field");
  PendingTransfer t = *pending_;
  pending_.reset();
  if (!owner_.empty()) former_owners_.insert(owner_);
  former_owners_.insert(t.from);
  former_owners_.erase(t.to);
  owner_ = t.to;
  users_.clear();
  transit(OwnershipEvent::kTransferAccept, OwnershipState::kOwned);
  return t;
}

Result<PendingTransfer> Ownership::cancel(const Principal& p, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  if (!pending_ || now_wall_ms >= pending_->expires_ms)
    return Error(ErrorCode::kNotFound, "no pending transfer", "transfer_id");
  if (!is_owner_locked(p) && !pending_->to.is(p))
    return Error(ErrorCode::kInsufficientPrivileges,
                 "only the owner or the named new owner may cancel", "role");
  PendingTransfer t = *pending_;
  pending_.reset();
  transit(OwnershipEvent::kTransferCancel, OwnershipState::kOwned);
  return t;
}

std::optional<PendingTransfer> Ownership::expire(int64_t now_wall_ms) {
  MutexLock lock(mu_);
  if (!pending_ || now_wall_ms < pending_->expires_ms) return std::nullopt;
  PendingTransfer t = *pending_;
  pending_.reset();
  transit(OwnershipEvent::kTransferExpire, OwnershipState::kOwned);
  return t;
}

void Ownership::cap(Principal& p) const {
  MutexLock lock(mu_);
  if (role_level(p.role) >= role_level(Role::kCreator)) return;
  // The new owner is never capped, whoever held the robot before under that name.
  if (!owner_.empty() && owner_.is(p)) return;
  for (const PrincipalId& f : former_owners_)
    if (f.is(p)) {
      p.role = Role::kGuest;
      return;
    }
}

void Ownership::note_user(const std::string& sub) {
  MutexLock lock(mu_);
  if (users_.size() < 10000 && users_.insert(sub).second) bump();
}

void Ownership::on_clear(std::function<void()> fn) {
  MutexLock lock(mu_);
  clear_hooks_.push_back(std::move(fn));
}

void Ownership::run_clear_hooks() {
  std::vector<std::function<void()>> hooks;
  {
    MutexLock lock(mu_);
    hooks = clear_hooks_;
  }
  for (auto& h : hooks) h();
}

OwnershipState Ownership::state(int64_t now_wall_ms) {
  MutexLock lock(mu_);
  if (pending_ && now_wall_ms >= pending_->expires_ms)
    return OwnershipState::kOwned;  // tick() records it
  return state_;
}

PrincipalId Ownership::owner() {
  MutexLock lock(mu_);
  return owner_;
}

std::optional<PendingTransfer> Ownership::pending() {
  MutexLock lock(mu_);
  return pending_;
}

json::Value Ownership::to_json(int64_t now_wall_ms, bool detailed) {
  OwnershipState st = state(now_wall_ms);
  MutexLock lock(mu_);
  json::Object o{{"state", std::string(ownership_state_name(st))},
                 {"owner", owner_.empty() ? json::Value() : json::Value(owner_.sub)},
                 {"owner_iss", owner_.iss.empty() ? json::Value() : json::Value(owner_.iss)},
                 {"users", static_cast<int64_t>(users_.size())}};
  if (pending_ && now_wall_ms < pending_->expires_ms) {
    json::Object t{{"transfer_id", pending_->id},
                   {"from", pending_->from.sub},
                   {"from_iss", pending_->from.iss},
                   {"to", pending_->to.sub},
                   {"to_iss", pending_->to.iss},
                   {"requested_ms", pending_->requested_ms},
                   {"expires_ms", pending_->expires_ms},
                   {"remaining_s", (pending_->expires_ms - now_wall_ms) / 1000}};
    if (detailed && !pending_->note.empty()) t.set("note", pending_->note);
    o.set("pending", t);
  } else {
    o.set("pending", json::Value());
  }
  return o;
}

json::Value Ownership::persist_json() {
  MutexLock lock(mu_);
  json::Array formers, users;
  for (const auto& f : former_owners_) formers.push_back(id_json(f));
  for (const auto& u : users_) users.emplace_back(u);
  json::Object o{{"owner", owner_.sub},
                 {"owner_iss", owner_.iss},
                 {"former_owners", formers},
                 {"users", users}};
  if (pending_)
    o.set("pending", json::Object{{"transfer_id", pending_->id},
                                  {"from", id_json(pending_->from)},
                                  {"to", id_json(pending_->to)},
                                  {"requested_ms", pending_->requested_ms},
                                  {"expires_ms", pending_->expires_ms},
                                  {"note", pending_->note}});
  return o;
}

void Ownership::load_json(const json::Value& v) {
  MutexLock lock(mu_);
  owner_ = PrincipalId{json::string_field(v, "owner_iss"), json::string_field(v, "owner")};
  former_owners_.clear();
  users_.clear();
  if (const json::Value* a = v.get("former_owners"); a && a->is_array())
    for (const auto& e : a->as_array())
      if (PrincipalId f = id_from(e); !f.empty()) former_owners_.insert(std::move(f));
  if (const json::Value* a = v.get("users"); a && a->is_array())
    for (const auto& e : a->as_array())
      if (e.is_string()) users_.insert(e.as_string());
  pending_.reset();
  state_ = OwnershipState::kOwned;
  if (const json::Value* p = v.get("pending"); p && p->is_object()) {
    const json::Value none;
    const json::Value* from = p->get("from");
    const json::Value* to = p->get("to");
    PendingTransfer t{json::string_field(*p, "transfer_id"),
                      id_from(from ? *from : none),
                      id_from(to ? *to : none),
                      json::int_field(*p, "requested_ms"),
                      json::int_field(*p, "expires_ms"),
                      json::string_field(*p, "note")};
    if (!t.id.empty() && !t.to.empty()) {
      pending_ = t;
      state_ = OwnershipState::kTransferPending;  // an expired one is recorded by the next tick
    }
  }
  bump();
}

uint64_t Ownership::version() {
  MutexLock lock(mu_);
  return version_;
}

}  // namespace rcan::node
