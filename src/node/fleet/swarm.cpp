#include "node/fleet/swarm.h"

#include <algorithm>

#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

namespace rcan::node {

namespace {

json::Array to_array(const std::set<std::string>& s) {
  json::Array a;
  for (const auto& m : s) a.emplace_back(m);
  return a;
}

constexpr const char* kMacKey = "swarm_mac";
constexpr int64_t kHeartbeatSkewMs = 30'000;  // PROFILE §3: a message's freshness window

// Over the swarm's id too: swarms that share a secret file cannot replay into each other.
std::string mac_of(const std::string& secret, const std::string& swarm_id,
                   const json::Object& body) {
  return hmac_sha256_hex(
      secret, "rcan-swarm-v1:" + swarm_id + ":" + json::canonical_without(body, kMacKey));
}

}  // namespace

SwarmAgent::SwarmAgent(NodeServices& svc, config::SwarmConfig cfg, std::string secret,
                       std::string prefix, Publish publish, bool require_bound_tokens,
                       std::string state_file)
    : svc_(svc),
      cfg_(std::move(cfg)),
      topics_(mqtt::swarm_topics(prefix, cfg_.swarm_id)),
      publish_(std::move(publish)),
      require_bound_tokens_(require_bound_tokens),
      state_file_(std::move(state_file)),
      secret_(std::move(secret)) {
  MutexLock lk(mu_);
  members_.insert(cfg_.members.begin(), cfg_.members.end());
  leader_ = cfg_.leader;
  restore_locked();
}

void SwarmAgent::restore_locked() {
  if (state_file_.empty()) return;
  auto v = read_state_file(state_file_);
  if (!v.ok()) {
    if (v.error().code != ErrorCode::kNotFound)
      log(LogLevel::kWarn, "swarm_state_unreadable",
          json::Object{{"file", state_file_}, {"error", v.error().message}});
    return;
  }
  const json::Value* ep = v->is_object() ? v->get("epoch") : nullptr;
  const json::Value* mem = v->is_object() ? v->get("members") : nullptr;
  const std::string leader = v->is_object() ? json::string_field(*v, "leader") : "";
  std::set<std::string> members;
  if (mem != nullptr && mem->is_array())
    for (const auto& m : mem->as_array())
      if (m.is_string() && mqtt::valid_topic_segment(m.as_string())) members.insert(m.as_string());
  if (!v->is_object() || json::string_field(*v, "swarm_id") != cfg_.swarm_id ||
      json::string_field(*v, "member_id") != cfg_.member_id || ep == nullptr || !ep->is_int() ||
      ep->as_int() < 0 || members.count(leader) == 0 || members.size() > 1024) {
    log(LogLevel::kWarn, "swarm_state_ignored",
        json::Object{{"file", state_file_}, {"reason", "not this member's swarm state"}});
    return;
  }
  epoch_ = static_cast<uint64_t>(ep->as_int());
  leader_ = leader;
  members_.insert(members.begin(), members.end());
  if (const json::Value* pend = v->get("pending"); pend != nullptr && pend->is_array())
    for (const auto& m : pend->as_array())
      if (m.is_string() && mqtt::valid_topic_segment(m.as_string())) pending_.insert(m.as_string());
  persist_locked();  // the configured members added to what it held
}

void SwarmAgent::persist_locked() {
  if (state_file_.empty()) return;
  json::Value doc(json::Object{{"swarm_id", cfg_.swarm_id},
                               {"member_id", cfg_.member_id},
                               {"epoch", static_cast<int64_t>(epoch_)},
                               {"leader", leader_},
                               {"members", to_array(members_)},
                               {"pending", to_array(pending_)}});
  std::string text = json::dump(doc);
  if (text == persisted_) return;
  if (Status st = write_state_file(state_file_, doc); !st.ok()) {
    log(LogLevel::kError, "swarm_state_write_failed",
        json::Object{{"file", state_file_}, {"error", st.error().message}});
    return;
  }
  persisted_ = std::move(text);
}

std::vector<std::string> SwarmAgent::subscriptions() const {
  return {topics_.announce(), topics_.heartbeats(), topics_.join()};
}

std::vector<std::string> SwarmAgent::hearing_subscriptions() const {
  return {topics_.announce(), topics_.heartbeats()};
}

std::string SwarmAgent::leader() const {
  MutexLock lk(mu_);
  return leader_;
}

json::Value SwarmAgent::state() const {
  MutexLock lk(mu_);
  json::Value v = announce_body("state", "");
  json::Object& p = v.as_object().find("payload")->as_object();
  p.set("dropped", static_cast<int64_t>(dropped_));
  p.set("hearing", connected_since_ >= 0 && hearing_);
  return v;
}

json::Value SwarmAgent::sealed(json::Value body) const {
  json::Object& o = body.as_object();
  o.set(kMacKey, mac_of(secret_, cfg_.swarm_id, o));
  return body;
}

bool SwarmAgent::authentic(const json::Value& body) const {
  if (secret_.empty() || !body.is_object()) return false;
  const json::Value* mac = body.get(kMacKey);
  return mac != nullptr && mac->is_string() &&
         constant_time_equal(mac->as_string(), mac_of(secret_, cfg_.swarm_id, body.as_object()));
}

void SwarmAgent::drop(const std::string& topic, const std::string& reason) {
  const int64_t now = svc_.clock.mono_ms();
  MutexLock lk(mu_);
  ++dropped_;
  if (drop_logged_mono_ >= 0 && now - drop_logged_mono_ < 10'000) return;
  drop_logged_mono_ = now;
  log(LogLevel::kWarn, "swarm_message_dropped",
      json::Object{{"swarm_id", cfg_.swarm_id},
                   {"topic", topic},
                   {"reason", reason},
                   {"dropped", static_cast<int64_t>(dropped_)}});
}

json::Value SwarmAgent::announce_body(const std::string& reason,
                                      const std::string& previous) const {
  json::Object p{{"swarm_id", cfg_.swarm_id},
                 {"members", to_array(members_)},
                 {"leader", leader_},
                 {"formation", cfg_.formation},
                 {"join_policy", cfg_.join_policy},
                 {"epoch", static_cast<int64_t>(epoch_)},
                 {"pending", to_array(pending_)},
                 {"announced_by", cfg_.member_id},
                 {"reason", reason}};
  if (!previous.empty()) p.set("previous_leader", previous);
  return json::Value(json::Object{{"type", "SWARM_ANNOUNCE"},
                                  {"message_id", new_uuid_v4()},
                                  {"source_ruri", svc_.settings.ruri},
                                  {"timestamp_ms", svc_.clock.wall_ms()},
                                  {"payload", std::move(p)}});
}

void SwarmAgent::reannounce_locked(const std::string& reason, int64_t now) {
  if (leader_ != cfg_.member_id) return;
  if (reannounced_mono_ >= 0 && now - reannounced_mono_ < 1000) {
    // Within a second of the last one: put it back from tick() once the second is over, so that
    // a second forged announce right after the first is not left standing.
    reannounce_due_ = reason;
    return;
  }
  reannounced_mono_ = now;
  reannounce_due_.clear();
  announce_locked(reason, "");
}

void SwarmAgent::announce_locked(const std::string& reason, const std::string& previous) {
  persist_locked();  // before it is announced: a restart never falls back below what was said
  publish_(topics_.announce(), sealed(announce_body(reason, previous)), 1, true);
}

void SwarmAgent::on_connected(int64_t now) {
  MutexLock lk(mu_);
  connected_since_ = now;
  for (const auto& m : members_) last_seen_[m] = now;  // everyone gets a full timeout of grace
  if (leader_ == cfg_.member_id) announce_locked("connected", "");
}

void SwarmAgent::on_disconnected() {
  MutexLock lk(mu_);
  connected_since_ = -1;
  hearing_ = false;
}

void SwarmAgent::on_message(const mqtt::InboundTopic& t, const json::Value& body, int64_t now) {
  if (t.kind == mqtt::TopicKind::kSwarmJoin) {
    handle_join(body);
    return;
  }
  if (t.kind != mqtt::TopicKind::kSwarmHeartbeat && t.kind != mqtt::TopicKind::kSwarmAnnounce)
    return;
  const std::string topic =
      t.kind == mqtt::TopicKind::kSwarmHeartbeat ? topics_.heartbeat(t.member) : topics_.announce();
  if (!authentic(body)) {
    drop(topic, "bad_mac");
    // A retained announce we drop would greet every member that starts later: the leader puts
    // the swarm's own back — at most once a second, so that two leaders holding different
    // secrets (a misconfigured member) do not answer each other without end.
    MutexLock lk(mu_);
    if (t.kind == mqtt::TopicKind::kSwarmAnnounce) reannounce_locked("restored", now);
    return;
  }
  if (t.kind == mqtt::TopicKind::kSwarmHeartbeat) {
    const json::Value* ts = body.get("timestamp_ms");
    const int64_t wall = svc_.clock.wall_ms();
    if (json::string_field(body, "member") != t.member) return drop(topic, "other_member");
    if (ts == nullptr || !ts->is_int() || ts->as_int() < wall - kHeartbeatSkewMs ||
        ts->as_int() > wall + kHeartbeatSkewMs)
      return drop(topic, "stale");
    ReleasableMutexLock lk(mu_);
    if (members_.count(t.member) == 0) return;
    auto last = last_beat_ts_.find(t.member);
    if (last != last_beat_ts_.end() && ts->as_int() <= last->second) {
      lk.unlock();
      return drop(topic, "replayed");
    }
    last_beat_ts_[t.member] = ts->as_int();
    last_seen_[t.member] = now;
    if (const json::Value* h = body.get("hearing"); h != nullptr && h->is_bool() && !h->as_bool())
      deaf_.insert(t.member);
    else
      deaf_.erase(t.member);
    return;
  }
  const json::Value* p = body.get("payload");
  if (p == nullptr || !p->is_object()) return;
  const json::Value* ep = p->get("epoch");
  const json::Value* mem = p->get("members");
  std::string leader = json::string_field(*p, "leader");
  if (ep == nullptr || !ep->is_int() || ep->as_int() < 0 || mem == nullptr || !mem->is_array() ||
      leader.empty())
    return;
  uint64_t epoch = static_cast<uint64_t>(ep->as_int());
  std::set<std::string> members;
  for (const auto& m : mem->as_array())
    if (m.is_string() && mqtt::valid_topic_segment(m.as_string())) members.insert(m.as_string());
  if (members.count(leader) == 0 || members.size() > 1024) return;
  MutexLock lk(mu_);
  bool newer = epoch > epoch_ || (epoch == epoch_ && leader < leader_) ||
               (epoch == epoch_ && leader == leader_);
  if (!newer) {
    // A stale announce (e.g. the retained one of a leader we replaced, or a captured one
    // replayed): correct it.
    reannounce_locked("superseded", now);
    return;
  }
  if (leader != leader_)
    log(LogLevel::kInfo, "swarm_leader",
        json::Object{{"swarm_id", cfg_.swarm_id},
                     {"leader", leader},
                     {"epoch", static_cast<int64_t>(epoch)}});
  epoch_ = epoch;
  leader_ = leader;
  for (const auto& m : members)
    if (last_seen_.count(m) == 0) last_seen_[m] = now;
  members_ = std::move(members);
  pending_.clear();
  if (const json::Value* pend = p->get("pending"); pend != nullptr && pend->is_array())
    for (const auto& m : pend->as_array())
      if (m.is_string() && mqtt::valid_topic_segment(m.as_string())) pending_.insert(m.as_string());
  persist_locked();
}

void SwarmAgent::tick(int64_t now, bool hearing) {
  MutexLock lk(mu_);
  if (connected_since_ < 0) return;  // the silence clocks start at on_connected()
  if (!reannounce_due_.empty() && now - reannounced_mono_ >= 1000)
    reannounce_locked(std::string(reannounce_due_), now);
  if (now - last_beat_ >= cfg_.heartbeat_ms) {
    last_beat_ = now;
    last_seen_[cfg_.member_id] = now;
    publish_(topics_.heartbeat(cfg_.member_id),
             sealed(json::Value(json::Object{{"type", "HEARTBEAT"},
                                             {"member", cfg_.member_id},
                                             {"leader", leader_},
                                             {"epoch", static_cast<int64_t>(epoch_)},
                                             {"hearing", hearing},
                                             {"timestamp_ms", svc_.clock.wall_ms()}})),
             0, false);
  }
  if (!hearing) {
    hearing_ = false;
    return;
  }
  if (!hearing_) {  // subscribed (again): everyone gets a full timeout of grace from now
    hearing_ = true;
    for (const auto& m : members_) last_seen_[m] = now;
    return;
  }
  if (leader_ == cfg_.member_id) return;
  auto it = last_seen_.find(leader_);
  int64_t seen = it == last_seen_.end() ? connected_since_ : it->second;
  if (now - seen <= static_cast<int64_t>(cfg_.leader_timeout_ms)) return;
  // The deterministic rule: the first live member in byte order, other than the silent leader
  // and those that say they cannot hear (this one can: it is judging).
  std::string next;
  for (const auto& m : members_) {
    if (m == leader_) continue;
    auto s = last_seen_.find(m);
    bool live =
        m == cfg_.member_id || (deaf_.count(m) == 0 && s != last_seen_.end() &&
                                now - s->second <= static_cast<int64_t>(cfg_.leader_timeout_ms));
    if (live) {
      next = m;
      break;
    }
  }
  if (next.empty()) return;
  std::string previous = leader_;
  leader_ = next;
  last_seen_[next] = now;
  if (next != cfg_.member_id) persist_locked();  // else with its announce, at the new epoch
  log(LogLevel::kWarn, "swarm_leader_silent",
      json::Object{{"swarm_id", cfg_.swarm_id}, {"previous_leader", previous}, {"leader", next}});
  if (next == cfg_.member_id) {
    ++epoch_;
    announce_locked("leader_silent", previous);
    svc_.trail.record("SWARM_LEADER_CHANGE")
        .by_system()
        .detail("swarm_id", cfg_.swarm_id)
        .detail("previous_leader", previous)
        .detail("leader", next)
        .detail("epoch", static_cast<int64_t>(epoch_))
        .write();
  }
}

void SwarmAgent::answer(const std::string& member, const std::string& type,
                        const std::string& reply_to, const std::string& reason) {
  json::Object o{
      {"type", type},
      {"message_id", new_uuid_v4()},
      {"reply_to", reply_to},
      {"source_ruri", svc_.settings.ruri},
      {"timestamp_ms", svc_.clock.wall_ms()},
      {"payload",
       json::Object{{"swarm_id", cfg_.swarm_id}, {"member", member}, {"reason", reason}}}};
  publish_(topics_.join_answer(member), json::Value(std::move(o)), 1, false);
}

void SwarmAgent::handle_join(const json::Value& body) {
  if (!body.is_object()) return;
  std::string type = json::string_field(body, "type");
  const json::Value* p = body.get("payload");
  std::string member = p != nullptr ? json::string_field(*p, "member") : std::string();
  std::string id = json::string_field(body, "message_id");
  {
    MutexLock lk(mu_);
    if (leader_ != cfg_.member_id) return;  // only the leader answers
  }
  if ((type != "SWARM_JOIN" && type != "SWARM_APPROVE") || !mqtt::valid_topic_segment(member))
    return;
  auto record = [&](const std::string& event, const std::string& outcome,
                    const Principal* principal, const std::string& reason) {
    AuditRecord r = svc_.trail.record(event, outcome);
    if (principal) r.by(*principal);
    r.message(id)
        .reason(reason)
        .detail("swarm_id", cfg_.swarm_id)
        .detail("member", member)
        .detail("join_policy", cfg_.join_policy)
        .write();
  };
  // The same checks as every other inbound message: a verified token, signed by the key it is
  // bound to, and a fresh, unseen id.
  auto principal = svc_.authenticate(json::string_field(body, "auth_token"));
  if (!principal.ok()) {
    record(type, "blocked", nullptr, std::string(error_name(principal.error().code)));
    answer(member, "DENIED", id, std::string(error_name(principal.error().code)));
    return;
  }
  if (auto pop = svc_.auth.check_bound_key(body.as_object(), *principal, require_bound_tokens_);
      !pop.ok()) {
    record(type, "blocked", &*principal, std::string(error_name(pop.error().code)));
    answer(member, "DENIED", id, std::string(error_name(pop.error().code)));
    return;
  }
  const json::Value* ts = body.get("timestamp_ms");
  auto fresh =
      svc_.replay.check(principal->key(), id, ts != nullptr && ts->is_int() ? ts->as_int() : 0,
                        false, svc_.clock.wall_ms());
  if (id.empty() || !fresh.ok()) {
    std::string why =
        id.empty() ? "missing message_id" : std::string(error_name(fresh.error().code));
    record(type, "blocked", &*principal, why);
    answer(member, "DENIED", id, why);
    return;
  }
  ReleasableMutexLock lk(mu_);
  if (type == "SWARM_APPROVE") {
    if (role_level(principal->role) < role_level(Role::kOwner) || cfg_.join_policy != "approval" ||
        pending_.count(member) == 0) {
      lk.unlock();
      record(type, "blocked", &*principal, "not_allowed");
      answer(member, "DENIED", id, "approval needs OWNER and a pending request");
      return;
    }
    pending_.erase(member);
    members_.insert(member);
    last_seen_[member] = svc_.clock.mono_ms();
    ++epoch_;
    announce_locked("joined", "");
    lk.unlock();
    record(type, "ok", &*principal, "approved");
    answer(member, "GRANTED", id, "approved");
    return;
  }
  if (members_.count(member) != 0) {
    lk.unlock();
    answer(member, "GRANTED", id, "already_member");
    return;
  }
  if (cfg_.join_policy == "open") {
    members_.insert(member);
    last_seen_[member] = svc_.clock.mono_ms();
    ++epoch_;
    announce_locked("joined", "");
    lk.unlock();
    record(type, "ok", &*principal, "open");
    answer(member, "GRANTED", id, "open");
  } else if (cfg_.join_policy == "approval") {
    // A new pending request changes the swarm's state, so it raises the epoch as every other
    // change does: an announce of the same epoch then always says the same, and a replay of an
    // earlier one (without the request) is stale, not taken (which forgot the request).
    if (pending_.insert(member).second) ++epoch_;
    announce_locked("join_pending", "");
    lk.unlock();
    record(type, "ok", &*principal, "pending_approval");
    answer(member, "PENDING_AUTH", id, "approval");
  } else {
    lk.unlock();
    record(type, "blocked", &*principal, "closed");
    answer(member, "DENIED", id, "closed");
  }
}

}  // namespace rcan::node
