#include "node/sessions.h"

#include "rcan/errors.h"

namespace rcan::node {

void SessionTable::expire_locked(int64_t now_mono_ms, std::vector<Session>* expired) {
  if (holder_ && holder_->expires_mono_ms != 0 && now_mono_ms >= holder_->expires_mono_ms) {
    if (expired) expired->push_back(*holder_);
    holder_.reset();
  }
}

Result<ClaimResult> SessionTable::claim(const Principal& p, std::optional<Role> requested,
                                        int64_t now_mono_ms, int64_t now_wall_ms) {
  Role role = p.role;
  if (requested && role_level(*requested) < role_level(role)) role = *requested;  // only lower
  std::lock_guard<std::mutex> lock(mu_);
  expire_locked(now_mono_ms, nullptr);
  if (reserved_ && now_mono_ms >= reserved_->until_mono_ms) reserved_.reset();
  if (reserved_) {
    if (p.sub != reserved_->target_sub) {
      return Error(ErrorCode::kControlConflict,
                   "control is reserved for a named handoff for " +
                       std::to_string((reserved_->until_mono_ms - now_mono_ms + 999) / 1000) + " s",
                   "session");
    }
    if (reserved_->max_role && role_level(*reserved_->max_role) < role_level(role)) role = *reserved_->max_role;
    reserved_.reset();
  }
  ClaimResult r;
  if (holder_) {
    if (holder_->principal_key == p.key()) {
      r.renewed = true;
    } else if (role_level(role) > role_level(holder_->role)) {
      r.preempted = holder_;
    } else {
      return Error(ErrorCode::kControlConflict,
                   "the robot is controlled by another " + std::string(role_name(holder_->role)) +
                       " (first claim wins)",
                   "session");
    }
  }
  Session s;
  s.id = r.renewed ? holder_->id : new_uuid_v4();
  s.principal_key = p.key();
  s.sub = p.sub;
  s.role = role;
  s.granted_mono_ms = now_mono_ms;
  s.granted_wall_ms = now_wall_ms;
  uint32_t ttl = session_ttl_seconds(role);
  s.expires_mono_ms = ttl ? now_mono_ms + int64_t{ttl} * 1000 : 0;
  holder_ = s;
  r.session = s;
  return r;
}

Result<Session> SessionTable::release(const std::string& session_id, const Principal& p,
                                      int64_t now_mono_ms) {
  std::lock_guard<std::mutex> lock(mu_);
  expire_locked(now_mono_ms, nullptr);
  if (!holder_ || holder_->id != session_id)
    return Error(ErrorCode::kNotFound, "no such control session", "session_id");
  if (holder_->principal_key != p.key() && role_level(p.role) <= role_level(holder_->role))
    return Error(ErrorCode::kInsufficientPrivileges, "only the holder may release this session", "session_id");
  Session s = *holder_;
  holder_.reset();
  return s;
}

Result<Session> SessionTable::handoff(const std::string& session_id, const Principal& p, std::string target_sub,
                                      std::optional<Role> target_role, int64_t window_ms, int64_t now_mono_ms) {
  std::lock_guard<std::mutex> lock(mu_);
  expire_locked(now_mono_ms, nullptr);
  if (!holder_ || holder_->id != session_id)
    return Error(ErrorCode::kNotFound, "no such control session", "session_id");
  if (holder_->principal_key != p.key())
    return Error(ErrorCode::kInsufficientPrivileges, "only the holder may hand control off", "session_id");
  Session s = *holder_;
  holder_.reset();
  reserved_ = Reservation{std::move(target_sub), target_role, s.id, now_mono_ms + window_ms};
  return s;
}

std::optional<Reservation> SessionTable::reservation(int64_t now_mono_ms) {
  std::lock_guard<std::mutex> lock(mu_);
  if (reserved_ && now_mono_ms >= reserved_->until_mono_ms) reserved_.reset();
  return reserved_;
}

std::optional<Session> SessionTable::controller(int64_t now_mono_ms, std::vector<Session>* expired) {
  std::lock_guard<std::mutex> lock(mu_);
  expire_locked(now_mono_ms, expired);
  return holder_;
}

std::optional<Session> SessionTable::find(const std::string& session_id, int64_t now_mono_ms) {
  std::lock_guard<std::mutex> lock(mu_);
  expire_locked(now_mono_ms, nullptr);
  if (holder_ && holder_->id == session_id) return holder_;
  return std::nullopt;
}

json::Value SessionTable::to_json(int64_t now_mono_ms, bool detailed) {
  std::lock_guard<std::mutex> lock(mu_);
  expire_locked(now_mono_ms, nullptr);
  json::Array arr;
  if (holder_) {
    json::Object o;
    o.set("session_id", detailed ? holder_->id : holder_->id.substr(0, 8));
    o.set("role", std::string(role_name(holder_->role)));
    o.set("user_id", detailed ? holder_->sub : holder_->sub.substr(0, 8));
    if (holder_->expires_mono_ms)
      o.set("expires_in", (holder_->expires_mono_ms - now_mono_ms) / 1000);
    else
      o.set("expires_in", json::Value());
    arr.push_back(std::move(o));
  }
  return arr;
}

}  // namespace rcan::node
