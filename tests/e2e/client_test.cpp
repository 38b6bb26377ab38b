// rcan::client against a real rcand (status, claim/release/handoff, commands, ESTOP/RESUME,
// audit, the WebSocket stream) and against an in-process fake node for the §16 endpoints,
// the watermark verify endpoint, stream reconnects and TLS. Pure parts: URLs, TXT records,
// error bodies, backoff.
#include "rcan/client.h"

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <thread>

#include "client/wire.h"
#include "fake_node.h"
#include "rcan/audit/secret.h"
#include "rcan/audit/verify.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

using client::Client;
using client::ClientOptions;

std::string trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

class ClientNodeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir();
    daemon_ = new test::RcandDaemon(dir_->path() + "/node");
  }
  static void TearDownTestSuite() {
    delete daemon_;
    delete dir_;
  }
  ClientOptions opts(const std::string& token = "") const {
    ClientOptions o;
    o.url = daemon_->url();
    o.token = token.empty() ? trimmed(test::read_file(daemon_->owner_token_file())) : token;
    return o;
  }
  static test::TempDir* dir_;
  static test::RcandDaemon* daemon_;
};
test::TempDir* ClientNodeTest::dir_ = nullptr;
test::RcandDaemon* ClientNodeTest::daemon_ = nullptr;

TEST_F(ClientNodeTest, StatusIsTypedAndDetailedWithAToken) {
  ClientOptions anon = opts();
  anon.token.clear();
  auto s = Client(anon).status();
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->ruri, daemon_->ruri());
  EXPECT_EQ(s->rcan_version, "1.0.0");
  EXPECT_FALSE(s->robot.is_object());  // anonymous: public summary only
  auto d = Client(opts()).status();
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->robot.is_object());
  EXPECT_FALSE(d->rrn.empty());
  EXPECT_NE(std::find(d->extensions.begin(), d->extensions.end(), "16.6-watermark"),
            d->extensions.end());
}

TEST_F(ClientNodeTest, ErrorsCarryTheProfileCodeAndHttpStatus) {
  auto bad = Client(opts("not-a-jwt")).claim();
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, "AUTH_INVALID");
  EXPECT_EQ(bad.error().http_status, 401);
  EXPECT_EQ(bad.error().known(), ErrorCode::kAuthInvalid);
  EXPECT_TRUE(bad.error().body.is_object());

  std::string guest = daemon_->token("guest", {"status", "chat"}, "guest-1");
  auto g = Client(opts(guest)).claim();
  ASSERT_FALSE(g.ok());
  EXPECT_EQ(g.error().code, "INSUFFICIENT_PRIVILEGES");
  EXPECT_EQ(g.error().http_status, 403);

  ClientOptions nowhere = opts();
  nowhere.url = "http://127.0.0.1:1";
  auto n = Client(nowhere).status();
  ASSERT_FALSE(n.ok());
  EXPECT_EQ(n.error().code, "CONNECTION_FAILED");
  EXPECT_TRUE(n.error().unreachable());
}

TEST_F(ClientNodeTest, ClaimCommandReleaseAndConflict) {
  std::string user_a = daemon_->token("user", {"status", "control"}, "alice");
  std::string user_b = daemon_->token("user", {"status", "control"}, "bob");
  Client a(opts(user_a)), b(opts(user_b));
  auto g = a.claim();
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_FALSE(g->session_id.empty());
  EXPECT_EQ(g->role, "USER");
  EXPECT_GT(g->heartbeat_timeout_ms, 0);
  auto conflict = b.claim();
  ASSERT_FALSE(conflict.ok());
  EXPECT_EQ(conflict.error().code, "CONTROL_CONFLICT");
  EXPECT_EQ(conflict.error().http_status, 409);

  client::Command move;
  move.action = "move";
  move.params.set("linear", 0.2);
  move.params.set("duration_ms", 200);
  auto r = a.command(move);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->type, "ACK");
  auto other = b.command(move);
  ASSERT_FALSE(other.ok());
  EXPECT_EQ(other.error().code, "CONTROL_CONFLICT");

  auto rel = a.release();
  ASSERT_TRUE(rel.ok()) << rel.error().message;
  EXPECT_EQ(rel->type, "RELEASED");
  auto again = a.release();
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().http_status, 400);
  // b queued behind a and a's release promoted it: it lets go, so that the suite's next test
  // (same rcand) finds the robot free.
  auto promoted = b.release();
  EXPECT_TRUE(promoted.ok()) << promoted.error().message;
}

TEST_F(ClientNodeTest, HandoffReservesTheRobotForItsTarget) {
  std::string carol = daemon_->token("user", {"status", "control"}, "carol");
  std::string dave = daemon_->token("user", {"status", "control"}, "dave");
  Client c(opts(carol));
  auto g = c.claim();
  ASSERT_TRUE(g.ok()) << g.error().message;
  auto h = c.handoff(g->session_id, "dave", "USER", "shift change");
  ASSERT_TRUE(h.ok()) << h.error().message;
  EXPECT_EQ(h->type, "AVAILABLE");
  auto d = Client(opts(dave)).claim();
  ASSERT_TRUE(d.ok()) << d.error().message;
  EXPECT_TRUE(Client(opts(dave)).release(d->session_id).ok());
}

TEST_F(ClientNodeTest, EstopRefusesMotionUntilResume) {
  Client c(opts());
  auto e = c.estop("client test");
  ASSERT_TRUE(e.ok()) << e.error().message;
  auto st = c.status();
  ASSERT_TRUE(st.ok());
  EXPECT_TRUE(st->estop_active);
  auto disc = json::parse(test::http(daemon_->port(), "GET", "/api/discovery").body);
  ASSERT_TRUE(disc.ok());
  EXPECT_EQ(disc->get("txt_record")->get("status")->as_string(), "estop");  // as in the mDNS TXT
  client::Command move;
  move.action = "move";
  move.params.set("linear", 0.1);
  auto refused = c.command(move);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, "COMMAND_REJECTED");
  EXPECT_EQ(refused.error().reason, "estop_active");
  EXPECT_EQ(refused.error().http_status, 423);
  std::string user = daemon_->token("user", {"status", "control"}, "eve");
  auto weak = Client(opts(user)).resume();
  ASSERT_FALSE(weak.ok());
  EXPECT_EQ(weak.error().code, "INSUFFICIENT_PRIVILEGES");
  auto ok = c.resume();
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_FALSE(c.status()->estop_active);
  disc = json::parse(test::http(daemon_->port(), "GET", "/api/discovery").body);
  ASSERT_TRUE(disc.ok());
  EXPECT_EQ(disc->get("txt_record")->get("status")->as_string(), "available");
}

TEST_F(ClientNodeTest, AuditRecentAndExportVerifyOffline) {
  Client c(opts());
  auto page = c.audit_recent(5);
  ASSERT_TRUE(page.ok()) << page.error().message;
  ASSERT_FALSE(page->entries.empty());
  EXPECT_LE(page->entries.size(), 5u);
  EXPECT_GT(page->last_seq, 0);
  auto text = c.audit_export();
  ASSERT_TRUE(text.ok()) << text.error().message;
  auto secret = audit::load_chain_secret(daemon_->dir() + "/audit.secret");
  ASSERT_TRUE(secret.ok());
  audit::VerifyOptions vo;
  auto rep = audit::verify_jsonl(std::string_view(*text), *secret, vo);
  EXPECT_TRUE(rep.ok) << rep.why;
  EXPECT_GT(rep.count, 0u);
  std::string user = daemon_->token("user", {"status", "control"}, "frank");
  auto denied = Client(opts(user)).audit_export();
  ASSERT_FALSE(denied.ok());
  EXPECT_EQ(denied.error().code, "INSUFFICIENT_PRIVILEGES");
}

TEST_F(ClientNodeTest, StreamDeliversAckEventsAndTelemetryAndCommandAnswers) {
  std::mutex mu;
  std::condition_variable cv;
  std::vector<json::Value> frames;
  client::StreamOptions so;
  so.client = opts();
  so.telemetry_hz = 20;
  so.max_attempts = 1;
  so.on_message = [&](const json::Value& v) {
    std::lock_guard<std::mutex> lock(mu);
    frames.push_back(v);
    cv.notify_all();
  };
  client::Stream s(so);
  std::thread t([&] { (void)s.run(); });
  auto count_type = [&](const std::string& type, const std::string& key = "",
                        const std::string& val = "") {
    size_t n = 0;
    for (const auto& f : frames) {
      const json::Value* ty = f.get("type");
      if (!ty || !ty->is_string() || ty->as_string() != type) continue;
      if (!key.empty()) {
        const json::Value* k = f.get(key);
        if (!k || !k->is_string() || k->as_string() != val) continue;
      }
      ++n;
    }
    return n;
  };
  {
    std::unique_lock<std::mutex> lock(mu);
    ASSERT_TRUE(
        cv.wait_for(lock, std::chrono::seconds(10), [&] { return count_type("STREAM") >= 2; }));
    EXPECT_EQ(count_type("CONNECT_ACK"), 1u);
  }
  EXPECT_TRUE(s.connected());
  EXPECT_FALSE(s.session_id().empty());
  client::Command chat;
  chat.action = "chat";
  chat.params.set("text", "hello");
  std::string id = s.send_command(chat);
  {
    std::unique_lock<std::mutex> lock(mu);
    EXPECT_TRUE(cv.wait_for(lock, std::chrono::seconds(10),
                            [&] { return count_type("ACK", "reply_to", id) == 1; }));
  }
  ASSERT_TRUE(Client(opts()).estop("stream test").ok());
  {
    std::unique_lock<std::mutex> lock(mu);
    EXPECT_TRUE(cv.wait_for(lock, std::chrono::seconds(10), [&] {
      for (const auto& f : frames)
        if (json::dump(f).find("ESTOP") != std::string::npos &&
            f.get("type")->as_string() != "STREAM")
          return true;
      return false;
    }));
  }
  ASSERT_TRUE(Client(opts()).resume().ok());
  s.stop();
  t.join();
}

// ---- the fake node: §16 endpoints, watermark verify, stream reconnects -------------------

TEST(ClientFakeNode, PendingAndAuthorizeFollowTheProfileContract) {
  test::FakeNode fake;
  ASSERT_NE(fake.port(), 0);
  ClientOptions o;
  o.url = fake.url();
  o.token = test::FakeNode::kGoodToken;
  Client c(o);
  auto p = c.pending();
  ASSERT_TRUE(p.ok()) << p.error().message;
  ASSERT_EQ(p->size(), 1u);
  EXPECT_EQ((*p)[0].message_id, "7f1c2a9e-0000-4000-8000-000000000001");
  EXPECT_EQ((*p)[0].action_type, "arm_move");
  EXPECT_EQ((*p)[0].auth_timeout_ms, 30000);
  auto a = c.authorize((*p)[0].message_id, false, "too close to a person");
  ASSERT_TRUE(a.ok()) << a.error().message;
  EXPECT_EQ(a->type, "ACK");
  {
    std::lock_guard<std::mutex> lock(fake.mu);
    ASSERT_EQ(fake.authorizations.size(), 1u);
    const json::Value& m = fake.authorizations[0];
    EXPECT_EQ(m.get("type")->as_string(), "AUTHORIZE");
    EXPECT_EQ(m.get("payload")->get("decision")->as_string(), "deny");
    EXPECT_EQ(m.get("payload")->get("reason")->as_string(), "too close to a person");
    EXPECT_TRUE(is_uuid(m.get("message_id")->as_string()));
  }
  auto unknown = c.authorize("no-such-id", true);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().code, "NOT_FOUND");
  EXPECT_EQ(unknown.error().http_status, 404);
  o.token.clear();
  auto anon = Client(o).pending();
  ASSERT_FALSE(anon.ok());
  EXPECT_EQ(anon.error().code, "AUTH_REQUIRED");
}

TEST(ClientFakeNode, ThoughtLookupShowsReasoningOnlyWithConfigScope) {
  test::FakeNode fake;
  ClientOptions o;
  o.url = fake.url();
  o.token = test::FakeNode::kGoodToken;
  auto t = Client(o).thought("th_42");
  ASSERT_TRUE(t.ok()) << t.error().message;
  EXPECT_EQ(t->id, "th_42");
  EXPECT_EQ(t->layer, "planner");
  ASSERT_TRUE(t->confidence.has_value());
  EXPECT_DOUBLE_EQ(*t->confidence, 0.87);
  EXPECT_FALSE(t->reasoning.has_value());
  o.token = test::FakeNode::kConfigToken;
  auto full = Client(o).thought("th_42");
  ASSERT_TRUE(full.ok());
  ASSERT_TRUE(full->reasoning.has_value());
  auto missing = Client(o).thought("th_nope/../x");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, "NOT_FOUND");
}

TEST(ClientFakeNode, WatermarkVerifyReadsTheSeedShapes) {
  test::FakeNode fake;
  ClientOptions o;
  o.url = fake.url();
  Client c(o);
  auto ok = c.watermark_verify(test::FakeNode::kWatermark, "RRN-000000000001");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_TRUE(ok->valid);
  EXPECT_EQ(ok->rrn, "RRN-000000000001");
  EXPECT_TRUE(ok->audit_entry.is_object());
  auto missing = c.watermark_verify("rcan-wm-v1:ffffffffffffffffffffffffffffffff");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, "HTTP_404");
  EXPECT_EQ(missing.error().message, "Watermark token not found in audit log");
  auto malformed = c.watermark_verify("rcan-wm-v1:XYZ&rrn=evil");
  ASSERT_FALSE(malformed.ok());
  EXPECT_EQ(malformed.error().code, "HTTP_400");
}

TEST(ClientFakeNode, StreamReconnectsWithBackoffAfterTheNodeDropsIt) {
  test::FakeNode fake;
  fake.drop_streams_after_ack = 1;
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::string> states;
  std::vector<std::string> events;
  client::StreamOptions so;
  so.client.url = fake.url();
  so.client.token = test::FakeNode::kGoodToken;
  so.on_state = [&](const std::string& s) {
    std::lock_guard<std::mutex> lock(mu);
    states.push_back(s);
    cv.notify_all();
  };
  so.on_message = [&](const json::Value& v) {
    std::lock_guard<std::mutex> lock(mu);
    if (const json::Value* e = v.get("event")) events.push_back(e->as_string());
    cv.notify_all();
  };
  client::Stream s(so);
  std::thread t([&] { (void)s.run(); });
  {
    std::unique_lock<std::mutex> lock(mu);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(15), [&] { return !events.empty(); }));
  }
  // Queued while connected: goes out on the live connection.
  client::Command c;
  c.action = "status";
  std::string id = s.send_command(c);
  for (int i = 0; i < 200; ++i) {
    {
      std::lock_guard<std::mutex> lock(fake.mu);
      if (!fake.stream_frames.empty()) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  s.stop();
  t.join();
  EXPECT_EQ(fake.stream_connects.load(), 2);
  std::lock_guard<std::mutex> lock(mu);
  // connecting, connected, disconnected, retrying in ~1 s, connecting, connected, stopped.
  int retry_ms = -1;
  for (const auto& st : states)
    if (st.rfind("retrying in ", 0) == 0) retry_ms = std::stoi(st.substr(12));
  EXPECT_GE(retry_ms, 500);
  EXPECT_LE(retry_ms, 1500);
  EXPECT_EQ(std::count(states.begin(), states.end(), "connected"), 2);
  EXPECT_EQ(states.back(), "stopped");
  std::lock_guard<std::mutex> lock2(fake.mu);
  ASSERT_FALSE(fake.stream_frames.empty());
  EXPECT_NE(fake.stream_frames[0].find(id), std::string::npos);
}

TEST(ClientFakeNode, RefusedConnectIsNotRetried) {
  test::FakeNode fake;
  std::vector<std::string> states;
  client::StreamOptions so;
  so.client.url = fake.url();
  so.client.token = "wrong";
  so.on_state = [&](const std::string& s) { states.push_back(s); };
  client::Stream s(so);
  client::ClientError e = s.run();
  EXPECT_EQ(e.code, "ConnectionRefused");
  ASSERT_FALSE(states.empty());
  EXPECT_EQ(states.back().rfind("refused", 0), 0u) << states.back();
  EXPECT_EQ(fake.stream_connects.load(), 0);
}

TEST(ClientFakeNode, UnreachableStreamGivesUpAfterMaxAttempts) {
  client::StreamOptions so;
  so.client.url = "http://127.0.0.1:1";
  so.client.token = "x";
  so.max_attempts = 1;
  client::Stream s(so);
  client::ClientError e = s.run();
  EXPECT_EQ(e.code, "CONNECTION_FAILED");
}

TEST(ClientTls, HttpsAndWssVerifyTheCertificate) {
  test::TempDir dir;
  const std::string cert = dir.file("cert.pem"), key = dir.file("key.pem");
  auto gen =
      test::run({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                 "ec_paramgen_curve:prime256v1", "-nodes", "-days", "1", "-subj", "/CN=127.0.0.1",
                 "-addext", "subjectAltName=IP:127.0.0.1", "-keyout", key, "-out", cert});
  ASSERT_EQ(gen.exit_code, 0) << gen.err;
  test::FakeNode fake(true, cert, key);
  ASSERT_NE(fake.port(), 0);
  ClientOptions o;
  o.url = fake.url();
  ASSERT_EQ(o.url.rfind("https://", 0), 0u);
  auto untrusted = Client(o).status();
  ASSERT_FALSE(untrusted.ok());
  EXPECT_EQ(untrusted.error().code, "TLS_FAILED");
  o.ca_file = cert;
  auto trusted = Client(o).status();
  ASSERT_TRUE(trusted.ok()) << trusted.error().message;
  EXPECT_EQ(trusted->name, "fake");
  ClientOptions ins;
  ins.url = fake.url();
  ins.insecure = true;
  EXPECT_TRUE(Client(ins).status().ok());
  // wss: CONNECT over TLS.
  client::StreamOptions so;
  so.client = o;
  so.client.token = test::FakeNode::kGoodToken;
  client::Stream* sp = nullptr;
  bool got_ack = false;
  so.on_message = [&](const json::Value& v) {
    if (v.get("type") && v.get("type")->as_string() == "CONNECT_ACK") got_ack = true;
    if (v.get("event") && sp) sp->stop();
  };
  client::Stream s(so);
  sp = &s;
  client::ClientError e = s.run();
  EXPECT_EQ(e.code, "STOPPED");
  EXPECT_TRUE(got_ack);
}

// ---- pure parts ---------------------------------------------------------------------------

TEST(ClientPure, EndpointsParse) {
  auto a = client::parse_endpoint("https://robot.local:8443/base/");
  ASSERT_TRUE(a.ok());
  EXPECT_TRUE(a->tls);
  EXPECT_EQ(a->host, "robot.local");
  EXPECT_EQ(a->port, 8443);
  EXPECT_EQ(a->base_path, "/base");
  EXPECT_EQ(a->url(), "https://robot.local:8443/base");
  auto b = client::parse_endpoint("http://[fe80::1]:8080");
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->host, "fe80::1");
  EXPECT_EQ(b->url(), "http://[fe80::1]:8080");
  auto c = client::parse_endpoint("10.0.0.5");
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->port, 80);
  for (const char* bad : {"ftp://x", "http://", "http://h:0", "http://h:99999", "http://u@h",
                          "http://h:8a", "http://[::1"})
    EXPECT_FALSE(client::parse_endpoint(bad).ok()) << bad;
}

TEST(ClientPure, TxtRecordsFollowRfc6763) {
  auto m = client::parse_txt(
      {"ruri=rcan://local.rcan/a/b/c", "Status=estop", "status=available", "flag", "=x", "caps="});
  EXPECT_EQ(m["ruri"], "rcan://local.rcan/a/b/c");
  EXPECT_EQ(m["status"], "estop");  // first wins, keys case-insensitive
  EXPECT_EQ(m.count("flag"), 1u);
  EXPECT_EQ(m["flag"], "");
  EXPECT_EQ(m.count(""), 0u);
  EXPECT_EQ(m["caps"], "");
}

TEST(ClientPure, ErrorBodiesOfEveryShape) {
  auto e = client::error_from_response(
      429,
      R"({"type":"ERROR","payload":{"error_code":"RATE_LIMITED","error":"slow down","detail":{"reason":"per_minute"}}})",
      "7");
  EXPECT_EQ(e.code, "RATE_LIMITED");
  EXPECT_EQ(e.message, "slow down");
  EXPECT_EQ(e.reason, "per_minute");
  EXPECT_EQ(e.retry_after_s, 7);
  auto w = client::error_from_response(
      404, R"({"error":"Watermark token not found in audit log","code":"HTTP_404"})");
  EXPECT_EQ(w.code, "HTTP_404");
  auto h = client::error_from_response(502, "<html>bad gateway</html>");
  EXPECT_EQ(h.code, "HTTP_502");
  EXPECT_EQ(h.http_status, 502);
}

TEST(ClientPure, BackoffFollowsAppendixB) {
  std::mt19937_64 rng(42);
  const int64_t base[] = {1000, 2000, 4000, 8000, 16000, 30000, 30000, 30000};
  for (int round = 0; round < 50; ++round)
    for (int i = 0; i < 8; ++i) {
      int64_t d = client::backoff_delay(i, rng).count();
      EXPECT_GE(d, base[i] - 500);
      EXPECT_LE(d, base[i] + 500);
    }
}

TEST(ClientPure, HttpResponsesParseIncrementally) {
  using client::wire::Parse;
  std::string resp =
      "HTTP/1.1 100 Continue\r\n\r\nHTTP/1.1 200 OK\r\nTransfer-Encoding: "
      "chunked\r\n\r\n4\r\nrcan\r\n3\r\n-ok\r\n0\r\n\r\n";
  for (size_t cut = 0; cut < resp.size(); ++cut) {
    client::wire::ParsedResponse pr;
    size_t used = 0;
    std::string err;
    EXPECT_EQ(
        client::wire::parse_response(std::string_view(resp).substr(0, cut), false, pr, used, err),
        Parse::kIncomplete)
        << cut;
  }
  client::wire::ParsedResponse pr;
  size_t used = 0;
  std::string err;
  ASSERT_EQ(client::wire::parse_response(resp, false, pr, used, err), Parse::kComplete) << err;
  EXPECT_EQ(pr.status, 200);
  EXPECT_EQ(pr.body, "rcan-ok");
  EXPECT_EQ(used, resp.size());
  std::string closed = "HTTP/1.0 200 OK\r\n\r\nuntil close";
  ASSERT_EQ(client::wire::parse_response(closed, true, pr, used, err), Parse::kComplete);
  EXPECT_EQ(pr.body, "until close");
  EXPECT_EQ(client::wire::parse_response(
                "HTTP/1.1 200 OK\r\nContent-Length: 5\r\nContent-Length: 6\r\n\r\n", false, pr,
                used, err),
            Parse::kError);
  EXPECT_EQ(client::wire::parse_response("SSH-2.0-OpenSSH\r\n\r\n", false, pr, used, err),
            Parse::kError);
}

TEST(ClientPure, WebSocketFramesRoundTrip) {
  const uint8_t mask[4] = {1, 2, 3, 4};
  for (size_t n : {size_t{0}, size_t{125}, size_t{126}, size_t{65535}, size_t{70000}}) {
    std::string payload(n, 'x');
    std::string f = client::wire::ws_frame(1, payload, mask);
    client::wire::WsFrame out;
    size_t used = 0;
    std::string err;
    ASSERT_EQ(client::wire::ws_parse(f, out, used, err), client::wire::Parse::kComplete) << n;
    EXPECT_EQ(out.payload, payload);
    EXPECT_EQ(used, f.size());
    EXPECT_EQ(client::wire::ws_parse(std::string_view(f).substr(0, f.size() - 1), out, used, err),
              client::wire::Parse::kIncomplete);
  }
  EXPECT_EQ(client::wire::ws_accept("dGhlIHNhbXBsZSBub25jZQ=="),
            "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");  // RFC 6455 §1.3
}

TEST(ClientPure, StatusBodiesParseOrFailCleanly) {
  auto s = client::parse_status(
      R"({"ruri":"rcan://local.rcan/a/b/c","estop_active":true,"sessions":[{"session_id":"s1","role":"USER"}]})");
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(s->estop_active);
  ASSERT_EQ(s->sessions.size(), 1u);
  EXPECT_EQ(s->active_sessions, 1);
  for (const char* bad : {"", "[]", "{}", R"({"ruri":5})", "{\"ruri\":\"x\""}) {
    auto r = client::parse_status(bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.error().code, "SCHEMA_VALIDATION_FAILED");
  }
}

}  // namespace
}  // namespace rcan
