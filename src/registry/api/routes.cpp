// The registry's HTTP routes, all of them, in one table (transport/router.h). A row's handler
// gets the API and the request, and the path's `*` segment when its pattern has one; the labels
// name the rows in /metrics. serve() (registry_api.cpp) answers 404 and 405 in the reference's
// form and applies OPTIONS and the rate limits before any row runs.
#include "registry/api/impl.h"

namespace rcan::registry::api {
namespace {

using Api = RegistryApi::Impl;

HttpResponse healthz(Api& a, const HttpRequest&, const std::string&) {
  return json_response(200,
                       json::Object{{"status", "ok"}, {"backend", std::string(a.store.backend())}});
}

HttpResponse metrics(Api& a, const HttpRequest&, const std::string&) {
  HttpResponse r;
  r.content_type = "text/plain; version=0.0.4";
  r.body = a.metrics.render();
  return r;
}

HttpResponse manifest(Api& a, const HttpRequest&, const std::string&) {
  HttpResponse r;
  r.body = a.manifest;
  r.headers.emplace_back("Cache-Control", "public, max-age=3600");
  return r;
}

// /api/v1/robots/<rrn>: a path that names no robot is a 404 whatever the method.
HttpResponse robot(Api& a, const HttpRequest& req, const std::string& tail) {
  auto rrn = parse_rrn(tail);
  if (!rrn) return ref_error(404, "Not found");
  if (req.method == "GET") return a.get_robot(rrn->rrn);
  if (req.method == "PATCH") return a.patch_robot(req, rrn->rrn);
  if (req.method == "DELETE") return a.delete_robot(req, rrn->rrn);
  return ref_error(405, "Method not allowed");
}

// Health, metrics, the manifest, the token authority's public endpoints and the device page.
void add_public_routes(RegistryRoutes& t) {
  t.add("GET", "/healthz", &healthz);
  t.add("GET", "/metrics", &metrics);
  t.add("GET", "/.well-known/rcan-node.json", &manifest);
  t.add("GET", "/.well-known/jwks.json",
        [](Api& a, const HttpRequest&, const std::string&) { return a.jwks(); });
  // The OAuth endpoints check their method themselves.
  t.add("*", "/oauth/token",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.oauth_token(req); });
  t.add("*", "/oauth/introspect",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.introspect(req); });
  t.add("*", "/oauth/device_authorization", [](Api& a, const HttpRequest& req, const std::string&) {
    return a.device_authorization(req);
  });
  auto device_page = [](Api& a, const HttpRequest& req, const std::string&) {
    return a.device_page(req);
  };
  t.add("GET", "/device", device_page);
  t.add("GET", "/device/", device_page, "/device");
}

// Robots, resolution, registry nodes, registration challenges and API keys.
void add_registry_routes(RegistryRoutes& t) {
  const std::string robots = "/api/v1/robots";
  t.add("GET", robots,
        [](Api& a, const HttpRequest& req, const std::string&) { return a.list_robots(req); });
  t.add("POST", robots,
        [](Api& a, const HttpRequest& req, const std::string&) { return a.register_robot(req); });
  t.add("GET", robots + "/search",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.search_robots(req); });
  // Any method: robot() answers 404 for a path that names no robot before it looks at it.
  t.add("*", robots + "/*", &robot, robots + "/{rrn}");

  t.add("GET", "/api/v1/resolve",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.resolve_uri(req); });
  t.add(
      "GET", "/api/v1/resolve/*",
      [](Api& a, const HttpRequest& req, const std::string& raw) { return a.resolve(req, raw); },
      "/api/v1/resolve/{rrn}");
  t.add("GET", "/api/v1/nodes",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.list_nodes(req); });
  t.add("POST", "/api/v1/nodes",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.add_node(req); });
  t.add(
      "GET", "/api/v1/nodes/*",
      [](Api& a, const HttpRequest&, const std::string& prefix) { return a.get_node(prefix); },
      "/api/v1/nodes/{prefix}");
  t.add("GET", "/api/v1/challenge",
        [](Api& a, const HttpRequest&, const std::string&) { return a.challenge(false); });
  t.add("POST", "/api/v1/challenge",
        [](Api& a, const HttpRequest&, const std::string&) { return a.challenge(true); });
  t.add("GET", "/api/v1/keys",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.list_keys(req); });
  t.add("POST", "/api/v1/keys",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.create_key_route(req); });
  t.add(
      "DELETE", "/api/v1/keys/*",
      [](Api& a, const HttpRequest& req, const std::string& id) { return a.revoke_key(req, id); },
      "/api/v1/keys/{id}");
}

// The token authority (revocations, signing keys, clients, grants, device approvals),
// federation sync and webhooks.
void add_authority_routes(RegistryRoutes& t) {
  t.add("GET", "/api/v1/revocations",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.list_revocations(req); });
  t.add("POST", "/api/v1/revocations",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.revoke(req); });
  t.add("POST", "/api/v1/authority/keys/rotate",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.rotate_keys(req); });
  for (const char* method : {"GET", "POST"}) {
    t.add(method, "/api/v1/clients",
          [](Api& a, const HttpRequest& req, const std::string&) { return a.clients_route(req); });
    t.add(method, "/api/v1/grants",
          [](Api& a, const HttpRequest& req, const std::string&) { return a.grants_route(req); });
  }
  t.add(
      "DELETE", "/api/v1/clients/*",
      [](Api& a, const HttpRequest& req, const std::string& id) {
        return a.delete_client(req, id);
      },
      "/api/v1/clients/{id}");
  t.add(
      "DELETE", "/api/v1/grants/*",
      [](Api& a, const HttpRequest& req, const std::string& id) { return a.delete_grant(req, id); },
      "/api/v1/grants/{id}");
  t.add("GET", "/api/v1/sync",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.sync(req); });
  auto add_webhook = [](Api& a, const HttpRequest& req, const std::string&) {
    return a.add_webhook(req);
  };
  t.add("GET", "/api/v1/webhooks",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.list_webhooks(req); });
  t.add("POST", "/api/v1/webhooks", add_webhook);
  t.add("POST", "/api/v1/webhooks/register", add_webhook);
  t.add(
      "DELETE", "/api/v1/webhooks/*",
      [](Api& a, const HttpRequest& req, const std::string& id) {
        return a.delete_webhook(req, id);
      },
      "/api/v1/webhooks/{id}");
  t.add("POST", "/api/v1/device/approve",
        [](Api& a, const HttpRequest& req, const std::string&) { return a.device_approve(req); });
  t.add(
      "GET", "/api/v1/device/requests/*",
      [](Api& a, const HttpRequest& req, const std::string& code) {
        return a.device_request_route(req, code);
      },
      "/api/v1/device/requests/{user_code}");
}

}  // namespace

const RegistryRoutes& registry_routes() {
  static const RegistryRoutes table = [] {
    RegistryRoutes t;  // in this order: a path's route is its first matching pattern
    add_public_routes(t);
    add_registry_routes(t);
    add_authority_routes(t);
    return t;
  }();
  return table;
}

std::string routing_path(std::string_view path) {
  constexpr std::string_view kApi = "/api/v1/";
  if (path.substr(0, kApi.size()) != kApi) return std::string(path);
  std::string_view rest = path.substr(kApi.size());
  while (!rest.empty() && rest.back() == '/') rest.remove_suffix(1);
  // rcan-py's NodeClient appends /api/v1/robots/<rrn> to a manifest's api_base, which already
  // ends in /api/v1 (rcan-ts appends /robots/<rrn>): serve both.
  if (rest.substr(0, 14) == "api/v1/robots/") rest.remove_prefix(7);
  return "/api/v1/" + std::string(rest);
}

}  // namespace rcan::registry::api
