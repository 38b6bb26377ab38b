#include "node/control/partition.h"

#include <pthread.h>

#include <algorithm>
#include <chrono>

#include "base/clock.h"
#include "runtime/http_client.h"

namespace rcan::node {

std::string_view net_mode_name(NetMode m) {
  switch (m) {
    case NetMode::kNormal:
      return "NORMAL";
    case NetMode::kOfflineAutonomous:
      return "OFFLINE_AUTONOMOUS";
    case NetMode::kLockdown:
      return "LOCKDOWN";
  }
  return "NORMAL";
}

PartitionMonitor::~PartitionMonitor() { stop(); }

void PartitionMonitor::configure(PartitionOptions o) { opts_ = std::move(o); }

int64_t PartitionMonitor::keys_base_locked() const {
  return opts_.keys_fetched_ms ? opts_.keys_fetched_ms() : last_ok_ms_;
}

NetMode PartitionMonitor::compute_locked(int64_t now_wall_ms) const {
  if (!enabled() || reachable_) return NetMode::kNormal;
  const int64_t base = keys_base_locked();
  if (base != 0 && now_wall_ms < base + opts_.key_ttl_ms) return NetMode::kOfflineAutonomous;
  return NetMode::kLockdown;
}

std::pair<NetMode, NetMode> PartitionMonitor::record(bool reachable, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  NetMode old = mode();
  if (reachable) {
    reachable_ = true;
    last_ok_ms_ = now_wall_ms;
    offline_since_ms_ = 0;
  } else {
    if (reachable_) offline_since_ms_ = now_wall_ms;
    reachable_ = false;
  }
  NetMode now = compute_locked(now_wall_ms);
  mode_.store(static_cast<int>(now));
  ++version_;
  return {old, now};
}

NetMode PartitionMonitor::probe_once() {
  if (!enabled()) return NetMode::kNormal;
  auto url = parse_web_url(opts_.issuer_url);
  HttpRequestOptions ho;
  ho.ca_file = opts_.ca_file;
  auto r = url.ok() ? http_request("GET", *url, "", opts_.timeout_ms, ho)
                    : Result<HttpAnswer>(url.error());
  bool ok = r.ok() && r->status >= 200 && r->status < 300;
  int64_t now = wall_ ? wall_() : 0;
  auto [old, cur] = record(ok, now);
  if (old != cur && on_change_) on_change_(old, cur);
  return cur;
}

void PartitionMonitor::start(std::function<int64_t()> wall_now,
                             std::function<void(NetMode, NetMode)> on_change) {
  wall_ = std::move(wall_now);
  on_change_ = std::move(on_change);
  if (!enabled()) return;
  {
    MutexLock lock(run_mu_);
    if (running_) return;
    running_ = true;
  }
  thread_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "partition");
    for (;;) {
      probe_once();
      MutexLock lock(run_mu_);
      const auto until = steady_now() + std::chrono::milliseconds(opts_.poll_interval_ms);
      while (running_) {
        if (run_cv_.wait_until(run_mu_, until) == std::cv_status::timeout) break;
      }
      if (!running_) return;
    }
  });
}

void PartitionMonitor::stop() {
  {
    MutexLock lock(run_mu_);
    running_ = false;
  }
  run_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void PartitionMonitor::note_validated(const Principal& p, int64_t now_wall_ms) {
  if (!enabled()) return;
  MutexLock lock(mu_);
  if (!reachable_) return;  // only what was validated while the issuer answered
  int64_t until = now_wall_ms + opts_.key_ttl_ms;
  if (p.token_exp) until = std::min(until, *p.token_exp * 1000);
  auto& slot = cache_[p.key()];
  if (slot != until) {
    slot = until;
    ++version_;
  }
  if (cache_.size() > 10000) cache_.erase(cache_.begin());
}

bool PartitionMonitor::cached(const Principal& p, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  auto it = cache_.find(p.key());
  const int64_t base = keys_base_locked();
  return it != cache_.end() && now_wall_ms < it->second && base != 0 &&
         now_wall_ms < base + opts_.key_ttl_ms;
}

json::Value PartitionMonitor::status_json(int64_t now_wall_ms) {
  MutexLock lock(mu_);
  json::Object o{{"mode", std::string(net_mode_name(mode()))},
                 {"issuer_probe", enabled()},
                 {"issuer_reachable", reachable_}};
  if (enabled()) {
    o.set("last_reachable_ms", last_ok_ms_ ? json::Value(last_ok_ms_) : json::Value());
    const int64_t base = keys_base_locked();
    o.set("keys_fresh_until_ms", base ? json::Value(base + opts_.key_ttl_ms) : json::Value());
    o.set("offline_since_s", offline_since_ms_
                                 ? json::Value((now_wall_ms - offline_since_ms_) / 1000)
                                 : json::Value());
    int64_t live = 0;
    for (const auto& [k, until] : cache_)
      if (until > now_wall_ms) ++live;
    o.set("cached_principals", live);
  }
  return o;
}

json::Value PartitionMonitor::persist_json() {
  MutexLock lock(mu_);
  json::Array entries;
  for (const auto& [k, until] : cache_)
    entries.push_back(json::Object{{"principal", k}, {"until_ms", until}});
  return json::Object{{"last_reachable_ms", last_ok_ms_}, {"principals", entries}};
}

void PartitionMonitor::load_json(const json::Value& v, int64_t now_wall_ms) {
  MutexLock lock(mu_);
  if (const json::Value* l = v.get("last_reachable_ms"); l && l->is_int())
    last_ok_ms_ = l->as_int();
  cache_.clear();
  if (const json::Value* a = v.get("principals"); a && a->is_array())
    for (const auto& e : a->as_array()) {
      const json::Value* k = e.get("principal");
      const json::Value* u = e.get("until_ms");
      if (k && k->is_string() && u && u->is_int() && u->as_int() > now_wall_ms)
        cache_[k->as_string()] = u->as_int();
    }
  // Until the first probe answers, the node is as reachable as its cache says.
  ++version_;
}

uint64_t PartitionMonitor::version() {
  MutexLock lock(mu_);
  return version_;
}

}  // namespace rcan::node
