// The L2 and L3 cases of the RCAN conformance suite v1.3 (tests/vectors/
// rcan-conformance-v1.3.json) run against a real rcand. Inputs come from the vector file.
// Where a case contradicts the §16 seed, the seed wins and the test says so:
//   * L2-CONF-001 expects error_code COMMAND_REJECTED; seed §16.3 says the ERROR code is
//     CONFIDENCE_GATE_FAIL (the case's reason, confidence_below_gate, is kept).
//   * L2-CONF-002 expects escalate → a HiTL queue; seed §16.3 says escalate → the next higher
//     brain layer, and with none it is a block.
//   * L3-HITL-001 lets LEASEE authorize; seed §16.4 allows only OWNER and CREATOR, so that
//     configuration is refused at start-up. Its principal is USER, who may not move the arm
//     at all (PROFILE §5); the hold is shown with a LEASEE sender.
//   * L3-HITL-002 expects outcome SUCCESS; the seed's §6 vocabulary is ok | blocked | error.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <set>

#include "ai_test_support.h"
#include "rcan/actions.h"
#include "rcan/roles.h"

namespace rcan {
namespace {

using test::HttpReply;
using namespace ai_test;

const json::Value& conformance_case(const std::string& id) {
  static const json::Value suite = test::load_vector("rcan-conformance-v1.3.json");
  for (const char* level : {"L2", "L3"})
    for (const auto& c : suite.get("levels")->get(level)->as_array())
      if (c.get("id")->as_string() == id) return c;
  static const json::Value none;
  ADD_FAILURE() << "no case " << id;
  return none;
}

const json::Value& in(const json::Value& c, const char* k) { return *c.get("input")->get(k); }
const json::Value& expect(const json::Value& c, const char* k) { return *c.get("expect")->get(k); }

// The capability name a conformance case's action addresses (the gate's scope).
std::string capability_of(const std::string& action) {
  const ActionSpec* a = find_action(action);
  if (!a) {
    ADD_FAILURE() << "no action " << action;
    return "teleop";
  }
  return std::string(capability_name(a->capability));
}

std::string gate_yaml(const std::string& scope, double min, const std::string& on_fail) {
  return "agent:\n  confidence_gates:\n    - {scope: " + scope +
         ", min_confidence: " + json::dump(json::Value(min)) + ", on_fail: " + on_fail + "}\n";
}

TEST(Conformance, EveryL2AndL3CaseIsAccountedFor) {
  // Where each case runs. §21 registry cases are rcan-registry's (tests/registry); INVOKE_RESULT
  // is a message this node sends no skill results in (a skill runs as a COMMAND and is ACKed).
  const std::map<std::string, std::string> where{{"L2-SAFE-001", "here"},
                                                 {"L2-INJECT-001", "here"},
                                                 {"L2-HMAC-001", "here"},
                                                 {"L2-CONF-001", "here"},
                                                 {"L2-CONF-002", "here"},
                                                 {"L2-SAFE-002", "rcand_test RcandDeadman"},
                                                 {"L2-INVOKE-001", "here"},
                                                 {"L3-AI-001", "here"},
                                                 {"L3-HITL-001", "here"},
                                                 {"L3-HITL-002", "here"},
                                                 {"L3-THOUGHT-001", "here"},
                                                 {"L3-CHAIN-001", "here"},
                                                 {"L3-AI-002", "here"},
                                                 {"L3-REGISTRY-001", "not implemented (§21)"},
                                                 {"L3-REGISTRY-002", "not implemented (§21)"},
                                                 {"L3-INVOKE-001", "no INVOKE_RESULT (§19)"}};
  json::Value suite = test::load_vector("rcan-conformance-v1.3.json");
  size_t n = 0;
  for (const char* level : {"L2", "L3"})
    for (const auto& c : suite.get("levels")->get(level)->as_array()) {
      ++n;
      EXPECT_TRUE(where.count(c.get("id")->as_string()))
          << "unaccounted case " << c.get("id")->as_string();
    }
  EXPECT_EQ(n, where.size());
}

TEST(Conformance, L2_CONF_001_BlockGate) {
  const json::Value& c = conformance_case("L2-CONF-001");
  const json::Value& gate = in(c, "confidence_gate");
  const json::Value& ai_cmd = in(c, "ai_command");
  std::string action = ai_cmd.get("action")->as_string();
  std::string scope = capability_of(action);  // pick_object: the arm capability (rcan/actions.h)
  test::TempDir dir;
  AiNode n(dir.path(), gate_yaml(scope, gate.get("min_confidence")->to_double(),
                                 gate.get("on_fail")->as_string()));
  std::string id = new_uuid_v4();
  HttpReply r = n.command(
      n.leasee(),
      cmd(id, action, {}, ai_block("sim", "m", ai_cmd.get("confidence")->to_double(), "fast")));
  EXPECT_FALSE(expect(c, "dispatched").as_bool());
  EXPECT_EQ(r.status, 403) << r.body;
  EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
  // Seed §16.3 wins over the case's COMMAND_REJECTED.
  EXPECT_EQ(error_code(r), "CONFIDENCE_GATE_FAIL");
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(),
            expect(c, "reason").as_string());
}

TEST(Conformance, L2_CONF_002_EscalateGoesToTheNextLayerNotAQueue) {
  const json::Value& c = conformance_case("L2-CONF-002");
  const json::Value& gate = in(c, "confidence_gate");
  const json::Value& ai_cmd = in(c, "ai_command");
  std::string action = ai_cmd.get("action")->as_string();
  std::string scope = capability_of(action);
  double conf = ai_cmd.get("confidence")->to_double();
  {
    // No higher layer: not dispatched (the case's "dispatched": false), blocked per the seed.
    test::TempDir dir;
    AiNode n(dir.path(), gate_yaml(scope, gate.get("min_confidence")->to_double(),
                                   gate.get("on_fail")->as_string()));
    std::string id = new_uuid_v4();
    HttpReply r = n.command(n.leasee(), cmd(id, action, {}, ai_block("sim", "m", conf, "fast")));
    EXPECT_EQ(expect(c, "dispatched").as_bool(), false);
    EXPECT_EQ(r.status, 403) << r.body;
    EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
    EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(), "no_higher_layer");
  }
  // With a planner layer: escalated (the case's "escalated": true) and, passing, dispatched.
  SimLayerProc planner("planner", 0.9);
  test::TempDir dir;
  AiNode n(
      dir.path(),
      gate_yaml(scope, gate.get("min_confidence")->to_double(), gate.get("on_fail")->as_string()) +
          "  layers:\n    planner: {url: \"" + planner.url() + "\", timeout_ms: 3000}\n");
  std::string id = new_uuid_v4();
  HttpReply r = n.command(n.leasee(), cmd(id, action, {}, ai_block("sim", "m", conf, "fast")));
  EXPECT_EQ(n.record(id, "CONFIDENCE_GATE_ESCALATED").get("reason")->as_string(),
            expect(c, "reason").as_string());
  // The planner's command (escalated: true) passed the gate and reached the robot, which has
  // no pick_object skill: the dispatcher refuses it as unsupported_action, naming the escalation.
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(), "unsupported_action")
      << r.body;
  json::Value rec = n.record(id, "COMMAND_REJECTED");
  ASSERT_TRUE(rec.get("ai")) << json::dump(rec);
  EXPECT_EQ(rec.get("ai")->get("escalated")->as_bool(), expect(c, "escalated").as_bool());
  EXPECT_EQ(rec.get("ai")->get("layer")->as_string(), "planner");
}

TEST(Conformance, L3_AI_001_AuditCarriesProviderModelConfidence) {
  const json::Value& c = conformance_case("L3-AI-001");
  const json::Value& meta = in(c, "ai_metadata");
  json::Object payload = in(c, "payload").as_object();
  std::string action = payload.find("action")->as_string();
  payload.erase("action");
  test::TempDir dir;
  AiNode n(dir.path(), "");
  std::string id = new_uuid_v4();
  json::Object ai = meta.as_object();
  ai.set("escalated", false);
  HttpReply r = n.command(n.leasee(), cmd(id, action, payload, ai));
  // The simulated robot cannot follow waypoints (a drive needs linear/angular): the command is
  // refused at dispatch, and that record carries the ai block all the same.
  json::Value rec = n.record(id, r.status == 200 ? "COMMAND" : "COMMAND_REJECTED");
  for (const auto& [path, want] : expect(c, "audit_entry_contains_nested").as_object()) {
    const json::Value* got = rec.get("ai") ? rec.get("ai")->get(path.substr(3)) : nullptr;
    ASSERT_TRUE(got) << path;
    EXPECT_EQ(*got, want) << path;
  }
}

TEST(Conformance, L3_AI_002_MissingModelIsRefused) {
  const json::Value& c = conformance_case("L3-AI-002");
  json::Object payload = in(c, "payload").as_object();
  std::string action = payload.find("action")->as_string();
  test::TempDir dir;
  AiNode n(dir.path(), "");
  std::string id = new_uuid_v4();
  HttpReply r = n.command(n.leasee(), cmd(id, action, {}, in(c, "ai_metadata").as_object()));
  EXPECT_EQ(r.status, 400) << r.body;
  json::Value p = *parse(r.body).get("payload");
  EXPECT_EQ(p.get("error_code")->as_string(), "SCHEMA_VALIDATION_FAILED");
  EXPECT_EQ(p.get("detail")->get("reason")->as_string(), expect(c, "error_code").as_string());
  EXPECT_EQ(p.get("detail")->get("field")->as_string(), expect(c, "missing_field").as_string());
  EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
}

TEST(Conformance, L3_HITL_001_GateHoldsTheCommand) {
  const json::Value& c = conformance_case("L3-HITL-001");
  const json::Value& g = in(c, "hitl_gates_config").as_array()[0];
  std::string action_type = g.get("action_type")->as_string();
  auto yaml = [&](const std::string& roles) {
    return "agent:\n  hitl_gates:\n    - {action_type: " + action_type +
           ", require_auth: " + (g.get("require_auth")->as_bool() ? "true" : "false") +
           ", authorized_roles: [" + roles + "]}\n";
  };
  test::TempDir dir;
  {
    // The case's LEASEE in authorized_roles contradicts seed §16.4: start-up refuses it.
    AiNode refused(dir.path(), yaml("OWNER, LEASEE"), true, /*expect_start=*/false);
    EXPECT_EQ(refused.exit_code(), 1);
    EXPECT_NE(refused.log().find("authorized_roles"), std::string::npos) << refused.log();
  }
  test::TempDir dir2;
  AiNode n(dir2.path(), yaml("OWNER"));
  std::string id = new_uuid_v4();
  json::Object payload = in(c, "payload").as_object();
  payload.erase("action");
  HttpReply r = n.command(n.leasee(), cmd(id, action_type, payload));
  EXPECT_EQ(r.status, 202) << r.body;
  EXPECT_FALSE(expect(c, "dispatched").as_bool());
  EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
  json::Value p = *parse(r.body).get("payload");
  EXPECT_EQ(p.get("queue_status")->as_string(), expect(c, "queue_status").as_string());
  EXPECT_TRUE(expect(c, "queued_for_hitl").as_bool());
  EXPECT_EQ(parse(n.get("/rcan/v1/pending", n.owner()).body).get("pending")->as_array().size(), 1u);
}

TEST(Conformance, L3_HITL_002_OwnerApprovesGuestIsRefused) {
  const json::Value& c = conformance_case("L3-HITL-002");
  test::TempDir dir;
  AiNode n(dir.path(),
           "agent:\n  hitl_gates:\n    - {action_types: [arm_move], require_auth: true}\n");
  std::string id = new_uuid_v4();
  ASSERT_EQ(
      n.command(n.leasee(), cmd(id, "arm_move", {{"joints", json::Array{0.1, 0, 0, 0, 0, 0}}}))
          .status,
      202);
  for (const auto& attempt : in(c, "authorize_attempts").as_array()) {
    std::string role = attempt.get("principal_role")->as_string();
    for (auto& ch : role) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (attempt.get("expected_result")->as_string() != "rejected") continue;
    HttpReply r = n.authorize(n.token(role, {"status"}), id, "approve");
    EXPECT_EQ(r.status, 403) << r.body;
    EXPECT_EQ(error_code(r), expect(c, "guest_authorize").get("error_code")->as_string());
    EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);  // guest_authorize.dispatched: false
  }
  HttpReply ok = n.authorize(n.owner(), id, "approve");
  ASSERT_EQ(ok.status, 200) << ok.body;
  EXPECT_TRUE(expect(c, "owner_authorize").get("dispatched")->as_bool());
  // SUCCESS in the case; "ok" in the seed's §6 vocabulary.
  EXPECT_EQ(n.record(id, "COMMAND").get("outcome")->as_string(), "ok");
  EXPECT_EQ(n.records(id, "HITL_AUTHORIZE_REFUSED", 1).size(), 1u);
}

TEST(Conformance, L3_THOUGHT_001_ReasoningNeedsConfigScope) {
  const json::Value& c = conformance_case("L3-THOUGHT-001");
  std::string tid = in(c, "thought_id").as_string();
  test::TempDir dir;
  AiNode n(dir.path(), "");
  json::Object thought{{"reasoning", "private chain of thought"}};
  ASSERT_EQ(n.command(n.leasee(),
                      cmd(new_uuid_v4(), "status", {}, ai_block("sim", "m", 0.8, "planner", tid),
                          ",\"thought\":" + json::dump(json::Value(thought))))
                .status,
            200);
  const json::Value& who = in(c, "requesting_principal");
  std::string role = who.get("role")->as_string();
  for (auto& ch : role) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  std::vector<std::string> scopes;
  for (const auto& s : who.get("scopes")->as_array()) scopes.push_back(s.as_string());
  HttpReply r = n.get("/api/thoughts/" + tid, n.token(role, scopes));
  EXPECT_EQ(r.status, expect(c, "http_status").as_int()) << r.body;
  json::Value v = parse(r.body);
  for (const auto& k : expect(c, "response_contains").as_array())
    EXPECT_NE(v.get(k.as_string()), nullptr) << k.as_string();
  for (const auto& k : expect(c, "response_excludes").as_array())
    EXPECT_EQ(v.get(k.as_string()), nullptr) << k.as_string();
}

TEST(Conformance, L2_SAFE_001_EstopRejectsCommands) {
  const json::Value& c = conformance_case("L2-SAFE-001");
  test::TempDir dir;
  AiNode n(dir.path(), "");
  ASSERT_TRUE(in(c, "device_state").get("estop_active")->as_bool());
  ASSERT_EQ(n.post("/api/stop", "{}", n.owner()).status, 200);
  json::Object payload = in(c, "payload").as_object();
  std::string action = payload.find("action")->as_string();
  payload.erase("action");
  std::string id = new_uuid_v4();
  HttpReply r = n.command(n.leasee(), cmd(id, action, payload));
  EXPECT_EQ(error_code(r), expect(c, "error_code").as_string()) << r.body;
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(),
            expect(c, "reason").as_string());
  EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
}

TEST(Conformance, L2_INVOKE_001_EstopRejectsInvoke) {
  const json::Value& c = conformance_case("L2-INVOKE-001");
  test::TempDir dir;
  AiNode n(dir.path(), "");
  ASSERT_TRUE(in(c, "device_state").get("estop_active")->as_bool());
  ASSERT_EQ(n.post("/api/stop", "{}", n.owner()).status, 200);
  // The suite's INVOKE (payload skill_id + args) by a USER, naming the simulator's own skill
  // (the suite's navigate.to_waypoint is no skill of the simulator: it is not found at all).
  json::Object payload = in(c, "payload").as_object();
  payload.set("skill_id", "scan_environment");
  const std::string token = n.token("user", {"status", "control"});
  auto invoke = [&](const std::string& id, const json::Object& p) {
    return json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                               {"message_id", id},
                                               {"type", "INVOKE"},
                                               {"timestamp_ms", wall_ms()},
                                               {"payload", p}}));
  };
  std::string id = new_uuid_v4();
  HttpReply r = n.command(token, invoke(id, payload));
  EXPECT_EQ(r.status, 423) << r.body;
  EXPECT_EQ(error_code(r), expect(c, "error_code").as_string()) << r.body;
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(),
            expect(c, "reason").as_string());
  EXPECT_FALSE(expect(c, "dispatched").as_bool());
  EXPECT_EQ(n.records(id, "COMMAND").size(), 0u);
  // The suite's own skill: refused, not found (nothing to dispatch either).
  std::string other = new_uuid_v4();
  HttpReply nf = n.command(token, invoke(other, in(c, "payload").as_object()));
  EXPECT_EQ(nf.status, 404) << nf.body;
  EXPECT_EQ(parse(nf.body).get("payload")->get("detail")->get("field")->as_string(),
            "payload.skill_id");
  EXPECT_EQ(n.records(other, "COMMAND").size(), 0u);
  // Released, the same INVOKE runs; args that are no object are a schema error.
  HttpReply resumed = n.command(
      n.owner(),
      json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                          {"message_id", new_uuid_v4()},
                                          {"type", "SAFETY"},
                                          {"timestamp_ms", wall_ms()},
                                          {"payload", json::Object{{"safety_event", "RESUME"}}}})));
  ASSERT_EQ(resumed.status, 200) << resumed.body;
  HttpReply ok = n.command(token, invoke(new_uuid_v4(), payload));
  EXPECT_EQ(ok.status, 200) << ok.body;
  payload.set("args", "dock-01");
  HttpReply bad = n.command(token, invoke(new_uuid_v4(), payload));
  EXPECT_EQ(bad.status, 400) << bad.body;
  EXPECT_EQ(parse(bad.body).get("payload")->get("detail")->get("field")->as_string(),
            "payload.args");
}

TEST(Conformance, L2_INJECT_001_InjectionIsBlockedAndAudited) {
  const json::Value& c = conformance_case("L2-INJECT-001");
  test::TempDir dir;
  AiNode n(dir.path(), "");
  json::Object payload = in(c, "payload").as_object();  // {instruction}; a chat carries it
  std::string id = new_uuid_v4();
  HttpReply r = n.command(n.token("user", {"status", "chat", "control"}), cmd(id, "chat", payload));
  EXPECT_EQ(error_code(r), expect(c, "error_code").as_string()) << r.body;
  EXPECT_EQ(parse(r.body).get("payload")->get("reason")->as_string(),
            expect(c, "reason").as_string());
  EXPECT_EQ(n.record(id, expect(c, "audit_event").as_string()).get("outcome")->as_string(),
            "blocked");
}

TEST(Conformance, L3_CHAIN_001_And_L2_HMAC_001_ExportVerifiesOfflineAndTamperingIsFound) {
  const json::Value& chain = conformance_case("L3-CHAIN-001");
  const json::Value& hmac = conformance_case("L2-HMAC-001");
  test::TempDir dir;
  AiNode n(dir.path(), "");
  for (int i = 0; i < 3; ++i)
    ASSERT_EQ(n.command(n.leasee(), cmd(new_uuid_v4(), "status", {})).status, 200);
  HttpReply exp =
      n.get("/api/v1/audit?format=" + in(chain, "export_format").as_string(), n.owner());
  ASSERT_EQ(exp.status, 200);
  std::string file = dir.file("export.jsonl");
  std::ofstream(file) << exp.body;
  auto ok =
      test::run_cli({"audit", "verify", file, "--secret-file", dir.path() + "/data/audit.secret"});
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;  // chain_valid: true, no network
  EXPECT_TRUE(expect(chain, "chain_valid").as_bool());
  // Tamper the field the L2-HMAC-001 case names in the record at its seq.
  std::string field = in(hmac, "tamper").get("field")->as_string();
  int64_t seq = in(hmac, "tamper").get("record_seq")->as_int();
  std::string tampered, line;
  std::istringstream lines(exp.body);
  while (std::getline(lines, line)) {
    json::Value v = parse(line);
    if (v.get("seq")->as_int() == seq)
      v.as_object().set(field, in(hmac, "tamper").get("new_value")->as_string());
    tampered += json::canonical(v) + "\n";
  }
  std::ofstream(dir.file("tampered.jsonl")) << tampered;
  auto bad = test::run_cli({"audit", "verify", dir.file("tampered.jsonl"), "--secret-file",
                            dir.path() + "/data/audit.secret"});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_FALSE(expect(hmac, "chain_valid").as_bool());
  EXPECT_NE(
      (bad.out + bad.err).find("seq " + std::to_string(expect(hmac, "first_invalid_seq").as_int())),
      std::string::npos)
      << bad.out << bad.err;
}

}  // namespace
}  // namespace rcan
