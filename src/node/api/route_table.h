// RouteTable: every HTTP route of the node in one table, the node's layer over transport's
// Router (transport/router.h: patterns, matching, which row serves a method). A row adds how
// its body is read; the table answers the node's 404 for a path no row has and 405 (with
// `Allow`) for a method the path does not serve, reads the body by the row's rule and counts
// those answers under the row's pattern (so /metrics labels are bounded).
//
//   RouteTable t(services);
//   t.add("GET", "/rcan/v1/leases", Body::kNone, [](RouteCall& c) { … });
//   t.add("POST", "/rcan/v1/leases/{id}/grants", Body::kObjectOrEmpty, [](RouteCall& c) {
//     const std::string& lease_id = c.params[0];  … }, {}, "/rcan/v1/leases");
//   t.dispatch(request, respond);
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "transport/http_api.h"
#include "transport/router.h"

namespace rcan::node {

// How a row reads the request body before its handler runs. A body that breaks the rule is
// answered 400 (MALFORMED_JSON / SCHEMA_VALIDATION_FAILED) without calling the handler.
enum class Body {
  kNone,           // not read
  kJson,           // one JSON value, required
  kJsonOrEmpty,    // one JSON value; an empty body reads as {}
  kObjectOrEmpty,  // a JSON object; an empty body reads as {}
};

struct RouteCall {
  transport::HttpRequest& req;
  transport::HttpHandler::Respond& respond;
  const std::string& route;         // the row's label: what the handler counts and audits under
  const std::string& pattern;       // the row's pattern: what the table counts its refusals under
  json::Value body;                 // as the row's Body rule read it (null for kNone)
  std::vector<std::string> params;  // the `{…}` and `*` segments, in order
};

using RouteHandler = std::function<void(RouteCall&)>;

struct BodyLimits {
  size_t max_bytes = 0;  // 0: the node's codec limit (server.limits.max_body_bytes)
  int max_depth = 32;
};

// Answers `body` (JSON) with `status` and `headers`, counted under `route` in /metrics: how
// every route answers.
void answer_json(NodeServices& svc, const transport::HttpHandler::Respond& respond,
                 const std::string& route, int status, const json::Value& body,
                 std::vector<std::pair<std::string, std::string>> headers = {});
// The PROFILE.md error body of `err` with its HTTP status.
void answer_error(NodeServices& svc, const transport::HttpHandler::Respond& respond,
                  const std::string& route, const Error& err);

class RouteTable {
 public:
  explicit RouteTable(NodeServices& services) : svc_(services) {}

  // `label` empty: the pattern.
  void add(std::string method, std::string pattern, Body body, RouteHandler handler,
           BodyLimits limits = {}, std::string label = {});

  // Answers `req`: the handler of the matching row, or 404 / 405 / 400 as above.
  void dispatch(transport::HttpRequest& req, transport::HttpHandler::Respond& respond) const;

  // The one 405 answer: METHOD_NOT_ALLOWED naming the method and the route, `Allow` listing
  // the methods the route serves.
  static transport::HttpResponse method_not_allowed(const json::Value& error_body,
                                                    std::string_view allow);

 private:
  struct Row {
    Body body;
    BodyLimits limits;
    RouteHandler handler;
  };
  using Router = transport::Router<Row>;

  // Reads the body by the row's rule and calls its handler; answers 400 for a body that
  // breaks the rule.
  void run(transport::HttpRequest& req, transport::HttpHandler::Respond& respond,
           const Router::Route& route, std::vector<std::string> params) const;

  NodeServices& svc_;
  Router router_;
};

}  // namespace rcan::node
