// rcan-registry's webhooks over real sockets (docs/REGISTRY.md "Webhooks"): the daemon as a
// child process, a receiver in this process (the project's HTTP server). Subscriptions and
// their validation, signed deliveries for created/updated/deleted records (the signature checked
// here with OpenSSL), retries with back-off, the failure cut-off, a webhook pointing at the
// registry itself and a receiver that never answers.
#include <gtest/gtest.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include <chrono>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "rcan/encoding.h"
#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"
#include "transport/http_server.h"

namespace rcan::test {
namespace {

using transport::HttpRequest;
using transport::HttpResponse;

json::Value body_of(const std::string& text) {
  auto v = json::parse(text);
  EXPECT_TRUE(v.ok()) << text;
  return v.ok() ? *v : json::Value(json::Object{});
}

std::string str(const json::Value& v, std::string_view key) {
  const json::Value* m = v.get(key);
  return m != nullptr && m->is_string() ? m->as_string() : std::string();
}

int64_t num(const json::Value& v, std::string_view key) {
  const json::Value* m = v.get(key);
  return m != nullptr && m->is_int() ? m->as_int() : -1;
}

std::string hmac_hex(const std::string& key, const std::string& data) {
  unsigned char out[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()),
       reinterpret_cast<const unsigned char*>(data.data()), data.size(), out, &len);
  return to_hex(Bytes(out, out + len));
}

template <class F>
bool wait_for(F cond, int ms) {
  auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
  while (std::chrono::steady_clock::now() < end) {
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return cond();
}

// The receiver: /ok answers 200, /flaky 500 twice then 200, /fail 500, /hang never answers.
class Receiver : public transport::HttpHandler {
 public:
  void handle(HttpRequest req, Respond respond) override {
    std::lock_guard<std::mutex> lock(mu);
    received.push_back(req);
    int n = ++calls[req.path];
    if (req.path == "/hang") {
      held.push_back(std::move(respond));
      return;
    }
    HttpResponse r;
    r.status = req.path == "/ok" || (req.path == "/flaky" && n > 2) ? 200 : 500;
    r.body = "{}";
    respond(r);
  }
  std::vector<HttpRequest> on(const std::string& path) {
    std::lock_guard<std::mutex> lock(mu);
    std::vector<HttpRequest> out;
    for (const auto& r : received)
      if (r.path == path) out.push_back(r);
    return out;
  }
  void release() {
    std::vector<Respond> h;
    {
      std::lock_guard<std::mutex> lock(mu);
      h.swap(held);
    }
    for (auto& r : h) r(HttpResponse{});
  }
  std::mutex mu;
  std::vector<HttpRequest> received;
  std::map<std::string, int> calls;
  std::vector<Respond> held;
};

class NoStreams : public transport::StreamHandler {
 public:
  std::unique_ptr<transport::StreamReceiver> open(const HttpRequest&,
                                                  std::shared_ptr<transport::StreamSink>,
                                                  HttpResponse& refusal) override {
    refusal.status = 404;
    return nullptr;
  }
};

class RegistryWebhooks : public ::testing::Test {
 protected:
  void SetUp() override {
    transport::ServerOptions so;
    so.port = 0;
    server_ = std::make_unique<transport::HttpServer>(so, receiver_, streams_);
    auto port = server_->start();
    ASSERT_TRUE(port.ok());
    base_ = "http://127.0.0.1:" + std::to_string(*port);
  }
  void TearDown() override {
    receiver_.release();
    server_->stop(500);
  }
  std::unique_ptr<RegistryDaemon> start(std::vector<std::string> extra = {}) {
    // The receiver is on loopback: a private address (tests/adversary/ops_seams_test.cpp shows
    // the refusal without the flag).
    extra.insert(extra.end(), {"--allow-http-node-urls", "--allow-private-webhooks",
                               "--webhook-backoff-ms", "50", "--webhook-timeout-ms", "300"});
    return std::make_unique<RegistryDaemon>(dir_.path(), extra);
  }
  static std::string subscription(const std::string& url, const std::string& secret,
                                  const std::string& prefix = "RRN") {
    json::Object o{{"node_prefix", prefix}, {"webhook_url", url}, {"secret", secret}};
    return json::dump(json::Value(std::move(o)));
  }
  static int64_t subscribe(RegistryDaemon& d, const std::string& url, const std::string& secret) {
    auto r = d.send("POST", "/api/v1/webhooks", subscription(url, secret), d.admin_key());
    EXPECT_EQ(r.status, 201) << r.body;
    return num(body_of(r.body), "id");
  }
  static std::string registrant(RegistryDaemon& d) {
    auto r = d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"t"})", d.admin_key());
    EXPECT_EQ(r.status, 201) << r.body;
    return str(body_of(r.body), "key");
  }
  static std::string register_robot(RegistryDaemon& d, const std::string& key,
                                    const std::string& device) {
    auto r = d.send(
        "POST", "/api/v1/robots",
        R"({"manufacturer":"Acme","model":"arm","version":"v2","device_id":")" + device + "\"}",
        key);
    EXPECT_EQ(r.status, 201) << r.body;
    return str(body_of(r.body), "rrn");
  }
  static json::Value hook(RegistryDaemon& d, int64_t id) {
    auto r = d.get("/api/v1/webhooks", d.admin_key());
    EXPECT_EQ(r.status, 200) << r.body;
    json::Value v = body_of(r.body);
    const json::Value* list = v.get("webhooks");
    if (list != nullptr && list->is_array())
      for (const auto& w : list->as_array())
        if (num(w, "id") == id) return w;
    return json::Value(json::Object{});
  }
  static double metric(RegistryDaemon& d, const std::string& name) {
    return metric_value(d.get("/metrics").body, name);
  }

  TempDir dir_;
  Receiver receiver_;
  NoStreams streams_;
  std::unique_ptr<transport::HttpServer> server_;
  std::string base_;
};

TEST_F(RegistryWebhooks, SubscriptionsNeedAdminHttpsAndASecretAndListWithoutSecrets) {
  TempDir dir;
  RegistryDaemon d(dir.path());  // no --allow-http-node-urls
  const std::string secret = "0123456789abcdef-secret";
  std::string key = registrant(d);
  auto body = subscription("https://hooks.example.com/rcan", secret);
  EXPECT_EQ(d.send("POST", "/api/v1/webhooks", body).status, 401);
  EXPECT_EQ(d.send("POST", "/api/v1/webhooks", body, key).status, 401);
  EXPECT_EQ(d.get("/api/v1/webhooks", key).status, 401);
  auto post = [&](const std::string& b) {
    return d.send("POST", "/api/v1/webhooks", b, d.admin_key());
  };
  EXPECT_EQ(post(subscription("http://hooks.example.com/rcan", secret)).status, 400);
  EXPECT_EQ(post(subscription("ftp://hooks.example.com/rcan", secret)).status, 400);
  EXPECT_EQ(post(subscription("https://hooks.example.com/rcan", "short")).status, 400);
  EXPECT_EQ(post(R"({"node_prefix":"RRN","webhook_url":"https://h.example.com/"})").status, 400);
  EXPECT_EQ(post(subscription("https://hooks.example.com/rcan", secret, "ZZ")).status, 422);
  EXPECT_EQ(post(subscription("https://hooks.example.com/rcan", secret, "bad prefix")).status, 400);
  EXPECT_EQ(post("not json").status, 400);
  // SQL metacharacters: whitespace in a URL is refused; the rest is stored as sent.
  EXPECT_EQ(post(subscription("https://h.example.com/?q=');DROP TABLE webhooks;--", secret)).status,
            400);
  const std::string odd_url = "https://h.example.com/?q=');DROP/**/TABLE/**/webhooks;--";
  const std::string odd_secret = "x'); DELETE FROM webhooks; --\"";
  auto r = post(subscription(odd_url, odd_secret));
  ASSERT_EQ(r.status, 201) << r.body;
  int64_t odd = num(body_of(r.body), "id");
  // The reference's alias.
  auto r2 = d.send("POST", "/api/v1/webhooks/register",
                   subscription("https://hooks.example.com/rcan", secret), d.admin_key());
  ASSERT_EQ(r2.status, 201) << r2.body;
  int64_t id = num(body_of(r2.body), "id");
  EXPECT_TRUE(body_of(r2.body).get("has_secret")->as_bool());

  auto list = d.get("/api/v1/webhooks", d.admin_key());
  ASSERT_EQ(list.status, 200);
  EXPECT_EQ(list.body.find(secret), std::string::npos);
  EXPECT_EQ(list.body.find("DELETE FROM"), std::string::npos);
  EXPECT_EQ(num(body_of(list.body), "count"), 2);
  EXPECT_EQ(str(hook(d, odd), "webhook_url"), odd_url);
  EXPECT_EQ(str(hook(d, id), "node_prefix"), "RRN");

  EXPECT_EQ(d.send("DELETE", "/api/v1/webhooks/" + std::to_string(id), "", key).status, 401);
  EXPECT_EQ(d.send("DELETE", "/api/v1/webhooks/abc", "", d.admin_key()).status, 400);
  EXPECT_EQ(d.send("DELETE", "/api/v1/webhooks/" + std::to_string(id), "", d.admin_key()).status,
            200);
  EXPECT_EQ(d.send("DELETE", "/api/v1/webhooks/" + std::to_string(id), "", d.admin_key()).status,
            404);
  EXPECT_EQ(num(body_of(d.get("/api/v1/webhooks", d.admin_key()).body), "count"), 1);
}

TEST_F(RegistryWebhooks, SignedDeliveriesForCreatedUpdatedAndDeletedRecords) {
  auto d = start();
  const std::string secret = "a-webhook-secret-of-32-bytes-xyz";
  int64_t id = subscribe(*d, base_ + "/ok", secret);
  std::string key = registrant(*d);
  std::string rrn = register_robot(*d, key, "unit-1");
  ASSERT_TRUE(wait_for([&] { return receiver_.on("/ok").size() >= 1; }, 10000));
  ASSERT_EQ(d->send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"moved"})", d->admin_key())
                .status,
            200);
  ASSERT_TRUE(wait_for([&] { return receiver_.on("/ok").size() >= 2; }, 10000));
  ASSERT_EQ(d->send("DELETE", "/api/v1/robots/" + rrn, "", key).status, 200);
  ASSERT_TRUE(wait_for([&] { return receiver_.on("/ok").size() >= 3; }, 10000));

  auto got = receiver_.on("/ok");
  ASSERT_EQ(got.size(), 3u);
  const char* events[] = {"record.created", "record.updated", "record.deleted"};
  int64_t now_s = std::chrono::duration_cast<std::chrono::seconds>(
                      std::chrono::system_clock::now().time_since_epoch())
                      .count();
  std::set<std::string> ids;
  for (size_t i = 0; i < got.size(); ++i) {
    const HttpRequest& q = got[i];
    EXPECT_EQ(q.method, "POST");
    EXPECT_EQ(q.header("content-type"), "application/json");
    EXPECT_EQ(q.header("x-rcan-delivery"), "webhook/1.0");
    std::string ts(q.header("x-rcan-timestamp"));
    ASSERT_FALSE(ts.empty());
    EXPECT_LE(std::llabs(std::stoll(ts) - now_s), 60);
    EXPECT_EQ(std::string(q.header("x-rcan-signature")),
              "sha256=" + hmac_hex(secret, ts + "." + q.body));
    EXPECT_NE(std::string(q.header("x-rcan-signature")),
              "sha256=" + hmac_hex("another-secret-0000", ts + "." + q.body));
    json::Value ev = body_of(q.body);
    EXPECT_EQ(str(ev, "event"), events[i]);
    EXPECT_EQ(str(ev, "rrn"), rrn);
    EXPECT_EQ(str(*ev.get("record"), "rrn"), rrn);
    EXPECT_FALSE(str(ev, "timestamp").empty());
    EXPECT_EQ(str(ev, "delivery_id"), std::string(q.header("x-rcan-delivery-id")));
    ids.insert(str(ev, "delivery_id"));
  }
  EXPECT_EQ(ids.size(), 3u);
  json::Value updated = body_of(got[1].body);
  EXPECT_EQ(str(*updated.get("record"), "description"), "moved");
  // A deletion tells the tombstone only (as GET /api/v1/sync): none of the robot's content.
  const json::Value deleted = body_of(got[2].body);
  const json::Value* gone = deleted.get("record");
  ASSERT_NE(gone, nullptr);
  const json::Value* flag = gone->get("deleted");
  EXPECT_TRUE(flag != nullptr && flag->is_bool() && flag->as_bool()) << got[2].body;
  EXPECT_EQ(gone->get("description"), nullptr) << got[2].body;
  json::Value h = hook(*d, id);
  EXPECT_EQ(num(h, "failure_count"), 0);
  EXPECT_FALSE(str(h, "last_delivered_at").empty());
  EXPECT_EQ(metric(*d, "rcan_registry_webhook_deliveries_total"), 3);
}

TEST_F(RegistryWebhooks, RetriesWithBackoffUntilTheReceiverTakesIt) {
  auto d = start();
  const std::string secret = "retry-secret-0123456789";
  int64_t id = subscribe(*d, base_ + "/flaky", secret);
  register_robot(*d, registrant(*d), "unit-2");
  ASSERT_TRUE(wait_for([&] { return receiver_.on("/flaky").size() >= 3; }, 10000));
  ASSERT_TRUE(
      wait_for([&] { return metric(*d, "rcan_registry_webhook_deliveries_total") == 1; }, 5000));
  auto got = receiver_.on("/flaky");
  ASSERT_EQ(got.size(), 3u);
  for (const auto& q : got) {
    EXPECT_EQ(q.header("x-rcan-delivery-id"), got[0].header("x-rcan-delivery-id"));
    EXPECT_EQ(q.body, got[0].body);
    std::string ts(q.header("x-rcan-timestamp"));
    EXPECT_EQ(std::string(q.header("x-rcan-signature")),
              "sha256=" + hmac_hex(secret, ts + "." + q.body));
  }
  EXPECT_EQ(metric(*d, "rcan_registry_webhook_failed_attempts_total"), 2);
  EXPECT_EQ(metric(*d, "rcan_registry_webhook_failures_total"), 0);
  EXPECT_EQ(num(hook(*d, id), "failure_count"), 0);
}

// A webhook pointing at the registry's own API (the delivery carries no credentials: 401, no
// record is made, no loop) and one that never answers are retried, counted as failed and
// switched off after 5 failed deliveries; the API answers at once meanwhile and a healthy
// subscription keeps receiving.
TEST_F(RegistryWebhooks, SelfLoopAndDeadReceiverAreCutOffWithoutDelayingTheApi) {
  auto d = start();
  const std::string secret = "cut-off-secret-0123456789";
  int64_t self = subscribe(*d, d->url() + "/api/v1/robots", secret);
  int64_t hang = subscribe(*d, base_ + "/hang", secret);
  subscribe(*d, base_ + "/ok", secret);
  std::string key = registrant(*d);
  for (int i = 0; i < 5; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    register_robot(*d, key, "loop-" + std::to_string(i));
    auto ms =
        std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0)
            .count();
    EXPECT_LT(ms, 1000) << "registration " << i << " waited on deliveries";
  }
  ASSERT_TRUE(wait_for(
      [&] {
        return num(hook(*d, self), "failure_count") >= 5 &&
               num(hook(*d, hang), "failure_count") >= 5;
      },
      60000));
  size_t hang_calls = receiver_.on("/hang").size();
  EXPECT_EQ(hang_calls, 25u);  // 5 deliveries × 5 attempts
  double skipped = metric(*d, "rcan_registry_webhook_skipped_total");
  register_robot(*d, key, "after-cut-off");
  ASSERT_TRUE(wait_for([&] { return receiver_.on("/ok").size() >= 6; }, 10000));
  ASSERT_TRUE(wait_for(
      [&] { return metric(*d, "rcan_registry_webhook_skipped_total") >= skipped + 2; }, 5000));
  EXPECT_EQ(receiver_.on("/hang").size(), hang_calls);
  EXPECT_EQ(num(hook(*d, self), "failure_count"), 5);
  // The deliveries to the registry itself made no robots.
  EXPECT_EQ(num(body_of(d->get("/api/v1/robots").body), "total"), 6);
  EXPECT_EQ(metric(*d, "rcan_registry_webhook_failures_total"), 10);
  EXPECT_EQ(metric(*d, "rcan_registry_webhook_dropped_total"), 0);
}

}  // namespace
}  // namespace rcan::test
