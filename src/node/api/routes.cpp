// The node's HTTP routes, all of them, in one table (route_table.h): the public read-only
// routes, the message routes into the pipeline, control sessions and their kin
// (control_routes.cpp), §16 (ai_routes.cpp), the audit log and the dashboard's files.
#include "node/api/ai_routes.h"
#include "node/api/node.h"
#include "node/api/web_assets.h"
#include "node/discovery/mdns.h"
#include "rcan/errors.h"

namespace rcan::node {

void Node::add_routes() {
  RouteTable& t = routes_;
  auto healthz = [this](RouteCall& c) {
    bool ok = svc_.audit.available();
    answer_json(c.respond, c.route, ok ? 200 : 503,
                json::Object{{"status", ok ? "ok" : "degraded"},
                             {"estop_active", svc_.act.estop_active()},
                             {"audit_available", ok}});
  };
  t.add("GET", "/healthz", Body::kNone, healthz);
  t.add("HEAD", "/healthz", Body::kNone, healthz);
  t.add("GET", "/metrics", Body::kNone, [this](RouteCall& c) {
    svc_.metrics.count_request(c.route, 200);
    transport::HttpResponse r;
    r.content_type = "text/plain; version=0.0.4";
    r.body = svc_.metrics.render();
    c.respond(std::move(r));
  });
  t.add("POST", "/rcan/v1/discover", Body::kJsonOrEmpty, [this](RouteCall& c) {
    std::string reply;
    if (const json::Value* id = c.body.get("message_id"); id && id->is_string())
      reply = id->as_string().substr(0, 64);
    answer_json(c.respond, c.route, 200,
                svc_.envelope(MessageType::kAnnounce, svc_.discovery_info().as_object(), reply));
  });
  t.add("GET", "/api/discovery", Body::kNone, [this](RouteCall& c) {
    std::string caps;
    for (const auto& cap : svc_.settings.capabilities) caps += (caps.empty() ? "" : ",") + cap;
    json::Object txt{{"ruri", svc_.settings.ruri},
                     {"model", svc_.settings.model},
                     {"caps", caps},
                     {"roles", "creator,owner,leasee,user,guest"},
                     {"role", "GUEST"},
                     {"version", svc_.settings.rcan_version},
                     {"name", svc_.settings.name},
                     {"status", status_word(svc_)}};  // as in the mDNS TXT record
    if (!svc_.settings.ruri_sdk.empty()) txt.set("ruri_sdk", svc_.settings.ruri_sdk);
    answer_json(c.respond, c.route, 200,
                json::Object{{"service_type", "_rcan._tcp"}, {"txt_record", txt}});
  });
  auto status = [this](RouteCall& c) {
    bool detailed = false;
    if (!c.req.header("authorization").empty()) {
      auto pr = bearer_principal(c.req);
      if (!pr.ok()) return answer_error(c.respond, c.route, pr.error());
      detailed = true;
    }
    answer_json(c.respond, c.route, 200, svc_.status(detailed));
  };
  t.add("GET", "/rcan/v1/status", Body::kNone, status);
  t.add("GET", "/api/status", Body::kNone, status);
  auto command = [this](RouteCall& c) {
    run_pipeline(c.req, c.respond, c.route, std::move(c.body));
  };
  t.add("POST", "/rcan/v1/command", Body::kJson, command);
  t.add("POST", "/api/command", Body::kJson, command);
  t.add("POST", "/api/stop", Body::kJsonOrEmpty, [this](RouteCall& c) {
    json::Value body = std::move(c.body);
    // A bare stop request becomes a SAFETY ESTOP message from the caller.
    if (!body.is_object() || !body.get("type")) {
      json::Object payload{{"safety_event", "ESTOP"}};
      if (body.is_object())
        if (const json::Value* r = body.get("reason"); r && r->is_string())
          payload.set("reason", r->as_string());
      body = json::Object{
          {"version", "1.0.0"},   {"message_id", new_uuid_v4()},          {"type", "SAFETY"},
          {"priority", "SAFETY"}, {"timestamp_ms", svc_.clock.wall_ms()}, {"payload", payload}};
    }
    run_pipeline(c.req, c.respond, c.route, std::move(body));
  });
  add_control_routes();
  add_revocation_routes();
  add_robots_routes();
  add_ai_routes(t, svc_);
  t.add("GET", "/api/audit", Body::kNone,
        [this](RouteCall& c) { audit_listing(c.req, c.respond, c.route); });
  t.add("GET", "/api/v1/audit", Body::kNone,
        [this](RouteCall& c) { audit_export(c.req, c.respond, c.route); });
  t.add("GET", "/api/node/log", Body::kNone,
        [this](RouteCall& c) { node_log(c.req, c.respond, c.route); });
  // The operator dashboard (docs/DASHBOARD.md): its files answer with their security headers.
  for (const char* path : {"/", "/index.html", "/favicon.ico", "/ui", "/ui/", "/ui/*"})
    for (const char* method : {"GET", "HEAD"})
      t.add(method, path, Body::kNone, [this](RouteCall& c) {
        transport::HttpResponse r = web_response(c.req, svc_.clock.wall_ms());
        svc_.metrics.count_request("/ui", r.status);
        c.respond(std::move(r));
      });
}

// Control sessions, the queue, handoff, leases, ownership transfer and consent requests.
// Their bodies are JSON objects (or empty); each handler authenticates by route_principal().
// A lease's and a consent request's own paths answer, and are audited, under the collection's
// label (/rcan/v1/leases, /rcan/v1/consent).
void Node::add_control_routes() {
  RouteTable& t = routes_;
  const BodyLimits limits{.max_bytes = 0, .max_depth = 16};
  auto row = [&](const char* method, const char* path,
                 void (Node::*fn)(transport::HttpRequest&, Respond&, const json::Value&,
                                  const std::string&)) {
    t.add(
        method, path, Body::kObjectOrEmpty,
        [this, fn](RouteCall& c) { (this->*fn)(c.req, c.respond, c.body, c.route); }, limits);
  };
  row("POST", "/rcan/v1/auth/claim", &Node::claim_route);
  row("DELETE", "/rcan/v1/auth/release", &Node::release_route);
  row("POST", "/rcan/v1/auth/release", &Node::release_route);
  row("POST", "/rcan/v1/handoff", &Node::handoff_route);
  row("POST", "/rcan/v1/auth/renew", &Node::renew_route);
  row("GET", "/rcan/v1/auth/queue", &Node::queue_route);
  row("DELETE", "/rcan/v1/auth/queue", &Node::queue_route);
  auto lease = [&](const char* method, const char* path, bool grants) {
    t.add(
        method, path, Body::kObjectOrEmpty,
        [this, grants](RouteCall& c) {
          lease_route(c.req, c.respond, c.body, c.route, c.params.empty() ? "" : c.params[0],
                      grants);
        },
        limits, "/rcan/v1/leases");
  };
  lease("GET", "/rcan/v1/leases", false);
  lease("POST", "/rcan/v1/leases", false);
  lease("DELETE", "/rcan/v1/leases/{id}", false);
  lease("POST", "/rcan/v1/leases/{id}/grants", true);
  row("GET", "/rcan/v1/transfer", &Node::transfer_route);
  row("POST", "/rcan/v1/transfer", &Node::transfer_route);
  row("GET", "/rcan/v1/consent", &Node::consent_list_route);
  row("POST", "/rcan/v1/consent", &Node::consent_request_route);
  for (const char* verb : {"grant", "deny"})
    t.add(
        "POST", std::string("/rcan/v1/consent/{id}/") + verb, Body::kObjectOrEmpty,
        [this, verb](RouteCall& c) {
          consent_decision_route(c.req, c.respond, c.body, c.route, c.params[0], verb);
        },
        limits, "/rcan/v1/consent");
}

}  // namespace rcan::node
