#include "node/api/route_table.h"

#include "rcan/errors.h"

namespace rcan::node {
namespace {

// The next '/'-separated segment of `s` from `pos` (which points after a '/').
std::string_view segment(std::string_view s, size_t& pos) {
  size_t end = s.find('/', pos);
  std::string_view seg = s.substr(pos, end == std::string_view::npos ? end : end - pos);
  pos = end == std::string_view::npos ? s.size() + 1 : end + 1;
  return seg;
}

constexpr size_t kMaxParam = 128;

}  // namespace

bool RouteTable::match(std::string_view pattern, std::string_view path,
                       std::vector<std::string>* params) {
  if (pattern.empty() || path.empty() || pattern[0] != '/' || path[0] != '/') return false;
  if (params) params->clear();
  size_t pp = 1, sp = 1;
  while (pp <= pattern.size()) {
    std::string_view want = segment(pattern, pp);
    if (want == "*" && pp > pattern.size()) {  // the rest: one or more non-empty segments
      if (sp > path.size()) return false;
      std::string_view rest = path.substr(sp);
      if (rest.empty()) return false;
      if (params) params->emplace_back(rest);
      return true;
    }
    if (sp > path.size()) return false;
    std::string_view got = segment(path, sp);
    if (want.size() > 2 && want.front() == '{' && want.back() == '}') {
      if (got.empty() || got.size() > kMaxParam) return false;
      if (params) params->emplace_back(got);
    } else if (want != got) {
      return false;
    }
  }
  return sp > path.size();
}

void RouteTable::add(std::string method, std::string pattern, Body body, RouteHandler handler,
                     BodyLimits limits) {
  rows_.push_back(Row{std::move(method), std::move(pattern), body, limits, std::move(handler)});
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
  const Row* row = nullptr;
  for (const Row& r : rows_)
    if (r.method == req.method && match(r.pattern, req.path, nullptr)) {
      row = &r;
      break;
    }
  if (!row) {
    const Row* first = nullptr;
    std::string allow;  // every method the path serves, in table order
    for (const Row& r : rows_) {
      if (!match(r.pattern, req.path, nullptr)) continue;
      if (!first) first = &r;
      if (allow.find(r.method) == std::string::npos)
        allow += (allow.empty() ? "" : ", ") + r.method;
    }
    if (!first)
      return answer_json(
          svc_, respond, "other", 404,
          svc_.error(Error(ErrorCode::kNotFound, "no route for " + req.path.substr(0, 128))));
    svc_.metrics.count_request(first->pattern, 405);
    return respond(
        method_not_allowed(svc_.error(Error(ErrorCode::kMethodNotAllowed,
                                            req.method + " is not allowed on " + first->pattern)),
                           allow));
  }
  std::vector<std::string> params;
  match(row->pattern, req.path, &params);
  RouteCall call{req, respond, row->pattern, json::Value(), std::move(params)};
  if (row->body != Body::kNone) {
    if (req.body.empty() && row->body != Body::kJson) {
      call.body = json::Object{};
    } else {
      json::ParseOptions po;
      po.max_bytes =
          row->limits.max_bytes ? row->limits.max_bytes : svc_.settings.codec.max_body_bytes;
      po.max_depth = row->limits.max_depth;
      auto v = json::parse(req.body, po);
      if (!v.ok()) {
        const Error& e = v.error();
        return answer_error(svc_, respond, row->pattern, e);
      }
      if (row->body == Body::kObjectOrEmpty && !v->is_object())
        return answer_json(
            svc_, respond, row->pattern, 400,
            svc_.error(Error(ErrorCode::kSchemaValidationFailed, "Invalid payload")));
      call.body = std::move(v).value();
    }
  }
  row->handler(call);
}

}  // namespace rcan::node
