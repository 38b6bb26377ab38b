// libFuzzer: the registry's request bodies (src/registry/api/body.h). Any bytes must parse or
// fail cleanly as registration, update, key, node and webhook subscription requests and sync
// records; whatever is accepted must hold the invariants the routes and the store rely on (slugs of
// [a-z0-9-] with one alphanumeric, at most 64 characters; metadata a JSON object within its bound;
// endpoints a JSON array).
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "rcan/json.h"
#include "registry/api/body.h"
#include "registry/api/sync.h"

namespace {

void require(bool cond) {
  if (!cond) std::abort();
}

void check_slug(const std::string& s) {
  require(!s.empty() && s.size() <= 64 && rcan::registry::api::usable_slug(s));
  for (char c : s) require((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-');
  require(rcan::registry::slugify(s) == s);  // slugging is idempotent
}

void check_json(const std::string& text, bool object) {
  auto v = rcan::json::parse(text);
  require(v.ok());
  require(object ? v->is_object() : v->is_array());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  namespace api = rcan::registry::api;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  const std::string now = "2026-11-27T05:20:00.000Z";
  if (auto r = api::parse_registration(text, now); r.ok()) {
    for (const auto* s : {&r->manufacturer, &r->model, &r->version, &r->device_id}) check_slug(*s);
    check_json(r->metadata_json, true);
    require(r->metadata_json.size() <= api::kMaxMetadataBytes);
    check_json(r->endpoints_json, false);
    require(r->description.size() <= api::kMaxTextField);
    if (r->proof) require(!r->proof->challenge_id.empty());
    std::string m = rcan::registry::proof_message("c", "n", r->manufacturer, r->model, r->version,
                                                  r->device_id);
    require(m.rfind("rcan-registry-pop:c:n:", 0) == 0);
  }
  if (auto u = api::parse_update(text, now); u.ok()) {
    if (u->metadata_json) check_json(*u->metadata_json, true);
    if (u->endpoints_json) check_json(*u->endpoints_json, false);
  }
  if (auto k = api::parse_key_request(text); k.ok())
    require(k->role == "registrant" || k->role == "admin");
  if (auto n = api::parse_node_request(text); n.ok()) {
    require(api::valid_prefix(n->prefix));
    require(n->node_url.rfind("https://", 0) == 0);
  }
  if (auto iso = api::normalize_iso(text); iso) {
    require(iso->size() == 24 && iso->back() == 'Z' && (*iso)[10] == 'T');
  }
  if (auto v = rcan::json::parse(text); v.ok()) {
    if (auto r = api::robot_from_sync(*v); r) {  // a federation sync record
      for (const auto* s : {&r->manufacturer, &r->model, &r->version, &r->device_id})
        check_slug(*s);
      require(api::parse_rrn(r->rrn).has_value());
      check_json(r->metadata_json, true);
      check_json(r->endpoints_json, false);
    }
  }
  for (bool allow_http : {false, true}) {
    if (auto w = api::parse_webhook_request(text, allow_http); w.ok()) {
      require(w->prefix == "RRN" || api::valid_prefix(w->prefix));
      require(w->url.rfind("https://", 0) == 0 || (allow_http && w->url.rfind("http://", 0) == 0));
      for (char c : w->url) require(static_cast<unsigned char>(c) > 0x20 && c != 0x7f);
      require(w->secret.size() >= api::kMinWebhookSecret &&
              w->secret.size() <= api::kMaxWebhookSecret);
    }
  }
  if (auto rrn = api::parse_rrn(text); rrn) {
    require(rrn->rrn.rfind("RRN-", 0) == 0);
    require(rrn->prefix.empty() || api::valid_prefix(rrn->prefix));
    require(api::parse_rrn(rrn->rrn).has_value());
  }
  std::string slug = rcan::registry::slugify(text);
  require(slug.size() <= 64 && rcan::registry::slugify(slug) == slug);
  return 0;
}
