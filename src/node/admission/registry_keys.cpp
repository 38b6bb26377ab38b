#include "node/admission/registry_keys.h"

#include <algorithm>

#include "node/admission/registry_feed.h"
#include "runtime/state_file.h"

namespace rcan::node {

bool RegistryKeys::install(const std::string& text, int64_t fetched_ms, const char* source) {
  const RegistryTrustOptions& o = link_.options();
  auto set = parse_registry_jwks(text);
  if (!set.ok()) {
    link_.failed("registry keys", set.error().message);
    link_.record({"REGISTRY_KEYS_REJECTED",
                  "error",
                  "malformed_jwks",
                  {{"registry", o.registry_url},
                   {"source", std::string(source)},
                   {"error", set.error().message}}});
    return false;
  }
  auto doc = json::parse(text, {.max_depth = 8, .max_bytes = kMaxRegistryJwksBytes});
  const std::string canon = doc.ok() ? json::canonical(*doc) : text;
  std::vector<std::string> kids;
  for (const auto& k : set->keys) kids.push_back(k.kid());
  bool changed;
  {
    MutexLock l(mu_);
    changed = canon != installed_;
    installed_ = canon;
    key_count_ = set->keys.size();
    kids_ = kids;
    source_ = source;
  }
  if (changed) {
    auth_.set_followed_issuer_keys(o.issuer, std::move(set->keys));
    json::Array ids;
    for (const auto& k : kids) ids.emplace_back(k);
    link_.record({"REGISTRY_KEYS_UPDATED",
                  "ok",
                  "",
                  {{"registry", o.registry_url},
                   {"issuer", o.issuer},
                   {"source", std::string(source)},
                   {"kids", json::Value(std::move(ids))},
                   {"skipped", static_cast<int64_t>(set->skipped)}}});
  }
  fetched_ms_.store(std::max(fetched_ms_.load(), fetched_ms));
  return true;
}

bool RegistryKeys::fetch(int timeout_ms) {
  ++fetches_;
  auto body = link_.get("/.well-known/jwks.json", timeout_ms);
  if (!body.ok()) return link_.failed("registry keys", body.error().message), ++failures_, false;
  const int64_t now = link_.clock().wall_ms();
  if (!install(*body, now, "fetched")) {
    ++failures_;
    return false;
  }
  auto doc = json::parse(*body, {.max_depth = 8, .max_bytes = kMaxRegistryJwksBytes});
  if (!doc.ok()) return true;  // install() parsed it: not reached
  const RegistryTrustOptions& o = link_.options();
  json::Object cache{{"registry_url", o.registry_url},
                     {"issuer", o.issuer},
                     {"fetched_at_ms", now},
                     {"jwks", *doc}};
  link_.keys_ok();
  Status s = link_.make_dir();
  if (s.ok())
    s = write_state_file(link_.dir() + "/jwks.json", json::Value(std::move(cache)), link_.env());
  if (!s.ok()) link_.failed("registry keys cache", s.error().message);
  return true;
}

bool RegistryKeys::load_cache() {
  const RegistryTrustOptions& o = link_.options();
  auto c = read_state_file(link_.dir() + "/jwks.json", link_.env());
  const json::Value* u = c.ok() ? c->get("registry_url") : nullptr;
  const json::Value* i = c.ok() ? c->get("issuer") : nullptr;
  const json::Value* at = c.ok() ? c->get("fetched_at_ms") : nullptr;
  const json::Value* jwks = c.ok() ? c->get("jwks") : nullptr;
  if (u && u->is_string() && u->as_string() == o.registry_url && i && i->is_string() &&
      i->as_string() == o.issuer && at && at->is_int() && jwks)
    return install(json::dump(*jwks), at->as_int(), "cache");
  return false;
}

size_t RegistryKeys::key_count() const {
  MutexLock l(mu_);
  return key_count_;
}

json::Value RegistryKeys::status_json() const {
  MutexLock l(mu_);
  json::Array kids;
  for (const auto& k : kids_) kids.emplace_back(k);
  const int64_t at = fetched_ms_.load();
  const int64_t max_age_ms = int64_t{link_.options().max_key_age_s} * 1000;
  return json::Object{{"fetched_at_ms", at ? json::Value(at) : json::Value()},
                      {"fresh_until_ms", at ? json::Value(at + max_age_ms) : json::Value()},
                      {"key_count", static_cast<int64_t>(key_count_)},
                      {"kids", std::move(kids)},
                      {"source", source_}};
}

}  // namespace rcan::node
