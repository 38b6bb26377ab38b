// The §16 HTTP routes (docs/AI.md): AUTHORIZE, the pending list, the thought log and the
// public watermark verification endpoint. Node::route hands them over through ai_route().
#include "node/api/ai_routes.h"

#include "node/ai/ai_services.h"
#include "node/services/node_services.h"
#include "rcan/crypto/watermark.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

Result<Principal> bearer(NodeServices& svc, const transport::HttpRequest& req) {
  return svc.authenticate_header(req.header("authorization"),
                                 RefusalLedger::source_of(req.remote_addr));
}

void authorize_route(NodeServices& svc, AiServices& ai, transport::HttpRequest& req,
                     const transport::HttpHandler::Respond& respond, const std::string& route) {
  auto p = bearer(svc, req);
  if (!p.ok()) {
    svc.trail.record("HITL_AUTHORIZE_REFUSED", "blocked")
        .reason(std::string(error_name(p.error().code)))
        .detail("route", route)
        .write();
    return answer_error(svc, respond, route, p.error());
  }
  auto body = json::parse(req.body, {.max_depth = 16, .max_bytes = 64 * 1024});
  if (!body.ok()) return answer_error(svc, respond, route, body.error());
  ai.authorize(*p, *body, "http", route, [&svc, respond, route](int status, json::Value out) {
    answer_json(svc, respond, route, status, out);
  });
}

void pending_route(NodeServices& svc, AiServices& ai, transport::HttpRequest& req,
                   const transport::HttpHandler::Respond& respond, const std::string& route) {
  auto p = bearer(svc, req);
  if (!p.ok()) return answer_error(svc, respond, route, p.error());
  json::Value list = ai.pending_list();
  if (role_level(p->role) < role_level(Role::kOwner)) {
    // Below OWNER: only one's own held commands — by issuer and subject (docs/SECURITY.md R13;
    // an entry kept from before issuers were recorded matches by subject).
    json::Array mine;
    for (const auto& i : list.get("pending")->as_array()) {
      PrincipalId by{json::string_field(i, "requested_by_iss"),
                     json::string_field(i, "requested_by")};
      if (by.is(*p)) mine.push_back(i);
    }
    list = json::Object{{"pending", mine}, {"count", static_cast<int64_t>(mine.size())}};
  }
  answer_json(svc, respond, route, 200, list);
}

void thought_route(NodeServices& svc, AiServices& ai, transport::HttpRequest& req,
                   const transport::HttpHandler::Respond& respond, const std::string& route) {
  auto p = bearer(svc, req);
  if (!p.ok()) return answer_error(svc, respond, route, p.error());
  // `status` is the lowest scope (GUEST): every verified token holds it (docs/AI.md).
  std::string id = req.path.substr(std::string("/api/thoughts/").size());
  auto t = id.empty() || id.size() > 128 ? std::nullopt : ai.thoughts().get(id);
  if (!t)
    return answer_error(
        svc, respond, route,
        Error(ErrorCode::kNotFound, "no thought with id " + id.substr(0, 128), "thought_id"));
  bool reasoning = p->has_scope("config") && role_level(p->role) >= role_level(Role::kOwner);
  answer_json(svc, respond, route, 200, t->to_json(reasoning));
}

void verify_route(NodeServices& svc, AiServices& ai, transport::HttpRequest& req,
                  const transport::HttpHandler::Respond& respond, const std::string& route) {
  auto seed_error = [&svc, respond, route](int status, const char* msg) {
    answer_json(svc, respond, route, status,
                json::Object{{"error", msg}, {"code", "HTTP_" + std::to_string(status)}});
  };
  std::string token(req.query_value("token"));
  if (!req.has_query("token") || !watermark::valid_format(token))
    return seed_error(400, "Invalid watermark token format");
  std::string rrn(req.query_value("rrn"));
  if (req.has_query("rrn") && rrn != svc.settings.rrn)
    return seed_error(404, "Watermark token not found in audit log");
  bool posted = ai.worker().post([&svc, respond, route, token, seed_error]() mutable {
    auto lines = svc.audit.find_by_watermark(token);
    std::optional<json::Value> entry;
    if (lines.ok()) {
      for (const auto& l : *lines) {
        auto v = json::parse(l, {.max_depth = 64, .max_bytes = 1u << 20});
        if (!v.ok()) continue;
        const json::Value* ev = v->get("event");
        bool command = ev && ev->is_string() && ev->as_string() == "COMMAND";
        if (!entry || command) entry = std::move(v).value();
        if (command) break;
      }
    }
    if (!entry) return seed_error(404, "Watermark token not found in audit log");
    answer_json(svc, respond, route, 200,
                json::Object{{"valid", true},
                             {"rrn", svc.settings.rrn},
                             {"watermark_token", token},
                             {"audit_entry", *entry}});
  });
  if (!posted) answer_error(svc, respond, route, Error(ErrorCode::kSafeStop, "busy; try again"));
}

}  // namespace

void add_ai_routes(RouteTable& table, NodeServices& svc) {
  using Fn = void (*)(NodeServices&, AiServices&, transport::HttpRequest&,
                      const transport::HttpHandler::Respond&, const std::string&);
  // A thought answers under /api/thoughts; "not enabled" is counted under the row's pattern.
  auto row = [&](const char* method, const char* path, Fn fn, std::string label = {}) {
    table.add(
        method, path, Body::kNone,
        [&svc, fn](RouteCall& c) {
          if (!svc.ai)
            return answer_error(
                svc, c.respond, c.pattern,
                Error(ErrorCode::kNotFound, "AI accountability is not enabled on this node"));
          fn(svc, *svc.ai, c.req, c.respond, c.route);
        },
        {}, std::move(label));
  };
  row("POST", "/rcan/v1/authorize", &authorize_route);
  row("GET", "/rcan/v1/pending", &pending_route);
  row("GET", "/api/thoughts/{id}", &thought_route, "/api/thoughts");
  row("GET", "/api/v1/watermark/verify", &verify_route);
}

bool ai_stream_message(NodeServices& svc, const std::string& type, const json::Value& body,
                       const std::optional<Principal>& principal,
                       const std::function<void(std::string)>& send) {
  if (type != "AUTHORIZE") return false;
  if (!svc.ai || !principal) {
    send(json::dump(
        svc.error(Error(ErrorCode::kNotFound, "AI accountability is not enabled on this node"))));
    return true;
  }
  svc.ai->authorize(*principal, body, "ws", "/rcan/v1/stream",
                    [send](int, json::Value out) { send(json::dump(out)); });
  return true;
}

}  // namespace rcan::node
