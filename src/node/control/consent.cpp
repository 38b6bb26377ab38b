#include "node/control/consent.h"

#include <cctype>

#include "rcan/errors.h"

namespace rcan::node {

json::Value ConsentRequest::to_json() const {
  json::Array sc;
  for (const auto& s : scopes) sc.emplace_back(s);
  json::Object o{{"consent_id", id},
                 {"requester", requester_sub},
                 {"requester_iss", requester_iss},
                 {"sender_type", sender_type},
                 {"scopes", sc},
                 {"duration_s", duration_s},
                 {"reason", reason},
                 {"created_ms", created_ms},
                 {"expires_ms", expires_ms},
                 {"status", status}};
  if (!cloud_provider.empty()) o.set("cloud_provider", cloud_provider);
  if (!function_name.empty()) o.set("function_name", function_name);
  if (!on_behalf_of.empty()) o.set("on_behalf_of", on_behalf_of);
  if (!decided_by.empty()) {
    o.set("decided_by", decided_by);
    o.set("decided_ms", decided_ms);
  }
  if (!grant_kind.empty()) o.set("grant_kind", grant_kind);
  if (!lease_id.empty()) o.set("lease_id", lease_id);
  return o;
}

json::Value consent_notification(const ConsentRequest& r, const std::string& robot_name) {
  std::string scopes = "[";
  for (size_t i = 0; i < r.scopes.size(); ++i) scopes += (i ? ", " : "") + r.scopes[i];
  scopes += "]";
  if (r.sender_type == "cloud_function") {
    std::string provider = r.cloud_provider;
    if (!provider.empty())
      provider[0] = static_cast<char>(std::toupper(static_cast<unsigned char>(provider[0])));
    std::string who = r.on_behalf_of.empty() ? r.requester_sub : r.on_behalf_of;
    return json::Object{
        {"title", "\xE2\x9A\xA0\xEF\xB8\x8F Service Consent Request"},
        {"body", provider + " function '" + r.function_name + "' (on behalf of " + who +
                     ") is requesting\naccess to " + robot_name + " with scope: " + scopes},
        {"highlight", "cloud_function: " + r.function_name + " via " + r.cloud_provider},
        {"consent_id", r.id},
        {"sender_type", r.sender_type}};
  }
  std::string who = r.requester_sub;
  if (r.sender_type == "robot") who = "Robot " + who;
  return json::Object{
      {"title", "Consent Request"},
      {"body", who + " is requesting access to " + robot_name + " with scope: " + scopes},
      {"consent_id", r.id},
      {"sender_type", r.sender_type}};
}

Result<ConsentRequest> ConsentBook::add(ConsentRequest r, int64_t now_ms) {
  MutexLock lock(mu_);
  size_t pending = 0;
  for (const auto& x : items_)
    if (x.status == "PENDING") ++pending;
  if (pending >= 256)
    return Error(ErrorCode::kControlConflict, "too many consent requests are pending");
  if (items_.size() >= 1024) {
    for (auto it = items_.begin(); it != items_.end(); ++it)
      if (it->status != "PENDING") {
        items_.erase(it);
        break;
      }
  }
  r.id = new_uuid_v4();
  r.created_ms = now_ms;
  r.expires_ms = now_ms + ttl_ms_;
  r.status = "PENDING";
  items_.push_back(r);
  bump();
  return r;
}

Result<ConsentRequest> ConsentBook::get(const std::string& id) {
  MutexLock lock(mu_);
  for (const auto& x : items_)
    if (x.id == id) return x;
  return Error(ErrorCode::kNotFound, "no consent request " + id.substr(0, 64), "consent_id");
}

Result<ConsentRequest> ConsentBook::decide(const std::string& id, bool grant, const std::string& by,
                                           const std::string& kind, const std::string& lease_id,
                                           int64_t now_ms) {
  MutexLock lock(mu_);
  for (auto& x : items_) {
    if (x.id != id) continue;
    if (x.status == "PENDING" && now_ms >= x.expires_ms) {
      x.status = "EXPIRED";
      bump();
    }
    if (x.status == "EXPIRED")
      return Error(ErrorCode::kSessionExpired, "the consent request expired", "consent_id");
    if (x.status != "PENDING")
      return Error(ErrorCode::kControlConflict, "the consent request was already " + x.status,
                   "consent_id");
    x.status = grant ? "GRANTED" : "DENIED";
    x.decided_by = by;
    x.decided_ms = now_ms;
    x.grant_kind = grant ? kind : "";
    x.lease_id = lease_id;
    bump();
    return x;
  }
  return Error(ErrorCode::kNotFound, "no consent request " + id.substr(0, 64), "consent_id");
}

void ConsentBook::bump() {
  ++version_;
  if (on_change_) on_change_();
}

bool ConsentBook::quiet() {
  MutexLock lock(mu_);
  for (const auto& x : items_)
    if (x.status == "PENDING") return false;
  return true;
}

std::vector<ConsentRequest> ConsentBook::expire(int64_t now_ms) {
  MutexLock lock(mu_);
  std::vector<ConsentRequest> out;
  for (auto& x : items_)
    if (x.status == "PENDING" && now_ms >= x.expires_ms) {
      x.status = "EXPIRED";
      out.push_back(x);
      bump();
    }
  return out;
}

std::vector<ConsentRequest> ConsentBook::list() {
  MutexLock lock(mu_);
  return items_;
}

void ConsentBook::clear() {
  MutexLock lock(mu_);
  items_.clear();
  bump();
}

json::Value ConsentBook::persist_json() {
  MutexLock lock(mu_);
  json::Array a;
  for (const auto& x : items_) a.push_back(x.to_json());
  return json::Object{{"requests", a}};
}

void ConsentBook::load_json(const json::Value& v) {
  const json::Value* a = v.get("requests");
  if (!a || !a->is_array()) return;
  MutexLock lock(mu_);
  items_.clear();
  for (const auto& e : a->as_array()) {
    if (!e.is_object()) continue;
    ConsentRequest r;
    r.id = json::string_field(e, "consent_id");
    r.requester_sub = json::string_field(e, "requester");
    r.requester_iss = json::string_field(e, "requester_iss");
    r.sender_type = json::string_field(e, "sender_type");
    r.cloud_provider = json::string_field(e, "cloud_provider");
    r.function_name = json::string_field(e, "function_name");
    r.on_behalf_of = json::string_field(e, "on_behalf_of");
    r.reason = json::string_field(e, "reason");
    r.duration_s = json::int_field(e, "duration_s");
    r.created_ms = json::int_field(e, "created_ms");
    r.expires_ms = json::int_field(e, "expires_ms");
    r.status = json::string_field(e, "status");
    r.decided_by = json::string_field(e, "decided_by");
    r.decided_ms = json::int_field(e, "decided_ms");
    r.grant_kind = json::string_field(e, "grant_kind");
    r.lease_id = json::string_field(e, "lease_id");
    if (const json::Value* s = e.get("scopes"); s && s->is_array())
      for (const auto& x : s->as_array())
        if (x.is_string()) r.scopes.push_back(x.as_string());
    if (r.id.empty() || r.status.empty()) continue;
    items_.push_back(std::move(r));
  }
  bump();
}

uint64_t ConsentBook::version() {
  MutexLock lock(mu_);
  return version_;
}

}  // namespace rcan::node
