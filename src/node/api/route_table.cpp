#include "node/api/route_table.h"

#include "rcan/errors.h"

namespace rcan::node {

void RouteTable::add(std::string method, std::string pattern, Body body, RouteHandler handler,
                     BodyLimits limits, std::string label) {
  router_.add(std::move(method), std::move(pattern), Row{body, limits, std::move(handler)},
              std::move(label));
}

transport::HttpResponse RouteTable::method_not_allowed(const json::Value& error_body,
                                                       std::string_view allow) {
  transport::HttpResponse r;
  r.status = 405;
  r.body = json::dump(error_body);
  r.headers.emplace_back("Allow", std::string(allow));
  return r;
}

void answer_json(NodeServices& svc, const transport::HttpHandler::Respond& respond,
                 const std::string& route, int status, const json::Value& body,
                 std::vector<std::pair<std::string, std::string>> headers) {
  svc.metrics.count_request(route, status);
  transport::HttpResponse r;
  r.status = status;
  r.body = json::dump(body);
  r.headers = std::move(headers);
  respond(std::move(r));
}

void answer_error(NodeServices& svc, const transport::HttpHandler::Respond& respond,
                  const std::string& route, const Error& err) {
  answer_json(svc, respond, route, http_status(err.code, err.reason), svc.error(err));
}

void RouteTable::dispatch(transport::HttpRequest& req,
                          transport::HttpHandler::Respond& respond) const {
  Router::Match m = router_.find(req.method, req.path);
  if (m.found()) return run(req, respond, *m.route, std::move(m.params));
  if (!m.method_not_allowed())
    return answer_json(
        svc_, respond, "other", 404,
        svc_.error(Error(ErrorCode::kNotFound, "no route for " + req.path.substr(0, 128))));
  const std::string& pattern = m.path->pattern;
  svc_.metrics.count_request(pattern, 405);
  respond(method_not_allowed(
      svc_.error(Error(ErrorCode::kMethodNotAllowed, req.method + " is not allowed on " + pattern)),
      m.allow));
}

void RouteTable::run(transport::HttpRequest& req, transport::HttpHandler::Respond& respond,
                     const Router::Route& route, std::vector<std::string> params) const {
  const Row& row = route.handler;
  RouteCall call{req, respond, route.label, route.pattern, json::Value(), std::move(params)};
  if (row.body != Body::kNone) {
    if (req.body.empty() && row.body != Body::kJson) {
      call.body = json::Object{};
    } else {
      json::ParseOptions po;
      po.max_bytes =
          row.limits.max_bytes ? row.limits.max_bytes : svc_.settings.codec.max_body_bytes;
      po.max_depth = row.limits.max_depth;
      auto v = json::parse(req.body, po);
      if (!v.ok()) return answer_error(svc_, respond, route.pattern, v.error());
      if (row.body == Body::kObjectOrEmpty && !v->is_object())
        return answer_json(
            svc_, respond, route.pattern, 400,
            svc_.error(Error(ErrorCode::kSchemaValidationFailed, "Invalid payload")));
      call.body = std::move(v).value();
    }
  }
  row.handler(call);
}

}  // namespace rcan::node
