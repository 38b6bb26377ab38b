#include "node/fleet/estop_ledger.h"

#include <algorithm>
#include <vector>

#include "rcan/errors.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

namespace rcan::node {

FleetEstopLedger::FleetEstopLedger(std::string path, std::string fleet_id, std::string member_id,
                                   int64_t now_s)
    : path_(std::move(path)), fleet_id_(std::move(fleet_id)), member_id_(std::move(member_id)) {
  restore();
  MutexLock lk(mu_);
  prune_locked(now_s);
}

void FleetEstopLedger::restore() {
  if (path_.empty()) return;
  auto v = read_state_file(path_);
  if (!v.ok()) {
    if (v.error().code != ErrorCode::kNotFound)
      log(LogLevel::kWarn, "fleet_estops_unreadable",
          json::Object{{"file", path_}, {"error", v.error().message}});
    return;
  }
  const json::Value* last = v->is_object() ? v->get("last_resume_ms") : nullptr;
  const json::Value* list = v->is_object() ? v->get("estops") : nullptr;
  if (!v->is_object() || json::string_field(*v, "fleet_id") != fleet_id_ ||
      json::string_field(*v, "member_id") != member_id_ || last == nullptr || !last->is_int() ||
      list == nullptr || !list->is_array()) {
    log(LogLevel::kWarn, "fleet_estops_ignored",
        json::Object{{"file", path_}, {"reason", "not this member's fleet ESTOP ledger"}});
    return;
  }
  MutexLock lk(mu_);
  last_resume_ms_ = last->as_int();
  for (const auto& e : list->as_array()) {
    const std::string id = e.is_object() ? json::string_field(e, "id") : "";
    const json::Value* ts = e.is_object() ? e.get("ts") : nullptr;
    const json::Value* exp = e.is_object() ? e.get("exp") : nullptr;
    if (id.empty() || id.size() > 256 || ts == nullptr || !ts->is_int() || exp == nullptr ||
        !exp->is_int())
      continue;
    entries_[id] = Entry{ts->as_int(), exp->as_int(), json::bool_field(e, "superseded")};
  }
}

FleetEstopLedger::Verdict FleetEstopLedger::judge(const std::string& id, int64_t ts_ms,
                                                  bool standing) const {
  MutexLock lk(mu_);
  auto it = entries_.find(id);
  if (it != entries_.end() && it->second.superseded) return Verdict::kSuperseded;
  // A live ESTOP is judged by the freshness window like any message; a standing one has no
  // other bound than this. Both stamps are their senders' clocks: two coordinators' may differ,
  // so a standing ESTOP is refused by its stamp only when it is older than the RESUME by more
  // than a message's freshness window — a genuine new ESTOP from a coordinator whose clock is
  // behind still stops the robot (a replay of one this robot obeyed is refused by its id).
  if (standing && last_resume_ms_ != 0 && ts_ms + kClockMarginMs <= last_resume_ms_)
    return Verdict::kOlderThanResume;
  return Verdict::kObey;
}

void FleetEstopLedger::honoured(const std::string& id, int64_t ts_ms, std::optional<int64_t> exp_s,
                                int64_t now_s) {
  MutexLock lk(mu_);
  if (entries_.count(id) != 0) return;  // a second copy (QoS 1, the retained one): known
  entries_[id] = Entry{ts_ms, exp_s.value_or(0), false};
  prune_locked(now_s);
  persist_locked();
}

void FleetEstopLedger::resumed(int64_t ts_ms, int64_t now_s) {
  MutexLock lk(mu_);
  last_resume_ms_ = std::max(last_resume_ms_, ts_ms);
  for (auto& [id, e] : entries_) e.superseded = true;
  prune_locked(now_s);
  persist_locked();
}

int64_t FleetEstopLedger::last_resume_ms() const {
  MutexLock lk(mu_);
  return last_resume_ms_;
}

size_t FleetEstopLedger::size() const {
  MutexLock lk(mu_);
  return entries_.size();
}

void FleetEstopLedger::prune_locked(int64_t now_s) {
  for (auto it = entries_.begin(); it != entries_.end();) {
    if (it->second.exp_s != 0 && it->second.exp_s <= now_s)
      it = entries_.erase(it);  // its token no longer verifies: the ESTOP cannot act again
    else
      ++it;
  }
  while (entries_.size() > kMaxEntries) {
    auto oldest = std::min_element(
        entries_.begin(), entries_.end(),
        [](const auto& a, const auto& b) { return a.second.ts_ms < b.second.ts_ms; });
    entries_.erase(oldest);
  }
}

void FleetEstopLedger::persist_locked() {
  if (path_.empty()) return;
  json::Array list;
  for (const auto& [id, e] : entries_)
    list.emplace_back(
        json::Object{{"id", id}, {"ts", e.ts_ms}, {"exp", e.exp_s}, {"superseded", e.superseded}});
  json::Value doc(json::Object{{"fleet_id", fleet_id_},
                               {"member_id", member_id_},
                               {"last_resume_ms", last_resume_ms_},
                               {"estops", std::move(list)}});
  if (Status st = write_state_file(path_, doc); !st.ok())
    log(LogLevel::kError, "fleet_estops_write_failed",
        json::Object{{"file", path_}, {"error", st.error().message}});
}

}  // namespace rcan::node
