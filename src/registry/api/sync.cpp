#include "registry/api/sync.h"

#include <cctype>
#include <chrono>
#include <map>
#include <set>

#include "base/clock.h"
#include "base/strings.h"
#include "registry/api/body.h"
#include "registry/api/registry_api.h"
#include "runtime/http_client.h"
#include "runtime/log.h"

namespace rcan::registry::api {
namespace {

std::string text(const json::Value& o, std::string_view key, size_t max, bool& ok) {
  const json::Value* v = o.get(key);
  if (v == nullptr || v->is_null()) return {};
  if (!v->is_string() || v->as_string().size() > max) {
    ok = false;
    return {};
  }
  return v->as_string();
}

}  // namespace

std::optional<Robot> robot_from_sync(const json::Value& rec) {
  if (!rec.is_object()) return std::nullopt;
  bool ok = true;
  Robot r;
  auto rrn = parse_rrn(text(rec, "rrn", 64, ok));
  if (!rrn) return std::nullopt;
  r.rrn = rrn->rrn;
  r.manufacturer = text(rec, "manufacturer", 64, ok);
  r.model = text(rec, "model", 64, ok);
  r.version = text(rec, "version", 64, ok);
  r.device_id = text(rec, "device_id", 64, ok);
  r.rcan_uri = text(rec, "rcan_uri", kMaxUrl, ok);
  r.verification_tier = text(rec, "verification_tier", 32, ok);
  if (r.verification_tier.empty()) r.verification_tier = "community";
  r.description = text(rec, "description", kMaxTextField, ok);
  r.contact_email = text(rec, "contact_email", 256, ok);
  r.source = text(rec, "source", kMaxTextField, ok);
  r.ed25519_pub = text(rec, "ed25519_public_key", 256, ok);
  r.mldsa65_pub = text(rec, "mldsa65_public_key", 4096, ok);
  r.registered_at = text(rec, "registered_at", 32, ok);
  r.updated_at = text(rec, "updated_at", 32, ok);
  for (const std::string* s : {&r.manufacturer, &r.model, &r.version, &r.device_id})
    if (!usable_slug(*s) || slugify(*s) != *s) ok = false;
  if (!ok || r.rcan_uri.rfind("rcan://", 0) != 0 || r.updated_at.empty()) return std::nullopt;
  if (const json::Value* m = rec.get("metadata"); m != nullptr && m->is_object()) {
    r.metadata_json = json::dump(*m);
    if (r.metadata_json.size() > kMaxMetadataBytes) return std::nullopt;
  }
  if (const json::Value* e = rec.get("endpoints"); e != nullptr && e->is_array()) {
    if (e->as_array().size() > kMaxEndpoints) return std::nullopt;
    r.endpoints_json = json::dump(*e);
  }
  const json::Value* del = rec.get("deleted");
  r.deleted = (del != nullptr && del->is_bool() && del->as_bool()) ||
              text(rec, "status", 16, ok) == "deleted";
  return r;
}

std::optional<std::string> deletion_from_sync(const json::Value& rec) {
  if (!rec.is_object()) return std::nullopt;
  const json::Value* del = rec.get("deleted");
  const json::Value* status = rec.get("status");
  const bool deleted =
      (del != nullptr && del->is_bool() && del->as_bool()) ||
      (status != nullptr && status->is_string() && status->as_string() == "deleted");
  if (!deleted) return std::nullopt;
  bool ok = true;
  auto rrn = parse_rrn(text(rec, "rrn", 64, ok));
  if (!ok || !rrn) return std::nullopt;
  return rrn->rrn;
}

SyncPuller::SyncPuller(Store& store, std::vector<std::string> urls, int interval_ms,
                       bool allow_http, bool delegations, Imported on_imported)
    : store_(store),
      urls_(std::move(urls)),
      interval_ms_(interval_ms),
      allow_http_(allow_http),
      delegations_(delegations),
      on_imported_(std::move(on_imported)) {
  for (std::string& u : urls_)
    while (!u.empty() && u.back() == '/') u.pop_back();
  worker_ = std::thread([this] { run(); });
}

SyncPuller::~SyncPuller() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (worker_.joinable()) worker_.join();
}

void SyncPuller::run() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stop_) {
    cv_.wait_for(lock, std::chrono::milliseconds(interval_ms_));
    if (stop_) break;
    lock.unlock();
    std::set<std::string> urls(urls_.begin(), urls_.end());
    if (delegations_) {
      auto dels = store_.list_delegations();
      if (dels.ok())
        for (const Delegation& d : *dels) urls.insert(d.node_url);
    }
    for (const std::string& u : urls) pull(u);
    lock.lock();
  }
}

Result<std::string> SyncPuller::judge(Robot& r, const std::string& node_host) {
  // The node speaks for the names under its own host, never for another registry's.
  const std::string own_uri = "rcan://" + node_host + "/" + r.manufacturer + "/" + r.model + "/" +
                              r.version + "/" + r.device_id;
  if (r.rcan_uri != own_uri) return std::string("uri_not_under_node");
  auto existing = store_.get_robot(r.rrn);
  if (!existing.ok()) return existing.error();
  // A record of this registry's own (it has an owner here) is never replaced by a copy.
  if (*existing && !(*existing)->owner_key_id.empty()) return std::string("rrn_is_local");
  auto same_uri = store_.find_robot_by_uri(r.rcan_uri);
  if (!same_uri.ok()) return same_uri.error();
  if (*same_uri && (*same_uri)->rrn != r.rrn) return std::string("uri_taken");
  // What this registry says of the copy is its own judgement: the tier it gave (community until
  // an admin here says otherwise) and its own times, never the node's.
  r.verification_tier = *existing ? (*existing)->verification_tier : std::string("community");
  const std::string now = iso_utc(unix_ms());
  r.registered_at = *existing ? (*existing)->registered_at : now;
  r.updated_at = now;
  return std::string();
}

Result<std::string> SyncPuller::forget(const std::string& rrn, const std::string& node_host,
                                       const std::string& url) {
  auto existing = store_.get_robot(rrn);
  if (!existing.ok()) return existing.error();
  if (!*existing) return std::string();  // never pulled here, or deleted already
  Robot gone = **existing;
  auto why = judge(gone, node_host);
  if (!why.ok() || !why->empty()) return why;
  gone.description.clear();
  gone.contact_email.clear();
  gone.source.clear();
  gone.metadata_json = "{}";
  gone.endpoints_json = "[]";
  gone.ed25519_pub.clear();
  gone.mldsa65_pub.clear();
  gone.deleted = true;
  if (Status s = store_.upsert_synced_robot(gone); !s.ok()) return s.error();
  imported.fetch_add(1);
  if (on_imported_) on_imported_(gone, url);
  return std::string();
}

void SyncPuller::pull(const std::string& url) {
  auto fail = [&](const std::string& why) {
    failures.fetch_add(1);
    log(LogLevel::kWarn, "registry_sync_failed", json::Object{{"from", url}, {"error", why}});
  };
  pulls.fetch_add(1);
  if (url.rfind("https://", 0) != 0 && !(allow_http_ && url.rfind("http://", 0) == 0))
    return fail("sync URLs must be https:// (http:// needs --allow-http-node-urls)");
  // The prefixes delegated to this URL; when they change, pull again from the start (records
  // refused before a delegation existed are taken then).
  auto dels = store_.list_delegations();
  if (!dels.ok()) return fail(dels.error().message);
  std::set<std::string> allowed;
  for (const Delegation& d : *dels)
    if (d.node_url == url) allowed.insert(d.prefix);
  std::string fingerprint;
  for (const std::string& p : allowed) fingerprint += p + ",";
  std::string& since = since_[url];
  if (fingerprint_[url] != fingerprint) {
    fingerprint_[url] = fingerprint;
    since.clear();
  }
  auto node = parse_web_url(url);
  if (!node.ok()) return fail(node.error().message);
  const std::string node_host = ascii_lower(node->host);
  // Records refused for what they claim (below), by reason: one log line a pull, not one each.
  std::map<std::string, std::vector<std::string>> refusals;
  struct LogRefusals {
    const std::string& url;
    std::map<std::string, std::vector<std::string>>& by_reason;
    ~LogRefusals() {
      for (auto& [reason, rrns] : by_reason) {
        json::Array some;
        for (size_t i = 0; i < rrns.size() && i < 10; ++i) some.emplace_back(rrns[i]);
        log(LogLevel::kWarn, "registry_sync_refused",
            json::Object{{"from", url},
                         {"reason", reason},
                         {"count", static_cast<int64_t>(rrns.size())},
                         {"rrns", std::move(some)}});
      }
    }
  } log_refusals{url, refusals};
  for (int page = 0; page < 20; ++page) {  // at most 20 pages of 500 a round
    auto u = parse_web_url(url + "/api/v1/sync?limit=500&since=" +
                           (since.empty() ? std::string("1970-01-01T00:00:00.000Z") : since));
    if (!u.ok()) return fail(u.error().message);
    HttpRequestOptions ro;
    ro.max_body = 16 * 1024 * 1024;
    auto a = http_request("GET", *u, "", 10000, ro);
    if (!a.ok()) return fail(a.error().message);
    if (a->status != 200) return fail("HTTP " + std::to_string(a->status));
    auto v = json::parse(a->body);
    if (!v.ok() || !v->is_object()) return fail("the answer is not a JSON object");
    const json::Value* recs = v->get("records");
    const json::Value* next = v->get("next_since");
    if (recs == nullptr || !recs->is_array() || next == nullptr || !next->is_string())
      return fail("the answer has no records or next_since");
    for (char c : next->as_string())
      if (!((c >= '0' && c <= '9') || c == '-' || c == ':' || c == '.' || c == 'T' || c == 'Z'))
        return fail("next_since is not an ISO time");
    for (const json::Value& rec : recs->as_array()) {
      if (auto gone = deletion_from_sync(rec)) {
        auto p = parse_rrn(*gone);
        if (p->prefix.empty() || allowed.count(p->prefix) == 0) {
          refused.fetch_add(1);
          continue;
        }
        auto why = forget(*gone, node_host, url);
        if (!why.ok()) return fail(why.error().message);
        if (!why->empty()) {
          refused.fetch_add(1);
          refusals[*why].push_back(*gone);
        }
        continue;
      }
      auto r = robot_from_sync(rec);
      auto p = r ? parse_rrn(r->rrn) : std::nullopt;
      if (!r || !p || p->prefix.empty() || allowed.count(p->prefix) == 0) {
        refused.fetch_add(1);
        continue;
      }
      auto why = judge(*r, node_host);
      if (!why.ok()) return fail(why.error().message);
      if (!why->empty()) {
        refused.fetch_add(1);
        refusals[*why].push_back(r->rrn);
        continue;
      }
      if (Status s = store_.upsert_synced_robot(*r); !s.ok()) return fail(s.error().message);
      imported.fetch_add(1);
      if (on_imported_) on_imported_(*r, url);
    }
    since = next->as_string();
    const json::Value* more = v->get("has_more");
    if (more == nullptr || !more->is_bool() || !more->as_bool()) return;
  }
}

}  // namespace rcan::registry::api
