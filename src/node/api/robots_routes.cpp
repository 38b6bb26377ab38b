// The dashboard's Robots view (docs/DASHBOARD.md §Robots, docs/NODE.md §Routes):
//
//   GET  /api/robots         this node and the robots of `dashboard.robots` with their state,
//                            and (dashboard.mdns) those announcing _rcan._tcp, listed only,
//                            and (dashboard.mdns) those announcing _rcan._tcp, listed only
//   POST /api/robots/estop   {"robots":[url…] (default: every configured one), "reason"?}:
//                            POST /api/stop on each at once with the caller's own token;
//                            {"results":[{url, result, …}], "confirmed", "total", "ok"}
//
// Both need a token this node accepts, of any role (as POST /api/stop). A stop goes only to
// URLs of the configuration: a URL the request names that is not configured is refused before
// anything is sent, so a token never leaves for an address a caller chose. Each relay is
// recorded (ROBOTS_ESTOP, with every robot's result).
#include <algorithm>

#include "node/api/node.h"
#include "node/discovery/mdns.h"
#include "node/discovery/robot_directory.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

constexpr size_t kMaxReasonBytes = 256;

Error bad(const std::string& msg, const std::string& field) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field);
}

}  // namespace

void Node::set_robot_directory(RobotDirectory* robots) { robots_ = robots; }

void Node::add_robots_routes() {
  RouteTable& t = routes_;
  t.add("GET", "/api/robots", Body::kNone, [this](RouteCall& c) {
    auto pr = bearer_principal(c.req);
    if (!pr.ok()) return answer_error(c.respond, c.route, pr.error());
    json::Object self{{"name", svc_.settings.name},
                      {"ruri", svc_.settings.ruri},
                      {"model", svc_.settings.model},
                      {"version", svc_.settings.rcan_version},
                      {"status", status_word(svc_)}};
    json::Array robots = robots_ ? robots_->snapshot() : json::Array{};
    const auto configured = static_cast<int64_t>(robots.size());
    answer_json(c.respond, c.route, 200,
                json::Object{{"self", std::move(self)},
                             {"robots", std::move(robots)},
                             {"configured", configured},
                             {"discovered",
                              robots_ ? robots_->discovered(svc_.settings.ruri) : json::Array{}},
                             {"mdns", robots_ ? robots_->mdns_state() : std::string("off")}});
  });
  t.add("POST", "/api/robots/estop", Body::kObjectOrEmpty,
        [this](RouteCall& c) { robots_estop(c.req, c.respond, c.body, c.route); });
}

void Node::robots_estop(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                        const std::string& route) {
  auto pr = bearer_principal(req);
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (!robots_ || robots_->urls().empty())
    return answer_error(
        respond, route,
        bad("no robot to stop: dashboard.robots lists none; nothing was sent", "robots"));
  std::string reason = "dashboard robots view";
  if (const json::Value* r = body.is_object() ? body.get("reason") : nullptr; r && !r->is_null()) {
    if (!r->is_string() || r->as_string().empty() || r->as_string().size() > kMaxReasonBytes)
      return answer_error(respond, route, bad("reason: a string of 1-256 bytes", "reason"));
    reason = r->as_string();
  }
  std::vector<std::string> urls;
  const json::Value* list = body.is_object() ? body.get("robots") : nullptr;
  if (!list || list->is_null()) {
    urls = robots_->urls();
  } else {
    if (!list->is_array() || list->as_array().empty())
      return answer_error(respond, route,
                          bad("robots: a non-empty list of configured robot URLs", "robots"));
    for (const json::Value& u : list->as_array()) {
      if (!u.is_string() || !robots_->configured(u.as_string()))
        return answer_error(
            respond, route,
            bad("robots: " +
                    (u.is_string() ? "\"" + u.as_string().substr(0, 200) + "\"" : "an entry") +
                    " is not in dashboard.robots; nothing was sent",
                "robots"));
      if (std::find(urls.begin(), urls.end(), u.as_string()) == urls.end())
        urls.push_back(u.as_string());
    }
  }
  const std::string authorization(req.header("authorization"));
  bool posted = relay_worker_.post(
      [this, respond, route, p = *pr, urls, authorization, reason]() mutable {
        auto results = robots_->relay_stop(urls, authorization, reason);
        json::Array out;
        json::Object recorded;
        int64_t confirmed = 0;
        for (const auto& r : results) {
          json::Object o{{"url", r.url},
                         {"result", r.result},
                         {"http_status", static_cast<int64_t>(r.http_status)},
                         {"elapsed_ms", r.elapsed_ms}};
          if (!r.error_code.empty()) o.set("error_code", r.error_code);
          if (!r.detail.empty()) o.set("detail", r.detail);
          recorded.set(r.url, r.error_code.empty() ? r.result : r.result + " " + r.error_code);
          if (r.result == "confirmed") ++confirmed;
          out.emplace_back(std::move(o));
        }
        const bool all = confirmed == static_cast<int64_t>(results.size());
        svc_.trail.record("ROBOTS_ESTOP", all ? "ok" : "failed")
            .by(p)
            .reason(reason)
            .detail("route", route)
            .detail("robots", std::move(recorded))
            .write();
        answer_json(respond, route, 200,
                    json::Object{{"results", std::move(out)},
                                 {"confirmed", confirmed},
                                 {"total", static_cast<int64_t>(results.size())},
                                 {"ok", all}});
      },
      4);
  if (!posted)
    answer_error(respond, route, Error(ErrorCode::kSafeStop, "busy relaying stops; try again"));
}

}  // namespace rcan::node
