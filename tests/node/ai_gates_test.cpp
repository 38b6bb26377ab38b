// §16 AI accountability end to end (docs/AI.md): a real rcand started with a configuration
// that has confidence gates, HiTL gates and brain layers (real `rcand --sim-layer`
// processes), driven over HTTP and WebSocket, with a real webhook receiver. Covers the ai
// block, the three on_fail behaviours and escalation across layers, HiTL trigger /
// approve / deny / timeout / refused AUTHORIZE and persistence across a restart, the thought
// log's scopes, the watermark and its public verify endpoint, and the CLI verbs.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

#include "ai_test_support.h"

namespace rcan {
namespace {

using test::HttpReply;
using namespace ai_test;

// ---------------------------------------------------------------------------------------------
// The shared configuration: a nav gate that escalates (reactive → fast → planner, the fast
// layer still unsure), a chat gate that blocks, a teleop gate that allows; arm_move held for
// OWNER/CREATOR (1.5 s, block, stream + webhook), arm_home held 0.8 s then allowed.

class AiGates : public ::testing::Test {
 protected:
  void SetUp() override {
    hook_ = std::make_unique<WebhookReceiver>();
    fast_ = std::make_unique<SimLayerProc>("fast", 0.5);
    planner_ = std::make_unique<SimLayerProc>("planner", 0.95);
    std::string agent =
        "agent:\n"
        "  confidence_gates:\n"
        "    - {scope: nav, min_confidence: 0.8, on_fail: escalate}\n"
        "    - {scope: chat, min_confidence: 0.5, on_fail: block}\n"
        "    - {scope: teleop, min_confidence: 0.6, on_fail: allow}\n"
        "  hitl_gates:\n"
        "    - action_types: [arm_move]\n"
        "      require_auth: true\n"
        "      auth_timeout_ms: 1500\n"
        "      on_timeout: block\n"
        "      notify: [ws, \"" +
        hook_->url() +
        "\"]\n"
        "    - action_types: [arm_home]\n"
        "      require_auth: true\n"
        "      auth_timeout_ms: 800\n"
        "      on_timeout: allow\n"
        "  layers:\n"
        "    fast: {url: \"" +
        fast_->url() +
        "\", timeout_ms: 3000}\n"
        "    planner: {url: \"" +
        planner_->url() + "\", timeout_ms: 3000}\n";
    node_ = std::make_unique<AiNode>(dir_.path(), agent);
  }
  AiNode& n() { return *node_; }

  test::TempDir dir_;
  std::unique_ptr<WebhookReceiver> hook_;
  std::unique_ptr<SimLayerProc> fast_, planner_;
  std::unique_ptr<AiNode> node_;
};

TEST_F(AiGates, AiBlockIsCopiedIntoTheAuditRecordAndConfidenceIsNeverDefaulted) {
  // Not gated (status): the ai block lands in the record as sent.
  std::string id = new_uuid_v4();
  HttpReply r = n().command(n().leasee(),
                            cmd(id, "status", {}, ai_block("openai", "gpt-4o", 0.91, "planner")));
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value rec = n().record(id, "COMMAND");
  ASSERT_TRUE(rec.get("ai")) << json::dump(rec);
  EXPECT_EQ(rec.get("ai")->get("provider")->as_string(), "openai");
  EXPECT_EQ(rec.get("ai")->get("model")->as_string(), "gpt-4o");
  EXPECT_DOUBLE_EQ(rec.get("ai")->get("confidence")->to_double(), 0.91);
  EXPECT_FALSE(rec.get("ai")->get("escalated")->as_bool());
  // Without a confidence, the record has none (not 1.0).
  std::string id2 = new_uuid_v4();
  json::Object no_conf{{"provider", "ollama"}, {"model", "llama3"}, {"escalated", false}};
  ASSERT_EQ(n().command(n().leasee(), cmd(id2, "status", {}, no_conf)).status, 200);
  json::Value rec2 = n().record(id2, "COMMAND");
  ASSERT_TRUE(rec2.get("ai"));
  EXPECT_EQ(rec2.get("ai")->get("confidence"), nullptr) << json::dump(rec2);
}

// A gate names an action; every name of that action is held (docs/SECURITY.md R2). Before the
// action table, `set_joints` and `joint_move` moved the arm past a gate on `arm_move`.
TEST_F(AiGates, AHitlGateHoldsEveryNameOfItsAction) {
  const json::Object joints{{"joints", json::Array{0.1, 0.1, 0.1, 0.1, 0.1, 0.1}}};
  for (const char* name : {"set_joints", "joint_move", "ARM", "move_arm"}) {
    SCOPED_TRACE(name);
    std::string id = new_uuid_v4();
    HttpReply r = n().command(n().leasee(), cmd(id, name, joints));
    EXPECT_EQ(r.status, 202) << r.body;
    EXPECT_EQ(n().records(id, "COMMAND").size(), 0u);  // not dispatched
    json::Value held = n().record(id, "HITL_PENDING");
    EXPECT_EQ(held.get("action")->as_string(), "arm_move") << json::dump(held);
  }
}

// A confidence gate on the arm capability covers every name that moves the arm.
TEST(AiGateNames, AConfidenceGateOnTheArmCoversEveryArmActionName) {
  test::TempDir dir;
  AiNode n(
      dir.path(),
      "agent:\n  confidence_gates:\n    - {scope: arm, min_confidence: 0.8, on_fail: block}\n");
  const json::Object joints{{"joints", json::Array{0.1, 0.1, 0.1, 0.1, 0.1, 0.1}}};
  for (const char* name : {"arm_move", "set_joints", "joint_move", "grip", "release_grip"}) {
    SCOPED_TRACE(name);
    std::string id = new_uuid_v4();
    HttpReply r = n.command(n.leasee(), cmd(id, name, joints, ai_block("p", "m", 0.3, "fast")));
    EXPECT_EQ(r.status, 403) << r.body;
    EXPECT_EQ(error_code(r), "CONFIDENCE_GATE_FAIL") << r.body;
    EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
  }
}

// §16.5 evidence outlives the process, and one sender cannot rewrite another's.
TEST(AiThoughts, AThoughtSurvivesARestartAndAnotherSenderCannotOverwriteIt) {
  test::TempDir dir;
  const json::Object why{{"reasoning", "the aisle is clear for 2 m"}, {"instruction", "hi"}};
  const json::Object forged{{"reasoning", "nothing happened here"}};
  {
    AiNode n(dir.path(), "");
    HttpReply sent = n.command(n.leasee(), cmd(new_uuid_v4(), "chat", {{"text", "hi"}},
                                               ai_block("sim", "m", 0.9, "fast", "th_keep"),
                                               ",\"thought\":" + json::dump(json::Value(why))));
    ASSERT_EQ(sent.status, 200) << sent.body;
    HttpReply other = n.command(
        n.token("user", {"status", "chat"}),
        cmd(new_uuid_v4(), "chat", {{"text", "hi"}}, ai_block("sim", "m", 0.9, "fast", "th_keep"),
            ",\"thought\":" + json::dump(json::Value(forged))));
    EXPECT_EQ(other.status, 400) << other.body;
    EXPECT_NE(other.body.find("thought_id_taken"), std::string::npos) << other.body;
    ASSERT_EQ(n.terminate(), 0);
  }
  AiNode again(dir.path(), "", /*fresh=*/false);
  HttpReply got = again.get("/api/thoughts/th_keep", again.owner());
  ASSERT_EQ(got.status, 200) << got.body;
  EXPECT_EQ(parse(got.body).get("reasoning")->as_string(), "the aisle is clear for 2 m");
}

TEST_F(AiGates, AiBlockWithoutAMustFieldOrWithABadConfidenceIsRefused) {
  json::Object no_model{{"provider", "anthropic"}, {"confidence", 0.88}};
  HttpReply r = n().command(n().leasee(), cmd(new_uuid_v4(), "status", {}, no_model));
  EXPECT_EQ(r.status, 400) << r.body;
  EXPECT_EQ(error_code(r), "SCHEMA_VALIDATION_FAILED");
  EXPECT_EQ(parse(r.body).get("payload")->get("detail")->get("reason")->as_string(),
            "AUDIT_INCOMPLETE_AI_IDENTITY");
  json::Object empty_provider{{"provider", ""}, {"model", "m"}};
  EXPECT_EQ(error_code(n().command(n().leasee(), cmd(new_uuid_v4(), "status", {}, empty_provider))),
            "SCHEMA_VALIDATION_FAILED");
  json::Object high{{"provider", "p"}, {"model", "m"}, {"confidence", 1.5}};
  EXPECT_EQ(n().command(n().leasee(), cmd(new_uuid_v4(), "status", {}, high)).status, 400);
}

TEST_F(AiGates, BlockGateRefusesBelowAndWithoutConfidenceAndPassesAtTheThreshold) {
  std::string low = new_uuid_v4();
  HttpReply r = n().command(n().leasee(),
                            cmd(low, "chat", {{"text", "hi"}}, ai_block("sim", "m", 0.3, "fast")));
  EXPECT_EQ(r.status, 403) << r.body;
  EXPECT_EQ(error_code(r), "CONFIDENCE_GATE_FAIL");
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(), "confidence_below_gate");
  json::Value rec = n().record(low, "CONFIDENCE_GATE_FAIL");
  EXPECT_EQ(rec.get("outcome")->as_string(), "blocked");
  ASSERT_TRUE(rec.get("ai")) << json::dump(rec);
  EXPECT_DOUBLE_EQ(rec.get("ai")->get("confidence")->to_double(), 0.3);
  // Absent confidence is a miss.
  json::Object none{{"provider", "sim"}, {"model", "m"}};
  EXPECT_EQ(n().command(n().leasee(), cmd(new_uuid_v4(), "chat", {{"text", "hi"}}, none)).status,
            403);
  // rcan-py's top-level confidence counts as the command's confidence too.
  HttpReply top = n().command(
      n().leasee(), cmd(new_uuid_v4(), "chat", {{"text", "hi"}}, {}, ",\"confidence\":0.2"));
  EXPECT_EQ(error_code(top), "CONFIDENCE_GATE_FAIL") << top.body;
  // Strict comparison: exactly at min_confidence passes.
  std::string at = new_uuid_v4();
  HttpReply ok = n().command(n().leasee(),
                             cmd(at, "chat", {{"text", "hi"}}, ai_block("sim", "m", 0.5, "fast")));
  EXPECT_EQ(ok.status, 200) << ok.body;
}

TEST_F(AiGates, AllowGateDispatchesAndMarksTheRecordGateBypassed) {
  std::string id = new_uuid_v4();
  HttpReply r = n().command(n().leasee(), cmd(id, "teleop", {{"linear", 0.1}, {"duration_ms", 100}},
                                              ai_block("sim", "m", 0.2, "reactive")));
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value rec = n().record(id, "COMMAND");
  ASSERT_TRUE(rec.get("gate_bypassed")) << json::dump(rec);
  EXPECT_TRUE(rec.get("gate_bypassed")->as_bool());
  // A passing command carries no gate_bypassed.
  std::string ok = new_uuid_v4();
  ASSERT_EQ(n().command(n().leasee(), cmd(ok, "teleop", {{"linear", 0.1}, {"duration_ms", 100}},
                                          ai_block("sim", "m", 0.9, "reactive")))
                .status,
            200);
  EXPECT_EQ(n().record(ok, "COMMAND").get("gate_bypassed"), nullptr);
}

TEST_F(AiGates, EscalationClimbsLayersUntilTheGatePassesThenDispatchesWithAWatermark) {
  std::string id = new_uuid_v4();
  json::Object thought{{"reasoning", "the dock is probably ahead"},
                       {"instruction", "go to the dock"}};
  HttpReply r = n().command(
      n().leasee(),
      cmd(id, "move", {{"linear", 0.2}, {"duration_ms", 100}, {"instruction", "go to the dock"}},
          ai_block("sim", "sim-reactive", 0.3, "reactive", "th_reactive_1"),
          ",\"thought\":" + json::dump(json::Value(thought))));
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value ack = parse(r.body);
  EXPECT_EQ(ack.get("type")->as_string(), "ACK");
  EXPECT_EQ(ack.get("reply_to")->as_string(), id);
  std::string wm = ack.get("payload")->get("watermark_token")->as_string();
  EXPECT_TRUE(wm.rfind("rcan-wm-v1:", 0) == 0) << wm;
  // reactive (0.3) → fast (0.5, still below 0.8) → planner (0.95): two escalation records.
  auto escalations = n().records(id, "CONFIDENCE_GATE_ESCALATED", 2);
  ASSERT_EQ(escalations.size(), 2u);
  EXPECT_EQ(escalations[0].get("ai")->get("layer")->as_string(), "reactive");
  EXPECT_EQ(escalations[0].get("detail")->get("to_layer")->as_string(), "fast");
  EXPECT_EQ(escalations[1].get("ai")->get("layer")->as_string(), "fast");
  EXPECT_TRUE(escalations[1].get("ai")->get("escalated")->as_bool());
  EXPECT_EQ(escalations[1].get("detail")->get("to_layer")->as_string(), "planner");
  json::Value rec = n().record(id, "COMMAND");
  EXPECT_EQ(rec.get("ai")->get("layer")->as_string(), "planner");
  EXPECT_TRUE(rec.get("ai")->get("escalated")->as_bool());
  EXPECT_DOUBLE_EQ(rec.get("ai")->get("confidence")->to_double(), 0.95);
  EXPECT_EQ(rec.get("watermark_token")->as_string(), wm);
  // The planner's thought names the fast layer's thought, which names the reactive one.
  std::string planner_thought = rec.get("ai")->get("thought_id")->as_string();
  HttpReply t = n().get("/api/thoughts/" + planner_thought, n().owner());
  ASSERT_EQ(t.status, 200) << t.body;
  json::Value tv = parse(t.body);
  EXPECT_EQ(tv.get("layer")->as_string(), "planner");
  std::string fast_thought = tv.get("escalated_from")->as_string();
  json::Value fv = parse(n().get("/api/thoughts/" + fast_thought, n().owner()).body);
  EXPECT_EQ(fv.get("layer")->as_string(), "fast");
  EXPECT_EQ(fv.get("escalated_from")->as_string(), "th_reactive_1");
  // The sender's own thought is in the log too.
  json::Value own = parse(n().get("/api/thoughts/th_reactive_1", n().owner()).body);
  EXPECT_EQ(own.get("reasoning")->as_string(), "the dock is probably ahead");
  EXPECT_EQ(fast_->requests_seen(), 1);
  EXPECT_EQ(planner_->requests_seen(), 1);
}

// An SDK-shaped message (rcan-py: `cmd`, `msg_id`) that escalates is answered in its own shape:
// the answer reads the received message, not the layer's command that replaced it.
TEST_F(AiGates, AnEscalatedSdkMessageIsAnsweredInTheSdkShape) {
  const std::string t = AiNode::kRuri;
  const std::string target = t.substr(0, t.rfind('/')) + "/v1" + t.substr(t.rfind('/'));
  const std::string id = new_uuid_v4();
  json::Object m{{"rcan", "3.2"},
                 {"msg_id", id},
                 {"timestamp", static_cast<double>(wall_ms()) / 1000.0},
                 {"cmd", "move"},
                 {"target", target},
                 {"params", json::Object{{"linear", 0.2}, {"duration_ms", 100}}},
                 {"ai", ai_block("sim", "sim-reactive", 0.3, "reactive")}};
  HttpReply r = n().command(n().leasee(), json::dump(json::Value(m)));
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value ack = parse(r.body);
  EXPECT_EQ(ack.get("type")->as_string(), "ACK") << r.body;
  ASSERT_NE(ack.get("msg_id"), nullptr) << r.body;
  EXPECT_EQ(ack.get("status")->as_string(), "ok") << r.body;
  EXPECT_EQ(n().records(id, "CONFIDENCE_GATE_ESCALATED", 2).size(), 2u);
}

TEST_F(AiGates, EscalationWithNoHigherLayerIsABlock) {
  std::string id = new_uuid_v4();
  HttpReply r = n().command(n().leasee(), cmd(id, "move", {{"linear", 0.2}, {"duration_ms", 100}},
                                              ai_block("sim", "m", 0.1, "planner")));
  EXPECT_EQ(r.status, 403) << r.body;
  EXPECT_EQ(error_code(r), "CONFIDENCE_GATE_FAIL");
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(), "no_higher_layer");
  EXPECT_EQ(n().records(id, "COMMAND").size(), 0u);
  EXPECT_EQ(n().record(id, "CONFIDENCE_GATE_FAIL").get("outcome")->as_string(), "blocked");
}

TEST_F(AiGates, HitlGateHoldsNotifiesOwnersOnlyAndTheOwnerApproves) {
  test::WsClient owner_ws, leasee_ws;
  ASSERT_TRUE(connect_stream(owner_ws, n().port(), n().owner()));
  ASSERT_TRUE(connect_stream(leasee_ws, n().port(), n().leasee()));
  std::string id = new_uuid_v4();
  HttpReply r = n().command(
      n().leasee(), cmd(id, "arm_move", {{"joints", json::Array{0.1, 0.0, 0.0, 0.0, 0.0, 0.0}}}));
  ASSERT_EQ(r.status, 202) << r.body;
  json::Value pa = parse(r.body);
  EXPECT_EQ(pa.get("type")->as_string(), "PENDING_AUTH");
  const json::Value* p = pa.get("payload");
  EXPECT_EQ(p->get("message_id")->as_string(), id);
  EXPECT_EQ(p->get("action_type")->as_string(), "arm_move");
  EXPECT_FALSE(p->get("description")->as_string().empty());
  EXPECT_EQ(p->get("auth_timeout_ms")->as_int(), 1500);
  EXPECT_GT(p->get("expires_at_ms")->as_int(), 0);
  EXPECT_EQ(p->get("queue_status")->as_string(), "pending_authorization");
  // Owners' streams get PENDING_AUTH; the LEASEE's stream does not; the webhook does.
  auto ev = wait_frame(owner_ws, "PENDING_AUTH");
  ASSERT_TRUE(ev) << "no PENDING_AUTH on the owner's stream";
  EXPECT_EQ(ev->get("payload")->get("message_id")->as_string(), id);
  EXPECT_EQ(ev->get("_deliver"), nullptr);
  ASSERT_TRUE(hook_->wait_for(id)) << "the webhook got nothing";
  json::Value listed = parse(n().get("/rcan/v1/pending", n().owner()).body);
  ASSERT_EQ(listed.get("pending")->as_array().size(), 1u);
  EXPECT_EQ(listed.get("pending")->as_array()[0].get("message_id")->as_string(), id);
  EXPECT_EQ(n().records(id, "COMMAND").size(), 0u);  // not dispatched
  EXPECT_EQ(n().record(id, "HITL_PENDING").get("action")->as_string(), "arm_move");
  // Approve.
  HttpReply a = n().authorize(n().owner(), id, "approve", "clear");
  ASSERT_EQ(a.status, 200) << a.body;
  EXPECT_EQ(parse(a.body).get("type")->as_string(), "ACK");
  json::Value approved = n().record(id, "HITL_APPROVED");
  EXPECT_EQ(approved.get("principal")->as_string(), "owner-1");
  EXPECT_EQ(approved.get("reason")->as_string(), "clear");
  json::Value dispatched = n().record(id, "COMMAND");
  EXPECT_EQ(dispatched.get("principal")->as_string(), "leasee-1");
  EXPECT_EQ(dispatched.get("detail")->get("hitl")->get("authorized_by")->as_string(), "owner-1");
  EXPECT_LT(approved.get("seq")->as_int(), dispatched.get("seq")->as_int());
  // The originator's stream hears the result.
  auto ack = wait_frame(leasee_ws, "ACK", id);
  EXPECT_TRUE(ack) << "the originator's stream got no ACK";
  EXPECT_EQ(parse(n().get("/rcan/v1/pending", n().owner()).body).get("pending")->as_array().size(),
            0u);
  // A second decision on the same id finds nothing.
  EXPECT_EQ(n().authorize(n().owner(), id, "approve").status, 404);
}

TEST_F(AiGates, AuthorizeBelowOwnerIsRefusedAndAudited) {
  std::string id = new_uuid_v4();
  ASSERT_EQ(
      n().command(n().leasee(), cmd(id, "arm_move", {{"joints", json::Array{0.1, 0, 0, 0, 0, 0}}}))
          .status,
      202);
  for (const std::string& tok :
       {n().token("guest", {"status"}), n().leasee(), n().token("user", {"status", "control"})}) {
    HttpReply r = n().authorize(tok, id, "approve");
    EXPECT_EQ(r.status, 403) << r.body;
    EXPECT_EQ(error_code(r), "INSUFFICIENT_PRIVILEGES");
  }
  auto refused = n().records(id, "HITL_AUTHORIZE_REFUSED", 3);
  EXPECT_EQ(refused.size(), 3u);
  EXPECT_EQ(n().records(id, "COMMAND").size(), 0u);
  EXPECT_EQ(n().post("/rcan/v1/authorize", "{}", "").status, 401);
  // CREATOR may.
  EXPECT_EQ(
      n().authorize(n().token("creator", {"status", "control", "config"}), id, "approve").status,
      200);
}

TEST_F(AiGates, DenyOnTheStreamDropsTheCommandAndTellsTheOriginator) {
  test::WsClient owner_ws, leasee_ws;
  ASSERT_TRUE(connect_stream(owner_ws, n().port(), n().owner()));
  ASSERT_TRUE(connect_stream(leasee_ws, n().port(), n().leasee()));
  std::string id = new_uuid_v4();
  // Sent on the originator's own stream: the 202 answer arrives there.
  leasee_ws.send_text(cmd(id, "arm_move", {{"joints", json::Array{0.1, 0, 0, 0, 0, 0}}}));
  ASSERT_TRUE(wait_frame(leasee_ws, "PENDING_AUTH"));
  json::Object authz{
      {"type", "AUTHORIZE"},
      {"message_id", new_uuid_v4()},
      {"payload",
       json::Object{{"message_id", id}, {"decision", "deny"}, {"reason", "person nearby"}}}};
  owner_ws.send_text(json::dump(json::Value(authz)));
  auto answer = wait_frame(owner_ws, "ACK");
  ASSERT_TRUE(answer);
  EXPECT_EQ(answer->get("payload")->get("decision")->as_string(), "deny");
  auto err = wait_frame(leasee_ws, "ERROR", id);
  ASSERT_TRUE(err) << "the originator got no ERROR";
  EXPECT_EQ(err->get("payload")->get("error_code")->as_string(), "HITL_DENIED");
  json::Value denied = n().record(id, "HITL_DENIED");
  EXPECT_EQ(denied.get("outcome")->as_string(), "blocked");
  EXPECT_EQ(denied.get("reason")->as_string(), "person nearby");
  EXPECT_EQ(n().records(id, "COMMAND").size(), 0u);
}

TEST_F(AiGates, TimeoutBlocksOrAllowsPerGate) {
  test::WsClient leasee_ws;
  ASSERT_TRUE(connect_stream(leasee_ws, n().port(), n().leasee()));
  std::string blocked = new_uuid_v4();
  ASSERT_EQ(n().command(n().leasee(),
                        cmd(blocked, "arm_move", {{"joints", json::Array{0.1, 0, 0, 0, 0, 0}}}))
                .status,
            202);
  std::string allowed = new_uuid_v4();
  ASSERT_EQ(n().command(n().leasee(), cmd(allowed, "arm_home", {})).status, 202);
  // Both outcomes reach the originator's stream, in whatever order the timers fire.
  std::optional<json::Value> err, ack;
  for (int i = 0; i < 2 && (!err || !ack); ++i) {
    auto f = wait_frame(leasee_ws, "", "", 15000);
    ASSERT_TRUE(f) << "the originator's stream went quiet";
    const json::Value* r = f->get("reply_to");
    std::string about = r && r->is_string() ? r->as_string() : "";
    if (about == blocked)
      err = f;
    else if (about == allowed)
      ack = f;
    else
      --i;  // another event
  }
  ASSERT_TRUE(err && ack);
  EXPECT_EQ(err->get("payload")->get("error_code")->as_string(), "HITL_TIMEOUT");
  EXPECT_EQ(n().record(blocked, "HITL_TIMEOUT").get("outcome")->as_string(), "blocked");
  EXPECT_EQ(n().records(blocked, "COMMAND").size(), 0u);
  EXPECT_EQ(ack->get("type")->as_string(), "ACK") << json::dump(*ack);
  json::Value rec = n().record(allowed, "COMMAND");
  ASSERT_TRUE(rec.get("hitl_timeout_bypass")) << json::dump(rec);
  EXPECT_TRUE(rec.get("hitl_timeout_bypass")->as_bool());
}

TEST_F(AiGates, ThoughtLogNeedsATokenShowsReasoningOnlyWithConfigScopeAnd404sUnknownIds) {
  std::string id = new_uuid_v4();
  json::Object thought{{"reasoning", "secret prompt text"},
                       {"instruction", "say hi"},
                       {"context_snapshot", json::Object{{"battery", 0.5}}}};
  HttpReply sent =
      n().command(n().leasee(),
                  cmd(id, "chat", {{"text", "hi"}}, ai_block("sim", "m", 0.9, "fast", "th_chat_1"),
                      ",\"thought\":" + json::dump(json::Value(thought))));
  ASSERT_EQ(sent.status, 200) << sent.body;
  HttpReply full = n().get("/api/thoughts/th_chat_1", n().owner());
  ASSERT_EQ(full.status, 200) << full.body;
  json::Value fv = parse(full.body);
  EXPECT_EQ(fv.get("reasoning")->as_string(), "secret prompt text");
  EXPECT_EQ(fv.get("instruction")->as_string(), "say hi");
  EXPECT_DOUBLE_EQ(fv.get("confidence")->to_double(), 0.9);
  EXPECT_EQ(fv.get("action")->get("type")->as_string(), "chat");
  EXPECT_TRUE(fv.get("escalated_from")->is_null());
  HttpReply partial = n().get("/api/thoughts/th_chat_1", n().leasee());
  ASSERT_EQ(partial.status, 200);
  EXPECT_EQ(parse(partial.body).get("reasoning"), nullptr);
  EXPECT_NE(parse(partial.body).get("confidence"), nullptr);
  // An OWNER without the config scope does not see reasoning either.
  EXPECT_EQ(
      parse(n().get("/api/thoughts/th_chat_1", n().token("owner", {"status", "control"})).body)
          .get("reasoning"),
      nullptr);
  EXPECT_EQ(n().get("/api/thoughts/th_chat_1").status, 401);
  EXPECT_EQ(n().get("/api/thoughts/th_nope", n().owner()).status, 404);
  // The thought is never dispatched: the COMMAND record's applied action has no thought.
  EXPECT_EQ(json::dump(n().record(id, "COMMAND")).find("secret prompt text"), std::string::npos);
  // The CLI reads it too.
  auto cli = test::run_cli(
      {"thoughts", "get", "th_chat_1", "--url", n().url(), "--token-file", n().owner_file()});
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("secret prompt text"), std::string::npos);
  EXPECT_EQ(test::run_cli({"thoughts", "get", "th_nope", "--url", n().url(), "--token-file",
                           n().owner_file()})
                .exit_code,
            1);
}

TEST_F(AiGates, WatermarkIsInPayloadAndRecordAndVerifiesPubliclyExactlyAsTheSeedShows) {
  std::string id = new_uuid_v4();
  HttpReply r = n().command(n().leasee(), cmd(id, "teleop", {{"linear", 0.1}, {"duration_ms", 100}},
                                              ai_block("sim", "m", 0.95, "planner", "th_wm_1")));
  ASSERT_EQ(r.status, 200) << r.body;
  std::string wm = parse(r.body).get("payload")->get("watermark_token")->as_string();
  json::Value rec = n().record(id, "COMMAND");
  ASSERT_EQ(rec.get("watermark_token")->as_string(), wm);
  // The token is HMAC-SHA256(ML-DSA-65 secret key, rrn:thought_id:timestamp_iso)[0:16].
  std::string ts = rec.get("detail")->get("watermark")->get("timestamp_iso")->as_string();
  EXPECT_EQ(n().expected_watermark("th_wm_1", ts), wm);
  HttpReply v = n().get("/api/v1/watermark/verify?token=" + wm + "&rrn=" + n().rrn());
  ASSERT_EQ(v.status, 200) << v.body;
  json::Value vv = parse(v.body);
  EXPECT_TRUE(vv.get("valid")->as_bool());
  EXPECT_EQ(vv.get("rrn")->as_string(), n().rrn());
  EXPECT_EQ(vv.get("watermark_token")->as_string(), wm);
  EXPECT_EQ(vv.get("audit_entry")->get("message_id")->as_string(), id);
  EXPECT_EQ(vv.get("audit_entry")->get("hmac")->as_string(), rec.get("hmac")->as_string());
  // rrn is optional; a foreign one is not found.
  EXPECT_EQ(n().get("/api/v1/watermark/verify?token=" + wm).status, 200);
  HttpReply foreign = n().get("/api/v1/watermark/verify?token=" + wm + "&rrn=RRN-000000000999");
  EXPECT_EQ(foreign.status, 404);
  EXPECT_EQ(foreign.body,
            R"({"error":"Watermark token not found in audit log","code":"HTTP_404"})");
  HttpReply unknown =
      n().get("/api/v1/watermark/verify?token=rcan-wm-v1:0123456789abcdef0123456789abcdef&rrn=" +
              n().rrn());
  EXPECT_EQ(unknown.status, 404);
  EXPECT_EQ(unknown.body,
            R"({"error":"Watermark token not found in audit log","code":"HTTP_404"})");
  for (std::string bad : {"rcan-wm-v1:0123", "rcan-wm-v1:0123456789ABCDEF0123456789ABCDEF", "x"}) {
    HttpReply b = n().get("/api/v1/watermark/verify?token=" + bad + "&rrn=" + n().rrn());
    EXPECT_EQ(b.status, 400) << bad;
    EXPECT_EQ(b.body, R"({"error":"Invalid watermark token format","code":"HTTP_400"})");
  }
  EXPECT_EQ(n().get("/api/v1/watermark/verify?rrn=" + n().rrn()).status, 400);
  // A command without an ai block is not AI-produced: no token.
  std::string plain = new_uuid_v4();
  HttpReply pr = n().command(n().leasee(), cmd(plain, "status", {}));
  ASSERT_EQ(pr.status, 200);
  EXPECT_EQ(parse(pr.body).get("payload")->get("watermark_token"), nullptr);
  EXPECT_EQ(n().record(plain, "COMMAND").get("watermark_token"), nullptr);
}

TEST_F(AiGates, ForwardedCommandKeepsItsWatermark) {
  std::string id = new_uuid_v4();
  std::string upstream = "rcan-wm-v1:00112233445566778899aabbccddeeff";
  json::Array chain{json::Object{{"issuer_ruri", "rcan://local.rcan/acme/fleet-brain/11111111"},
                                 {"human_subject", "ops"},
                                 {"timestamp", 1}}};
  HttpReply r =
      n().command(n().leasee(), cmd(id, "status", {{"watermark_token", upstream}},
                                    ai_block("sim", "m", 0.9, "planner", "th_fwd_1"),
                                    ",\"delegation_chain\":" + json::dump(json::Value(chain))));
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(parse(r.body).get("payload")->get("watermark_token")->as_string(), upstream);
  EXPECT_EQ(n().record(id, "COMMAND").get("watermark_token")->as_string(), upstream);
  // Without a delegation chain a carried token is replaced by the robot's own.
  std::string id2 = new_uuid_v4();
  HttpReply r2 = n().command(n().leasee(), cmd(id2, "status", {{"watermark_token", upstream}},
                                               ai_block("sim", "m", 0.9, "planner", "th_fwd_2")));
  ASSERT_EQ(r2.status, 200);
  EXPECT_NE(parse(r2.body).get("payload")->get("watermark_token")->as_string(), upstream);
}

// ---------------------------------------------------------------------------------------------

TEST(AiHitlRestart, HeldCommandsSurviveARestartAndTheCliDecides) {
  test::TempDir dir;
  std::string agent =
      "agent:\n"
      "  hitl_gates:\n"
      "    - {action_types: [arm_move], require_auth: true, auth_timeout_ms: 120000, on_timeout: "
      "block, notify: [ws]}\n"
      "    - {action_types: [arm_home], require_auth: true, auth_timeout_ms: 300, on_timeout: "
      "allow}\n";
  std::string held = new_uuid_v4();
  std::string homing = new_uuid_v4();
  std::string second = new_uuid_v4();
  {
    AiNode node(dir.path(), agent);
    ASSERT_EQ(node.command(node.leasee(),
                           cmd(held, "arm_move", {{"joints", json::Array{0.1, 0, 0, 0, 0, 0}}}))
                  .status,
              202);
    ASSERT_EQ(node.command(node.leasee(),
                           cmd(second, "arm_move", {{"joints", json::Array{0.2, 0, 0, 0, 0, 0}}}))
                  .status,
              202);
    namespace fs = std::filesystem;
    std::string file = dir.path() + "/data/hitl-pending.json";
    // Held, then stop: it times out while the node is down or just after it is back.
    ASSERT_EQ(node.command(node.leasee(), cmd(homing, "arm_home", {})).status, 202);
    ASSERT_TRUE(fs::exists(file));
    EXPECT_EQ(fs::status(file).permissions() & (fs::perms::group_all | fs::perms::others_all),
              fs::perms::none);
    EXPECT_NE(test::read_file(file).find(held), std::string::npos);
    EXPECT_EQ(test::read_file(file).find("auth_token"), std::string::npos);
    EXPECT_EQ(node.terminate(), 0);
  }
  AiNode node(dir.path(), agent, /*fresh=*/false);
  // The arm_home hold is settled by its on_timeout (allow) after the restart.
  json::Value homed = node.record(homing, "COMMAND");
  ASSERT_TRUE(homed.get("hitl_timeout_bypass")) << json::dump(homed);
  EXPECT_EQ(node.record(homing, "HITL_TIMEOUT").get("outcome")->as_string(), "ok");
  auto list = test::run_cli({"pending", "--url", node.url(), "--token-file", node.owner_file()});
  EXPECT_EQ(list.exit_code, 0) << list.err;
  EXPECT_NE(list.out.find(held), std::string::npos) << list.out;
  EXPECT_NE(list.out.find("arm_move"), std::string::npos);
  auto ok = test::run_cli({"authorize", held, "--approve", "--reason", "checked", "--url",
                           node.url(), "--token-file", node.owner_file()});
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  EXPECT_EQ(node.record(held, "COMMAND").get("outcome")->as_string(), "ok");
  auto no = test::run_cli(
      {"authorize", second, "--deny", "--url", node.url(), "--token-file", node.owner_file()});
  EXPECT_EQ(no.exit_code, 0) << no.out << no.err;
  EXPECT_EQ(node.records(second, "COMMAND").size(), 0u);
  EXPECT_EQ(node.records(second, "HITL_DENIED", 1).size(), 1u);
  // A LEASEE's CLI attempt is refused (exit 1) and audited.
  auto lower = test::run_cli(
      {"authorize", second, "--approve", "--url", node.url(), "--token-file", node.leasee_file()});
  EXPECT_EQ(lower.exit_code, 1);
  EXPECT_NE(lower.out.find("INSUFFICIENT_PRIVILEGES"), std::string::npos);
  EXPECT_EQ(
      test::run_cli({"authorize", held, "--url", node.url(), "--token-file", node.owner_file()})
          .exit_code,
      2);
  auto verify = test::run_cli({"audit", "verify", "--data-dir", dir.path() + "/data",
                               "--secret-file", dir.path() + "/data/audit.secret"});
  EXPECT_EQ(verify.exit_code, 0) << verify.out << verify.err;
}

TEST(AiHitlRestart, AnUnreadablePendingFileIsMovedAsideAndAudited) {
  test::TempDir dir;
  std::string agent =
      "agent:\n  hitl_gates:\n    - {action_types: [arm_move], require_auth: true}\n";
  {
    AiNode node(dir.path(), agent);
    EXPECT_EQ(node.terminate(), 0);
  }
  std::ofstream(dir.path() + "/data/hitl-pending.json") << "{not json";
  AiNode node(dir.path(), agent, /*fresh=*/false);
  ASSERT_NE(node.port(), 0);
  bool moved = false;
  for (const auto& e : std::filesystem::directory_iterator(dir.path() + "/data"))
    moved = moved || e.path().filename().string().rfind("hitl-pending.json.unreadable-", 0) == 0;
  EXPECT_TRUE(moved);
  EXPECT_EQ(
      parse(node.get("/rcan/v1/pending", node.owner()).body).get("pending")->as_array().size(), 0u);
  // The record is written asynchronously at start-up: wait for it to be durable.
  HttpReply audit;
  for (int i = 0; i < 250; ++i) {
    audit = node.get("/api/audit?limit=100", node.owner());
    if (audit.body.find("HITL_PENDING_LOST") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_NE(audit.body.find("HITL_PENDING_LOST"), std::string::npos);
}

TEST(AiLayers, AFailingOrSlowLayerBlocksWithoutHoldingThePipeline) {
  test::TempDir dir;
  SimLayerProc slow("planner", 0.99, /*delay_ms=*/5000);
  std::string agent =
      "agent:\n"
      "  confidence_gates:\n"
      "    - {scope: nav, min_confidence: 0.8, on_fail: escalate}\n"
      "  layers:\n"
      "    fast: {url: \"http://127.0.0.1:1/\", timeout_ms: 500}\n"
      "    planner: {url: \"" +
      slow.url() + "\", timeout_ms: 2500}\n";
  AiNode node(dir.path(), agent);
  HttpReply dead = node.command(node.leasee(),
                                cmd(new_uuid_v4(), "move", {{"linear", 0.1}, {"duration_ms", 100}},
                                    ai_block("sim", "m", 0.2, "reactive")));
  EXPECT_EQ(dead.status, 403) << dead.body;
  EXPECT_EQ(parse(dead.body).get("payload")->get("reason")->as_string(), "escalation_failed");
  // The slow planner times out; meanwhile the node keeps answering.
  std::atomic<bool> slow_done{false};
  HttpReply slow_reply;
  std::string slow_id = new_uuid_v4();
  std::thread t([&] {
    slow_reply =
        node.command(node.leasee(), cmd(slow_id, "move", {{"linear", 0.1}, {"duration_ms", 100}},
                                        ai_block("sim", "m", 0.2, "fast")));
    slow_done = true;
  });
  // Wait until the layer has the request, then show other commands still flow.
  for (int i = 0; i < 200 && slow.requests_seen() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_EQ(slow.requests_seen(), 1);
  for (int i = 0; i < 3; ++i) {
    HttpReply quick = node.command(node.leasee(), cmd(new_uuid_v4(), "status", {}));
    EXPECT_EQ(quick.status, 200);
  }
  EXPECT_FALSE(slow_done.load())
      << "the escalation finished before the other commands: nothing was shown";
  t.join();
  EXPECT_EQ(slow_reply.status, 403) << slow_reply.body;
  EXPECT_EQ(parse(slow_reply.body).get("payload")->get("reason")->as_string(), "escalation_failed");
  EXPECT_EQ(node.records(slow_id, "COMMAND").size(), 0u);
}

}  // namespace
}  // namespace rcan
