// Re-arm after ESTOP, against a real rcand (docs/NODE.md, "Re-arm after ESTOP"): a control
// session that was armed before an ESTOP does not drive again after the RESUME — its motion
// commands are refused (423 COMMAND_REJECTED, reason rearm_required, audited) and the robot
// stays where it stopped — until its holder re-arms with `rearm: true` on a claim or a renewal.
// A renewal without it, heartbeats and further drives do not re-arm; stops are never refused.
// A WebSocket stream without a control session follows the same rule: it is armed when it
// connects, and after an ESTOP its motion commands need one that carries "rearm": true.
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

using test::HttpReply;
using Headers = std::vector<std::pair<std::string, std::string>>;

Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string message(const char* type, json::Object payload) {
  return json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                             {"message_id", new_uuid_v4()},
                                             {"type", type},
                                             {"timestamp_ms", now_ms()},
                                             {"payload", std::move(payload)}}));
}

std::string drive(double linear, int64_t duration_ms) {
  return message(
      "COMMAND",
      json::Object{
          {"action", "drive"}, {"linear", linear}, {"angular", 0.0}, {"duration_ms", duration_ms}});
}

json::Value parse(const HttpReply& r) {
  auto v = json::parse(r.body);
  return v.ok() ? std::move(v).value() : json::Value();
}

std::string reason_of(const HttpReply& r) {
  json::Value v = parse(r);
  const json::Value* p = v.get("payload");
  const json::Value* reason = p ? p->get("reason") : nullptr;
  return reason && reason->is_string() ? reason->as_string() : std::string();
}

class RearmTest : public ::testing::Test {
 protected:
  void SetUp() override {
    d_ = std::make_unique<test::RcandDaemon>(dir_.path() + "/node");
    ASSERT_NE(d_->port(), 0);
    owner_ = d_->token("owner", {"status", "control", "config"}, "owner-1");
    user_ = d_->token("user", {"status", "control"}, "driver-1");
  }
  HttpReply post(const std::string& path, const std::string& body, const std::string& tok) {
    return test::http(d_->port(), "POST", path, body, bearer(tok));
  }
  json::Value status() {
    return parse(test::http(d_->port(), "GET", "/rcan/v1/status", "", bearer(owner_)));
  }
  double x() {
    json::Value st = status();
    return st.get("robot")->get("robot")->get("base")->get("x")->to_double();
  }
  // Waits until the base reports it has stopped (the sim decelerates).
  void wait_stopped() {
    for (int i = 0; i < 100; ++i) {
      json::Value st = status();
      if (st.get("robot")->get("robot")->get("stopped")->as_bool()) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "the robot did not stop";
  }
  void estop_and_resume() {
    ASSERT_EQ(post("/api/stop", "{}", owner_).status, 200);
    ASSERT_TRUE(status().get("estop_active")->as_bool());
    HttpReply r = post("/rcan/v1/command", message("SAFETY", {{"safety_event", "RESUME"}}), owner_);
    ASSERT_EQ(r.status, 200) << r.body;
    ASSERT_FALSE(status().get("estop_active")->as_bool());
  }
  std::string claim(const std::string& body = "{}") {
    HttpReply c = post("/rcan/v1/auth/claim", body, user_);
    EXPECT_EQ(c.status, 200) << c.body;
    const json::Value v = parse(c);
    const json::Value* sid = v.get("payload") ? v.get("payload")->get("session_id") : nullptr;
    return sid && sid->is_string() ? sid->as_string() : std::string();
  }

  test::TempDir dir_;
  std::unique_ptr<test::RcandDaemon> d_;
  std::string owner_;
  std::string user_;
};

TEST_F(RearmTest, AHoldFromBeforeTheEstopIsRefusedAfterResumeUntilRearmed) {
  const std::string session = claim();
  ASSERT_FALSE(session.empty());
  HttpReply before = post("/rcan/v1/command", drive(0.3, 300), user_);
  ASSERT_EQ(before.status, 200) << before.body;
  const int64_t epoch0 = status().get("robot")->get("estop_epoch")->as_int();

  estop_and_resume();
  EXPECT_EQ(status().get("robot")->get("estop_epoch")->as_int(), epoch0 + 1);
  wait_stopped();
  const double x0 = x();

  // The same holder keeps "holding": every drive is refused, coded, and nothing moves.
  for (int i = 0; i < 4; ++i) {
    HttpReply r = post("/rcan/v1/command", drive(0.5, 500), user_);
    EXPECT_EQ(r.status, 423) << r.body;
    EXPECT_NE(r.body.find("COMMAND_REJECTED"), std::string::npos) << r.body;
    EXPECT_EQ(reason_of(r), "rearm_required") << r.body;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  // A renewal without `rearm`, and a renewing claim without it, do not re-arm.
  HttpReply renew = post("/rcan/v1/auth/renew", "{\"session_id\":\"" + session + "\"}", user_);
  ASSERT_EQ(renew.status, 200) << renew.body;
  EXPECT_EQ(claim(), session);
  EXPECT_EQ(reason_of(post("/rcan/v1/command", drive(0.5, 500), user_)), "rearm_required");
  // Stops are never refused.
  HttpReply stop = post("/rcan/v1/command", message("SAFETY", {{"safety_event", "STOP"}}), user_);
  EXPECT_EQ(stop.status, 200) << stop.body;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_DOUBLE_EQ(x(), x0) << "a refused drive moved the robot";

  // The refusal is audited like every other refusal.
  HttpReply audit =
      test::http(d_->port(), "GET", "/api/v1/audit?format=jsonl", "", bearer(owner_), 30000);
  ASSERT_EQ(audit.status, 200);
  EXPECT_NE(audit.body.find("\"rearm_required\""), std::string::npos)
      << "no audit record of the refusal";

  // The holder re-arms explicitly: its drives are accepted and the robot moves.
  HttpReply rearm =
      post("/rcan/v1/auth/renew", "{\"session_id\":\"" + session + "\",\"rearm\":true}", user_);
  ASSERT_EQ(rearm.status, 200) << rearm.body;
  const json::Value rv = parse(rearm);
  EXPECT_TRUE(rv.get("payload")->get("rearmed")->as_bool()) << rearm.body;
  HttpReply after = post("/rcan/v1/command", drive(0.5, 400), user_);
  EXPECT_EQ(after.status, 200) << after.body;
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_GT(x(), x0 + 0.01);
  EXPECT_NE(audit.body.find("\"CLAIM_RENEWED\""), std::string::npos);
}

TEST_F(RearmTest, RearmOnAClaimAndSessionsClaimedAfterTheEstop) {
  const std::string session = claim();
  ASSERT_FALSE(session.empty());
  estop_and_resume();
  EXPECT_EQ(reason_of(post("/rcan/v1/command", drive(0.2, 200), user_)), "rearm_required");
  // A renewing claim with rearm: true re-arms the same session.
  HttpReply c = post("/rcan/v1/auth/claim", "{\"rearm\":true}", user_);
  ASSERT_EQ(c.status, 200) << c.body;
  const json::Value cv = parse(c);
  EXPECT_EQ(cv.get("payload")->get("session_id")->as_string(), session);
  EXPECT_TRUE(cv.get("payload")->get("rearmed")->as_bool());
  EXPECT_EQ(post("/rcan/v1/command", drive(0.2, 200), user_).status, 200);

  // A session claimed while the ESTOP is latched is a fresh operator action: after the RESUME
  // it drives without re-arming.
  ASSERT_EQ(post("/rcan/v1/auth/release", "{\"session_id\":\"" + session + "\"}", user_).status,
            200);
  ASSERT_EQ(post("/api/stop", "{}", owner_).status, 200);
  const std::string fresh = claim();
  ASSERT_FALSE(fresh.empty());
  EXPECT_NE(fresh, session);
  HttpReply latched = post("/rcan/v1/command", drive(0.2, 200), user_);
  EXPECT_EQ(reason_of(latched), "estop_active") << latched.body;
  ASSERT_EQ(
      post("/rcan/v1/command", message("SAFETY", {{"safety_event", "RESUME"}}), owner_).status,
      200);
  HttpReply ok = post("/rcan/v1/command", drive(0.2, 200), user_);
  EXPECT_EQ(ok.status, 200) << ok.body;
}

// A stream's answer to the message sent (pushed events skipped): its reason, "" for an ACK.
std::string answer_reason(test::WsClient& ws, const std::string& msg_id) {
  for (int i = 0; i < 50; ++i) {
    auto frame = ws.recv_text(5000);
    if (!frame) return "no answer";
    auto v = json::parse(*frame);
    if (!v.ok()) continue;
    const json::Value* rt = v->get("reply_to");
    if (rt == nullptr || !rt->is_string() || rt->as_string() != msg_id) continue;
    if (v->get("type")->as_string() == "ACK") return "";
    const json::Value* reason = v->get("payload") ? v->get("payload")->get("reason") : nullptr;
    return reason && reason->is_string() ? reason->as_string() : "error without a reason";
  }
  return "no answer";
}

TEST_F(RearmTest, AStreamWithoutASessionFromBeforeTheEstopNeedsARearmingCommand) {
  test::WsClient ws;
  ASSERT_EQ(ws.connect(d_->port(), "/rcan/v1/stream"), 101);
  ASSERT_TRUE(ws.send_text("{\"type\":\"CONNECT\",\"token\":\"" + user_ + "\"}"));
  auto ack = ws.recv_text(5000);
  ASSERT_TRUE(ack.has_value());
  ASSERT_NE(ack->find("CONNECT_ACK"), std::string::npos) << *ack;
  auto send = [&](double linear, bool rearm) {
    json::Value m = *json::parse(drive(linear, 300));
    if (rearm) m.as_object().set("rearm", true);
    const std::string id = m.get("message_id")->as_string();
    EXPECT_TRUE(ws.send_text(json::dump(m)));
    return answer_reason(ws, id);
  };
  EXPECT_EQ(send(0.3, false), "");  // armed at CONNECT: it drives
  estop_and_resume();
  wait_stopped();
  const double x0 = x();
  // The stream keeps "holding": every drive is refused and nothing moves.
  for (int i = 0; i < 3; ++i) EXPECT_EQ(send(0.5, false), "rearm_required");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_DOUBLE_EQ(x(), x0) << "a refused stream drive moved the robot";
  // HTTP commands without a session are each their own action: not held by this rule.
  EXPECT_EQ(post("/rcan/v1/command", drive(0.0, 100), user_).status, 200);
  // The operator's fresh action re-arms the stream; later drives need no flag.
  EXPECT_EQ(send(0.4, true), "");
  EXPECT_EQ(send(0.4, false), "");
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  EXPECT_GT(x(), x0 + 0.01);
  HttpReply audit =
      test::http(d_->port(), "GET", "/api/v1/audit?format=jsonl", "", bearer(owner_), 30000);
  ASSERT_EQ(audit.status, 200);
  EXPECT_NE(audit.body.find("\"rearm_required\""), std::string::npos);
  EXPECT_NE(audit.body.find("\"rearmed\":true"), std::string::npos);

  // A stream that connects while the ESTOP is latched is armed after it: it drives after RESUME.
  ASSERT_EQ(post("/api/stop", "{}", owner_).status, 200);
  test::WsClient late;
  ASSERT_EQ(late.connect(d_->port(), "/rcan/v1/stream"), 101);
  ASSERT_TRUE(late.send_text("{\"type\":\"CONNECT\",\"token\":\"" + user_ + "\"}"));
  ASSERT_TRUE(late.recv_text(5000).has_value());
  ASSERT_EQ(
      post("/rcan/v1/command", message("SAFETY", {{"safety_event", "RESUME"}}), owner_).status,
      200);
  json::Value m = *json::parse(drive(0.2, 200));
  ASSERT_TRUE(late.send_text(json::dump(m)));
  EXPECT_EQ(answer_reason(late, m.get("message_id")->as_string()), "");
  EXPECT_EQ(send(0.2, false), "rearm_required");  // the first stream missed this ESTOP too
}

}  // namespace
}  // namespace rcan
