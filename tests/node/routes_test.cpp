// The HTTP route table in-process: RouteTable's refusals and the node's own table (routes.cpp)
// answered through Node::handle, what every HTTP transport calls, without sockets. The pattern
// matching itself is tested with transport's Router (tests/transport/router_test.cpp).
#include <gtest/gtest.h>

#include <future>
#include <set>

#include "in_process_node.h"
#include "node/api/node.h"

namespace rcan::node {
namespace {

using transport::HttpRequest;
using transport::HttpResponse;

std::string header(const HttpResponse& r, const std::string& name) {
  for (const auto& [k, v] : r.headers)
    if (k == name) return v;
  return {};
}

std::string http_error_code(const HttpResponse& r) {
  auto v = json::parse(r.body);
  if (!v.ok()) return {};
  const json::Value* p = v->get("payload");
  return p ? json::string_field(*p, "error_code") : std::string();
}

class RoutesTest : public test_node::InProcessNode {
 protected:
  void SetUp() override {
    InProcessNode::SetUp();
    node_ = std::make_unique<Node>(*services_);
  }
  void TearDown() override {
    node_.reset();
    InProcessNode::TearDown();
  }
  HttpResponse call(const std::string& method, const std::string& path,
                    const std::string& body = "", const std::string& bearer = "") {
    HttpRequest req;
    req.method = method;
    req.target = path;
    req.path = path.substr(0, path.find('?'));
    if (size_t q = path.find('?'); q != std::string::npos) {  // name=value&… (test paths only)
      std::string rest = path.substr(q + 1);
      for (size_t at = 0; at <= rest.size();) {
        size_t amp = std::min(rest.find('&', at), rest.size());
        std::string kv = rest.substr(at, amp - at);
        size_t eq = kv.find('=');
        req.query.emplace_back(kv.substr(0, eq), eq == std::string::npos ? "" : kv.substr(eq + 1));
        at = amp + 1;
      }
    }
    req.body = body;
    if (!bearer.empty()) req.headers.emplace_back("authorization", "Bearer " + bearer);
    return answer(node_.get(), std::move(req));
  }
  static HttpResponse answer(transport::HttpHandler* h, HttpRequest req) {
    auto got = std::make_shared<std::promise<HttpResponse>>();
    auto fut = got->get_future();
    h->handle(std::move(req), [got](HttpResponse r) { got->set_value(std::move(r)); });
    if (fut.wait_for(std::chrono::seconds(10)) != std::future_status::ready) {
      ADD_FAILURE() << "no answer within 10 s";
      return HttpResponse{};
    }
    return fut.get();
  }
  std::unique_ptr<Node> node_;
};

TEST_F(RoutesTest, UnknownPathsAre404UnderOneMetricsLabel) {
  for (const char* p : {"/nope", "/rcan/v1/leasesX", "/rcan/v1/consent/x/steal", "/api"}) {
    HttpResponse r = call("GET", p);
    EXPECT_EQ(r.status, 404) << p;
    EXPECT_EQ(http_error_code(r), "NOT_FOUND") << p;
  }
  std::string metrics = call("GET", "/metrics").body;
  EXPECT_NE(metrics.find("route=\"other\""), std::string::npos) << metrics;
  EXPECT_EQ(metrics.find("leasesX"), std::string::npos);
}

TEST_F(RoutesTest, AWrongMethodIs405WithEveryMethodThePathServes) {
  struct Case {
    const char* method;
    const char* path;
    const char* allow;
  };
  for (const Case& c : std::vector<Case>{
           {"POST", "/healthz", "GET, HEAD"},
           {"GET", "/rcan/v1/command", "POST"},
           {"PUT", "/rcan/v1/leases", "GET, POST"},
           {"GET", "/rcan/v1/leases/L-1", "DELETE"},
           {"GET", "/rcan/v1/auth/release", "DELETE, POST"},
           {"PATCH", "/rcan/v1/auth/queue", "GET, DELETE"},
           {"GET", "/rcan/v1/consent/C-1/grant", "POST"},
           {"DELETE", "/rcan/v1/transfer", "GET, POST"},
           {"POST", "/rcan/v1/pending", "GET"},
           {"DELETE", "/", "GET, HEAD"},
           {"POST", "/ui/js/main.js", "GET, HEAD"},
       }) {
    HttpResponse r = call(c.method, c.path, "{}");
    EXPECT_EQ(r.status, 405) << c.method << " " << c.path;
    EXPECT_EQ(http_error_code(r), "METHOD_NOT_ALLOWED") << c.method << " " << c.path;
    EXPECT_EQ(header(r, "Allow"), c.allow) << c.method << " " << c.path;
  }
}

TEST_F(RoutesTest, BodiesAreReadByTheRowsRule) {
  const std::string owner = token("owner", "alice");
  // A required JSON body.
  EXPECT_EQ(http_error_code(call("POST", "/rcan/v1/command", "", owner)), "MALFORMED_JSON");
  EXPECT_EQ(http_error_code(call("POST", "/rcan/v1/command", "{nope", owner)), "MALFORMED_JSON");
  // An object or nothing.
  HttpResponse arr = call("POST", "/rcan/v1/auth/claim", "[1,2]", owner);
  EXPECT_EQ(arr.status, 400);
  EXPECT_EQ(http_error_code(arr), "SCHEMA_VALIDATION_FAILED");
  EXPECT_EQ(call("POST", "/rcan/v1/auth/claim", "", owner).status, 200)
      << "an empty body reads as {}";
  // Nesting beyond the control routes' depth.
  std::string deep(20, '[');
  deep = "{\"a\":" + deep + std::string(20, ']') + "}";
  EXPECT_EQ(call("POST", "/rcan/v1/auth/renew", deep, owner).status, 400);
  // Optional JSON: a bare stop.
  EXPECT_EQ(call("POST", "/api/stop", "", owner).status, 200);
  EXPECT_EQ(act_.estops(), 1u);
}

TEST_F(RoutesTest, MetricsLabelsComeFromTheTableNotFromThePath) {
  const std::string owner = token("owner", "alice");
  for (int i = 0; i < 20; ++i) {
    std::string id = "lease-" + std::to_string(i);
    call("POST", "/rcan/v1/leases/" + id + "/grants", "{bad json", owner);
    call("DELETE", "/rcan/v1/leases/" + id, "", owner);
    call("POST", "/rcan/v1/consent/" + id + "/grant", "[", owner);
  }
  std::string metrics = call("GET", "/metrics").body;
  EXPECT_EQ(metrics.find("lease-1"), std::string::npos) << "a path segment became a label";
  EXPECT_NE(metrics.find("/rcan/v1/leases/{id}/grants"), std::string::npos) << metrics;
}

TEST_F(RoutesTest, ParametersReachTheirHandlers) {
  const std::string owner = token("owner", "alice");
  HttpResponse revoke = call("DELETE", "/rcan/v1/leases/no-such-lease", "", owner);
  EXPECT_EQ(revoke.status, 404);
  EXPECT_NE(revoke.body.find("no-such-lease"), std::string::npos) << revoke.body;
  HttpResponse thought = call("GET", "/api/thoughts/t-1", "", owner);
  EXPECT_EQ(thought.status, 404);
  EXPECT_NE(thought.body.find("AI accountability is not enabled"), std::string::npos)
      << thought.body;
}

TEST_F(RoutesTest, EveryRowAnswersAndNoneIsShadowed) {
  // One request per documented route: none may fall through to "no route".
  const std::string owner = token("owner", "alice");
  for (const auto& [method, path] : std::vector<std::pair<std::string, std::string>>{
           {"GET", "/healthz"},
           {"HEAD", "/healthz"},
           {"GET", "/metrics"},
           {"POST", "/rcan/v1/discover"},
           {"GET", "/api/discovery"},
           {"GET", "/rcan/v1/status"},
           {"GET", "/api/status"},
           {"GET", "/rcan/v1/auth/queue"},
           {"GET", "/rcan/v1/leases"},
           {"GET", "/rcan/v1/transfer"},
           {"GET", "/rcan/v1/consent"},
           {"GET", "/api/audit"},
           {"GET", "/"},
           {"GET", "/ui/"},
           {"GET", "/favicon.ico"},
       }) {
    HttpResponse r = call(method, path, "", owner);
    EXPECT_TRUE(r.status == 200 || r.status == 304)
        << method << " " << path << " " << r.status << " " << r.body.substr(0, 200);
  }
}

// The audit log names every principal and carries their §16 blocks: reading it (the listing and
// the export) needs OWNER — the export also scope config — and every read, allowed or refused,
// leaves a record of its own (AUDIT_READ, with the query).
TEST_F(RoutesTest, TheAuditLogIsTheOwnersToReadAndEveryReadIsRecorded) {
  ASSERT_EQ(call("POST", "/api/command", json::dump(command("move")), token("user", "bob")).status,
            200);
  const std::vector<std::pair<std::string, std::string>> others{
      {"guest", "gus"}, {"user", "bob"}, {"leasee", "lee"}};
  for (const auto& [role, sub] : others) {
    SCOPED_TRACE(role);
    const std::string t = token(role.c_str(), sub.c_str(), {"status", "chat", "control"});
    for (const char* path : {"/api/audit", "/api/audit?limit=1000", "/api/v1/audit?format=jsonl"}) {
      HttpResponse r = call("GET", path, "", t);
      EXPECT_EQ(r.status, 403) << path << " " << r.body;
      auto body = json::parse(r.body);
      ASSERT_TRUE(body.ok()) << r.body;
      EXPECT_EQ(json::string_field(*body, "type"), "ERROR") << r.body;  // the profile's body
      EXPECT_EQ(http_error_code(r), "INSUFFICIENT_PRIVILEGES") << r.body;
      EXPECT_EQ(r.body.find("\"entries\""), std::string::npos);
    }
  }
  // OWNER reads the listing; the export needs scope config besides.
  HttpResponse listing = call("GET", "/api/audit?limit=7", "", token("owner", "alice", {"status"}));
  ASSERT_EQ(listing.status, 200) << listing.body;
  EXPECT_EQ(
      call("GET", "/api/v1/audit?format=jsonl", "", token("owner", "alice", {"status"})).status,
      403);
  HttpResponse exported =
      call("GET", "/api/v1/audit?from=0&format=jsonl", "", token("owner", "alice", {"config"}));
  ASSERT_EQ(exported.status, 200) << exported.body.substr(0, 300);

  // The listing already shows its own read: the record is durable before the log is read.
  auto v = json::parse(listing.body);
  ASSERT_TRUE(v.ok());
  const auto& entries = v->get("entries")->as_array();
  ASSERT_FALSE(entries.empty());
  EXPECT_EQ(json::string_field(entries.back(), "event"), "AUDIT_READ");
  EXPECT_EQ(json::string_field(entries.back(), "sub"), "alice");

  // 3 roles × 3 refusals, the OWNER's export without config, the listing and the export.
  std::vector<json::Value> reads = audited("AUDIT_READ", 12);
  ASSERT_EQ(reads.size(), 12u);
  size_t blocked = 0;
  std::set<std::string> refused;
  for (const auto& r : reads) {
    const json::Value* d = r.get("detail");
    ASSERT_NE(d, nullptr) << json::dump(r);
    if (json::string_field(r, "outcome") == "blocked") {
      ++blocked;
      refused.insert(json::string_field(r, "sub"));
      EXPECT_EQ(json::string_field(r, "reason"), "INSUFFICIENT_PRIVILEGES");
      continue;
    }
    EXPECT_EQ(json::string_field(r, "sub"), "alice");
    const std::string route = json::string_field(*d, "route");
    const json::Value* q = d->get("query");
    ASSERT_NE(q, nullptr) << json::dump(r);
    if (route == "/api/audit") {
      EXPECT_EQ(q->get("limit")->as_int(), 7);
    } else {
      EXPECT_EQ(route, "/api/v1/audit");
      EXPECT_EQ(json::string_field(*q, "format"), "jsonl");
      EXPECT_EQ(q->get("from")->as_int(), 0);
    }
  }
  EXPECT_EQ(blocked, 10u);
  EXPECT_EQ(refused, (std::set<std::string>{"gus", "bob", "lee", "alice"}));
}

}  // namespace
}  // namespace rcan::node
