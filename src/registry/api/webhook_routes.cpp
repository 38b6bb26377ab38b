// Webhook subscriptions (docs/REGISTRY.md "Webhooks"): the reference's
// POST /api/v1/webhooks[/register], GET /api/v1/webhooks, DELETE /api/v1/webhooks/{id}, all
// for admin keys. Deliveries are src/registry/api/webhooks.h's.
#include <charconv>
#include <set>

#include "rcan/errors.h"
#include "registry/api/impl.h"
#include "runtime/http_client.h"

namespace rcan::registry::api {
namespace {

json::Object webhook_json(const Webhook& w) {
  return json::Object{
      {"id", w.id},
      {"node_prefix", w.prefix},
      {"webhook_url", w.url},
      {"has_secret", !w.secret.empty()},
      {"created_at", w.created_at},
      {"last_delivered_at",
       w.last_delivered_at.empty() ? json::Value() : json::Value(w.last_delivered_at)},
      {"failure_count", w.failure_count}};
}

}  // namespace

void RegistryApi::Impl::notify(const char* event, const Robot& r) {
  auto parsed = parse_rrn(r.rrn);
  std::string prefix = parsed && !parsed->prefix.empty() ? parsed->prefix : "RRN";
  webhooks->publish(event, r.rrn, prefix, r.deleted ? tombstone_json(r) : robot_json(r));
}

HttpResponse RegistryApi::Impl::list_webhooks(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err.status >= 500 ? err : ref_error(401, "Authorization required");
  if (!caller->is("admin")) return ref_error(401, "Authorization required");
  // Subscriptions are accepted for "RRN", this node's prefix and the delegated prefixes only.
  std::set<std::string> prefixes{"RRN"};
  if (!o.prefix.empty()) prefixes.insert(o.prefix);
  auto dels = store.list_delegations();
  if (!dels.ok()) return store_error(dels.error());
  for (const Delegation& d : *dels) prefixes.insert(d.prefix);
  json::Array out;
  for (const std::string& p : prefixes) {
    auto hooks = store.webhooks_for(p);
    if (!hooks.ok()) return store_error(hooks.error());
    for (const Webhook& w : *hooks) out.emplace_back(webhook_json(w));
  }
  int64_t n = static_cast<int64_t>(out.size());
  return json_response(200, json::Object{{"webhooks", std::move(out)}, {"count", n}});
}

HttpResponse RegistryApi::Impl::add_webhook(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err.status >= 500 ? err : ref_error(401, "Authorization required");
  if (auto l = limit_key(caller->key.id)) return *l;
  if (!caller->is("admin")) return ref_error(401, "Authorization required");
  auto w = parse_webhook_request(req.body, o.allow_http_node_urls);
  if (!w.ok()) return ref_error(400, w.error().message);
  auto url = parse_web_url(w->url);
  if (!url.ok()) return ref_error(400, "webhook_url is not a valid URL");
  // A literal address is judged now; a name when a delivery connects (webhooks.h).
  if (auto ip = parse_ip(url->host); ip && !is_public_address(*ip) && !o.webhooks.allow_private)
    return project_error(ErrorCode::kSchemaValidationFailed,
                         "webhook_url names a loopback, private or link-local address: webhooks "
                         "go to public addresses only (rcan-registry --allow-private-webhooks)",
                         "webhook_url", "private_address");
  // The reference's rule: a namespace this registry knows (RRN: the root namespace).
  bool known = w->prefix == "RRN" || w->prefix == o.prefix;
  if (!known) {
    auto d = store.get_delegation(w->prefix);
    if (!d.ok()) return store_error(d.error());
    known = d->has_value();
  }
  if (!known)
    return ref_error(422, "No namespace delegation found for prefix: " + w->prefix +
                              ". Register the node first.");
  if (auto a = audit_unavailable()) return *a;
  Webhook h;
  h.prefix = w->prefix;
  h.url = w->url;
  h.secret = w->secret;
  h.created_at = now();
  auto id = store.add_webhook(h);
  if (!id.ok()) return store_error(id.error());
  h.id = *id;
  audit("REGISTRY_WEBHOOK_ADDED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"webhook_id", h.id}, {"prefix", h.prefix}, {"url", h.url}});
  json::Object out = webhook_json(h);
  out.set("message", "Webhook registered successfully");
  return json_response(201, out);
}

HttpResponse RegistryApi::Impl::delete_webhook(const HttpRequest& req, const std::string& id) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err.status >= 500 ? err : ref_error(401, "Authorization required");
  if (auto l = limit_key(caller->key.id)) return *l;
  if (!caller->is("admin")) return ref_error(401, "Authorization required");
  int64_t n = 0;
  auto [end, ec] = std::from_chars(id.data(), id.data() + id.size(), n);
  if (ec != std::errc() || end != id.data() + id.size() || n <= 0)
    return ref_error(400, "Invalid webhook ID");
  if (auto a = audit_unavailable()) return *a;
  auto done = store.delete_webhook(n);
  if (!done.ok()) return store_error(done.error());
  if (!*done) return ref_error(404, "Webhook not found: " + id);
  audit("REGISTRY_WEBHOOK_REMOVED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"webhook_id", n}});
  return json_response(200, json::Object{{"message", "Webhook removed"}, {"id", n}});
}

}  // namespace rcan::registry::api
