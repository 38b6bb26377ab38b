// The message codec: both input shapes, normalisation to the seed shape, strict validation.
#include "rcan/message.h"

#include <gtest/gtest.h>

#include "rcan/errors.h"
#include "test_support.h"

namespace rcan {
namespace {

constexpr const char* kId = "0b0a6d4e-5f3c-4a2b-9c1d-2e3f4a5b6c7d";

std::string seed_msg(const std::string& extra = "",
                     const std::string& payload = R"({"action":"move","linear":0.3})") {
  return std::string(R"({"version":"1.0.0","message_id":")") + kId +
         R"(","source_ruri":"rcan://local.rcan/acme/app/12345678","target_ruri":"rcan://local.rcan/acme/rover/abcdef12",)"
         R"("type":"COMMAND","payload":)" +
         payload + R"(,"timestamp_ms":1740721482934,"ttl_ms":30000,"priority":"NORMAL")" + extra +
         "}";
}

Error decode_error(const std::string& body) {
  auto m = parse_message(body);
  EXPECT_FALSE(m.ok()) << body;
  return m.ok() ? Error() : m.error();
}

TEST(MessageCodec, SeedShapeRoundTrip) {
  auto m = parse_message(seed_msg(R"(,"scope":["control"],"auth_token":"tok","reply_to":"x")"));
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->shape, WireShape::kSeed);
  EXPECT_EQ(m->type, MessageType::kCommand);
  EXPECT_EQ(m->priority, Priority::kNormal);
  EXPECT_EQ(m->message_id, kId);
  EXPECT_EQ(m->timestamp_ms, 1740721482934);
  EXPECT_EQ(m->ttl_ms, 30000);
  EXPECT_EQ(m->action(), "move");
  EXPECT_EQ(m->scope, std::vector<std::string>{"control"});
  EXPECT_EQ(m->sender_type, SenderType::kHuman);
  EXPECT_FALSE(m->sender_type_explicit);
  json::Value enc = encode_message(*m);
  auto again = decode_message(enc);
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(json::dump(encode_message(*again)), json::dump(enc));
  EXPECT_EQ(enc.get("type")->as_string(), "COMMAND");
  EXPECT_EQ(enc.get("priority")->as_string(), "NORMAL");
  EXPECT_EQ(enc.get("sender_type")->as_string(), "human");
  EXPECT_EQ(enc.get("auth_token")->as_string(), "tok");
  EXPECT_EQ(encode_message(*m, EncodeOptions{false}).get("auth_token"), nullptr);
}

TEST(MessageCodec, ReferenceClientShapeWithMessageTypeKey) {
  std::string body =
      std::string(R"({"version":"1.0.0","message_id":")") + kId +
      R"(","message_type":"STATUS","payload":{},"timestamp_ms":1740000000000,"priority":"LOW"})";
  auto m = parse_message(body);
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->type, MessageType::kStatus);
  EXPECT_EQ(m->priority, Priority::kLow);
}

TEST(MessageCodec, NumericTypesOnlyUnderAnExplicitSeedVersion) {
  std::string base =
      std::string(R"({"message_id":")") + kId + R"(","payload":{},"timestamp_ms":1740000000000,)";
  auto ok = parse_message(base + R"("version":"1.0.0","type":2,"priority":3})");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->type, MessageType::kCommand);
  EXPECT_EQ(ok->priority, Priority::kSafety);
  EXPECT_EQ(decode_error(base + R"("version":"1.2","type":2})").field, "type");
  EXPECT_EQ(decode_error(base + R"("type":2})").field, "type");
  EXPECT_EQ(decode_error(base + R"("version":"1.0.0","type":8})").field, "type");
  EXPECT_EQ(decode_error(base + R"("version":"1.0.0","type":"COMMAND","priority":9})").field,
            "priority");
}

TEST(MessageCodec, RcanPyShapeNormalisesToACommand) {
  json::Value v = test::load_vector("python-json-preimage.json");
  for (const auto& c : v.get("cases")->as_array()) {
    SCOPED_TRACE(c.get("name")->as_string());
    auto m = parse_message(c.get("signed_wire_json")->as_string());
    ASSERT_TRUE(m.ok()) << m.error().message;
    EXPECT_EQ(m->shape, WireShape::kRcanPy);
    EXPECT_EQ(m->type, MessageType::kCommand);
    auto wire = json::parse(c.get("wire_json")->as_string());
    ASSERT_TRUE(wire.ok());
    EXPECT_EQ(m->action(), wire->get("cmd")->as_string());
    EXPECT_EQ(m->message_id, wire->get("msg_id")->as_string());
    ASSERT_TRUE(m->sig.has_value());
    EXPECT_EQ(m->sig->alg, "ml-dsa-65");
    EXPECT_EQ(m->sig->kid, "d666806e");
    // The wire object is kept for signature pre-images.
    EXPECT_EQ(*m->wire.find("msg_id"), *wire->get("msg_id"));
  }
}

// decode_message(json::Value&&) keeps the received object itself as the wire object: the same
// message as from a copy; a message that does not decode leaves the value as it was.
TEST(MessageCodec, DecodingFromAMovedValueGivesTheSameMessageAndKeepsARefusedOne) {
  const std::string text = std::string(R"({"rcan":"3.2","msg_id":")") + kId +
                           R"(","timestamp":1740721482.934,"cmd":"move_forward",)"
                           R"("target":"rcan://local.rcan/acme/rover/abcdef12","params":{"d":1}})";
  auto v = json::parse(text);
  ASSERT_TRUE(v.ok());
  const json::Value original = *v;
  auto copied = decode_message(original);
  auto moved = decode_message(std::move(*v));
  ASSERT_TRUE(copied.ok() && moved.ok());
  EXPECT_EQ(json::Value(moved->wire), original);
  EXPECT_EQ(json::Value(moved->wire), json::Value(copied->wire));
  EXPECT_EQ(moved->message_id, copied->message_id);
  EXPECT_EQ(moved->action(), "move_forward");

  auto bad = json::parse(R"({"rcan":"3.2","msg_id":"x y","timestamp":1,"cmd":"stop"})");
  ASSERT_TRUE(bad.ok());
  const json::Value before = *bad;
  EXPECT_FALSE(decode_message(std::move(*bad)).ok());
  EXPECT_EQ(*bad, before);  // NOLINT(bugprone-use-after-move): unchanged on failure
}

TEST(MessageCodec, RcanPyTimestampSecondsBecomeMilliseconds) {
  auto m = parse_message(
      std::string(R"({"rcan":"3.2","msg_id":")") + kId +
      R"(","timestamp":1740721482.934,"cmd":"move_forward","target":"rcan://local.rcan/acme/rover/abcdef12","params":{"distance_m":1.5},"confidence":0.87})");
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->timestamp_ms, 1740721482934);
  EXPECT_EQ(*m->confidence, 0.87);
  EXPECT_EQ(m->payload.find("distance_m")->as_double(), 1.5);
  EXPECT_EQ(m->target_ruri, "rcan://local.rcan/acme/rover/abcdef12");
}

// rcan-ts 3.4.2 RCANMessage.toJSONString(): camelCase rcanVersion, ISO timestamp, no msg_id.
constexpr const char* kTsMsg =
    R"({"rcan":"3.2","rcanVersion":"3.2","cmd":"move","target":"rcan://local.rcan/acme/rover/v1/0a1b2c3d",)"
    R"("timestamp":"2025-02-28T05:44:42.934Z","params":{"linear":0.1,"duration_ms":100}})";

std::string ts_with(const std::string& from, const std::string& to) {
  std::string s = kTsMsg;
  size_t at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? s : s.replace(at, from.size(), to);
}

TEST(MessageCodec, RcanTsShapeIsReadWithADerivedReplayIdentity) {
  auto m = parse_message(kTsMsg);
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->shape, WireShape::kRcanTs);
  EXPECT_EQ(m->type, MessageType::kCommand);
  EXPECT_EQ(m->action(), "move");
  EXPECT_EQ(m->timestamp_ms, 1740721482934);
  EXPECT_EQ(m->target_ruri, "rcan://local.rcan/acme/rover/v1/0a1b2c3d");
  ASSERT_EQ(m->message_id.size(), 35u) << m->message_id;  // "ts-" + 32 hex
  EXPECT_EQ(m->message_id.substr(0, 3), "ts-");
  // The same signed content is the same message: unsigned fields, a signature block or a
  // msg_id do not change the identity; a signed field or the timestamp does.
  auto same = [&](const std::string& body) {
    auto o = parse_message(body);
    EXPECT_TRUE(o.ok()) << body << (o.ok() ? "" : o.error().message);
    return o.ok() && o->message_id == m->message_id;
  };
  EXPECT_TRUE(same(ts_with(R"("params")", R"("confidence":0.5,"params")")));
  EXPECT_TRUE(same(ts_with(R"("params")", R"("msg_id":"other","params")")));
  EXPECT_TRUE(same(ts_with(
      R"("params")", R"("signature":{"alg":"ml-dsa-65","kid":"0011aabb","sig":"AA"},"params")")));
  EXPECT_FALSE(same(ts_with("42.934Z", "42.935Z")));
  EXPECT_FALSE(same(ts_with(R"("linear":0.1)", R"("linear":0.2)")));
  EXPECT_FALSE(same(ts_with(R"("cmd":"move")", R"("cmd":"rotate")")));
  // An offset is read; an absent params is {} (rcan-ts omits an empty one).
  auto off = parse_message(ts_with("05:44:42.934Z", "07:44:42.934+02:00"));
  ASSERT_TRUE(off.ok()) << off.error().message;
  EXPECT_EQ(off->timestamp_ms, 1740721482934);
  EXPECT_TRUE(parse_message(ts_with(R"(,"params":{"linear":0.1,"duration_ms":100})", "")).ok());
}

TEST(MessageCodec, RcanTsCamelCaseSenderFieldsAreRead) {
  // rcan-ts writes senderType, cloudProvider and delegationChain; they mean what rcan-py's
  // snake_case members mean (a robot sender still needs a delegation chain).
  auto robot = parse_message(ts_with(
      R"("params")",
      R"("senderType":"robot","delegationChain":[{"issuerRuri":"rcan://a/b/c/d","scope":"control"}],"params")"));
  ASSERT_TRUE(robot.ok()) << robot.error().message;
  EXPECT_EQ(robot->sender_type, SenderType::kRobot);
  EXPECT_TRUE(robot->sender_type_explicit);
  ASSERT_TRUE(robot->delegation_chain.is_array());
  EXPECT_EQ(robot->delegation_chain.as_array().size(), 1u);
  auto no_chain = parse_message(ts_with(R"("params")", R"("senderType":"robot","params")"));
  ASSERT_FALSE(no_chain.ok());
  EXPECT_EQ(no_chain.error().code, ErrorCode::kMissingDelegationChain);
  auto bad = parse_message(ts_with(R"("params")", R"("senderType":"wizard","params")"));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().field, "senderType");
  auto bad_chain = parse_message(ts_with(R"("params")", R"("delegationChain":{},"params")"));
  ASSERT_FALSE(bad_chain.ok());
  EXPECT_EQ(bad_chain.error().field, "delegationChain");
  auto cloud = parse_message(
      ts_with(R"("params")", R"("senderType":"cloud_function","cloudProvider":"aws","params")"));
  ASSERT_FALSE(cloud.ok());  // rcan-ts has no functionName: a cloud function is not complete
  EXPECT_EQ(cloud.error().field, "function_name");
  // The snake_case member wins where a message carries both.
  auto both = parse_message(
      ts_with(R"("params")", R"("sender_type":"human","senderType":"robot","params")"));
  ASSERT_TRUE(both.ok()) << both.error().message;
  EXPECT_EQ(both->sender_type, SenderType::kHuman);
}

TEST(MessageCodec, InvokeInEveryShape) {
  // Seed shape: the type name round-trips.
  auto seed = parse_message(seed_msg("", R"({"skill":"scan_environment"})")
                                .replace(seed_msg().find("COMMAND"), 7, "INVOKE"));
  ASSERT_TRUE(seed.ok()) << seed.error().message;
  EXPECT_EQ(seed->type, MessageType::kInvoke);
  EXPECT_EQ(message_type_name(seed->type), "INVOKE");
  // SDK shapes: `type` 11 or "INVOKE" asks for a skill; anything else is ignored.
  auto ts = parse_message(ts_with(R"("cmd":"move")", R"("type":11,"cmd":"scan_environment")"));
  ASSERT_TRUE(ts.ok()) << ts.error().message;
  EXPECT_EQ(ts->type, MessageType::kInvoke);
  EXPECT_EQ(ts->action(), "scan_environment");
  auto named = parse_message(ts_with(R"("cmd":"move")", R"("type":"INVOKE","cmd":"dock")"));
  ASSERT_TRUE(named.ok());
  EXPECT_EQ(named->type, MessageType::kInvoke);
  for (const char* other : {R"("type":1,)", R"("type":"COMMAND",)", R"("type":[11],)"}) {
    auto m = parse_message(ts_with(R"("cmd")", std::string(other) + R"("cmd")"));
    ASSERT_TRUE(m.ok()) << other;
    EXPECT_EQ(m->type, MessageType::kCommand) << other;
  }
}

TEST(MessageCodec, RcanTsBadTimestampsAreSchemaErrors) {
  for (const char* bad : {"2025-02-28 05:44:42Z", "2025-02-28T05:44:42", "2025-13-28T05:44:42Z",
                          "2025-02-28T05:44:42.Z", "2025-02-28T25:44:42Z", "yesterday",
                          "2025-02-28T05:44:42.1234567890Z", "1969-12-31T23:59:59Z"}) {
    Error e = decode_error(ts_with("2025-02-28T05:44:42.934Z", bad));
    EXPECT_EQ(e.code, ErrorCode::kSchemaValidationFailed) << bad;
    EXPECT_EQ(e.field, "timestamp") << bad;
  }
  // rcan-py's shape still needs its msg_id.
  Error e = decode_error(ts_with(R"("2025-02-28T05:44:42.934Z")", "1740721482.934"));
  EXPECT_EQ(e.field, "msg_id");
}

TEST(MessageCodec, AiBlockAtTopLevelOrInPayloadConfidenceNeverDefaulted) {
  auto m = parse_message(seed_msg(
      R"(,"ai":{"provider":"anthropic","model":"claude-sonnet-4-6","layer":"planner","thought_id":"th_1"})"));
  ASSERT_TRUE(m.ok()) << m.error().message;
  ASSERT_TRUE(m->ai.has_value());
  EXPECT_FALSE(m->ai->confidence.has_value());
  json::Value ai = m->ai->to_json();
  EXPECT_EQ(ai.get("confidence"), nullptr);
  EXPECT_EQ(ai.get("escalated")->as_bool(), false);
  auto p = parse_message(seed_msg(
      "", R"({"action":"move","ai":{"provider":"openai","model":"gpt-4o","confidence":0.91}})"));
  ASSERT_TRUE(p.ok()) << p.error().message;
  ASSERT_TRUE(p->ai.has_value());
  EXPECT_EQ(*p->ai->confidence, 0.91);
  // Both places at once is ambiguous.
  EXPECT_EQ(decode_error(seed_msg(R"(,"ai":{"provider":"a","model":"b"})",
                                  R"({"ai":{"provider":"a","model":"b"}})"))
                .field,
            "ai");
}

TEST(MessageCodec, AiBlockMissingAMustFieldIsAuditIncomplete) {
  Error e = decode_error(seed_msg(R"(,"ai":{"provider":"anthropic","confidence":0.88})"));
  EXPECT_EQ(e.code, ErrorCode::kSchemaValidationFailed);
  EXPECT_EQ(e.field, "ai.model");
  EXPECT_EQ(e.reason, "AUDIT_INCOMPLETE_AI_IDENTITY");
  e = decode_error(seed_msg(R"(,"ai":{"provider":"","model":"m"})"));
  EXPECT_EQ(e.field, "ai.provider");
  e = decode_error(seed_msg(R"(,"ai":{"provider":"p","model":"m","confidence":1.5})"));
  EXPECT_EQ(e.field, "ai.confidence");
  e = decode_error(seed_msg(R"(,"ai":{"provider":"p","model":"m","escalated":"no"})"));
  EXPECT_EQ(e.field, "ai.escalated");
}

TEST(MessageCodec, CloudFunctionNeedsProviderAndFunctionName) {
  EXPECT_EQ(decode_error(seed_msg(R"(,"sender_type":"cloud_function","function_name":"f")")).field,
            "cloud_provider");
  EXPECT_EQ(decode_error(seed_msg(R"(,"sender_type":"cloud_function","cloud_provider":"firebase")"))
                .field,
            "function_name");
  auto m = parse_message(seed_msg(
      R"(,"sender_type":"cloud_function","cloud_provider":"firebase","function_name":"castor-bridge-v2","function_region":"us-central1")"));
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->sender_type, SenderType::kCloudFunction);
  EXPECT_TRUE(m->sender_type_explicit);
  EXPECT_EQ(m->function_region, "us-central1");
  EXPECT_EQ(decode_error(seed_msg(R"(,"sender_type":"service")")).field, "sender_type");
  EXPECT_EQ(decode_error(seed_msg(R"(,"sender_type":"robot")")).code,
            ErrorCode::kMissingDelegationChain);
}

TEST(MessageCodec, VersionChecks) {
  std::string body = seed_msg();
  std::string v2 = body;
  v2.replace(v2.find("1.0.0"), 5, "2.1.0");
  EXPECT_EQ(decode_error(v2).code, ErrorCode::kVersionIncompatible);
  std::string junk = body;
  junk.replace(junk.find("1.0.0"), 5, "x.y");
  EXPECT_EQ(decode_error(junk).field, "version");
  // The rcan-py shape is accepted whatever its rcan field says.
  auto m = parse_message(
      std::string(R"({"rcan":"9.9","msg_id":")") + kId +
      R"(","timestamp":1740721482,"cmd":"status","target":"rcan://local.rcan/acme/rover/abcdef12"})");
  EXPECT_TRUE(m.ok());
}

TEST(MessageCodec, SafetyTypeImpliesSafetyPriority) {
  std::string body =
      std::string(R"({"version":"1.0.0","message_id":")") + kId +
      R"(","type":"SAFETY","payload":{"safety_event":"ESTOP"},"timestamp_ms":1740000000000})";
  auto m = parse_message(body);
  ASSERT_TRUE(m.ok());
  EXPECT_TRUE(m->is_safety());
  EXPECT_EQ(m->priority, Priority::kSafety);
}

struct BadField {
  const char* name;
  std::string body;
  const char* field;
};

class MessageRejects : public ::testing::TestWithParam<BadField> {};

TEST_P(MessageRejects, WithTheOffendingField) {
  auto m = parse_message(GetParam().body);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.error().field, GetParam().field) << m.error().message;
  json::Value body = error_body(m.error(), "", 0);
  EXPECT_EQ(body.get("type")->as_string(), "ERROR");
  EXPECT_FALSE(body.get("payload")->get("error")->as_string().empty());
}

std::vector<BadField> bad_fields() {
  std::string id = kId;
  std::string head =
      R"({"version":"1.0.0","type":"COMMAND","payload":{},"timestamp_ms":1740000000000,)";
  return {
      {"missing_payload", R"({"version":"1.x","type":"COMMAND"})", "payload"},
      {"payload_not_object", R"({"version":"1.0.0","type":"COMMAND","payload":[1]})", "payload"},
      {"missing_type", R"({"version":"1.0.0","payload":{}})", "type"},
      {"unknown_type", R"({"version":"1.0.0","type":"LAUNCH","payload":{}})", "type"},
      {"lowercase_type", R"({"version":"1.0.0","type":"command","payload":{}})", "type"},
      {"type_disagrees",
       R"({"version":"1.0.0","type":"COMMAND","message_type":"STATUS","payload":{}})", "type"},
      {"missing_message_id",
       R"({"version":"1.0.0","type":"COMMAND","payload":{},"timestamp_ms":1})", "message_id"},
      {"non_uuid_message_id", head + R"("message_id":"msg-001"})", "message_id"},
      {"numeric_message_id", head + R"("message_id":42})", "message_id"},
      {"missing_timestamp",
       R"({"version":"1.0.0","type":"COMMAND","payload":{},"message_id":")" + id + "\"}",
       "timestamp_ms"},
      {"float_timestamp",
       R"({"version":"1.0.0","type":"COMMAND","payload":{},"timestamp_ms":1.5,"message_id":")" +
           id + "\"}",
       "timestamp_ms"},
      {"negative_timestamp",
       R"({"version":"1.0.0","type":"COMMAND","payload":{},"timestamp_ms":-5,"message_id":")" + id +
           "\"}",
       "timestamp_ms"},
      {"huge_timestamp",
       R"({"version":"1.0.0","type":"COMMAND","payload":{},"timestamp_ms":99999999999999999999,"message_id":")" +
           id + "\"}",
       "timestamp_ms"},
      {"negative_ttl", head + R"("message_id":")" + id + R"(","ttl_ms":-1})", "ttl_ms"},
      {"string_ttl", head + R"("message_id":")" + id + R"(","ttl_ms":"30"})", "ttl_ms"},
      {"bad_priority", head + R"("message_id":")" + id + R"(","priority":"URGENT"})", "priority"},
      {"bad_source_ruri", head + R"("message_id":")" + id + R"(","source_ruri":"http://x"})",
       "source_ruri.scheme"},
      {"bad_target_ruri",
       head + R"("message_id":")" + id + R"(","target_ruri":"rcan://local.rcan/a1/b2"})",
       "target_ruri.device-id"},
      {"token_not_string", head + R"("message_id":")" + id + R"(","auth_token":{}})", "auth_token"},
      {"huge_token",
       head + R"("message_id":")" + id + R"(","auth_token":")" + std::string(9000, 'a') + "\"}",
       "auth_token"},
      {"scope_number", head + R"("message_id":")" + id + R"(","scope":5})", "scope"},
      {"scope_bad_chars", head + R"("message_id":")" + id + R"(","scope":["CONTROL"]})", "scope"},
      {"too_many_scopes",
       head + R"("message_id":")" + id + R"(","scope":[)" +
           [] {
             std::string s;
             for (int i = 0; i < 40; ++i) s += (i ? ",\"s" : "\"s") + std::to_string(i) + "\"";
             return s;
           }() +
           "]}",
       "scope"},
      {"sig_missing_value",
       head + R"("message_id":")" + id + R"(","sig":{"alg":"ed25519","kid":"ab"}})", "sig.value"},
      {"delegation_not_array", head + R"("message_id":")" + id + R"(","delegation_chain":"x"})",
       "delegation_chain"},
      {"delegation_too_long",
       head + R"("message_id":")" + id + R"(","delegation_chain":[{},{},{},{},{}]})",
       "delegation_chain"},
      {"not_an_object", "[1,2,3]", ""},
      {"rcanpy_missing_target",
       R"({"rcan":"3.2","cmd":"x","msg_id":")" + id + R"(","timestamp":1})", "target"},
      {"rcanpy_bad_target",
       R"({"rcan":"3.2","cmd":"x","target":"rcan://nope","msg_id":")" + id + R"(","timestamp":1})",
       "target.manufacturer"},
      {"rcanpy_msg_id_with_space",
       R"({"rcan":"3.2","cmd":"x","target":"rcan://local.rcan/acme/rover/abcdef12","timestamp":1,"msg_id":"a b"})",
       "msg_id"},
      {"rcanpy_missing_msg_id",
       R"({"rcan":"3.2","cmd":"x","target":"rcan://local.rcan/acme/rover/abcdef12","timestamp":1})",
       "msg_id"},
      {"rcanpy_string_timestamp",
       R"({"rcan":"3.2","cmd":"x","target":"rcan://local.rcan/acme/rover/abcdef12","timestamp":"now","msg_id":")" +
           id + "\"}",
       "timestamp"},
      {"rcanpy_params_array",
       R"({"rcan":"3.2","cmd":"x","target":"rcan://local.rcan/acme/rover/abcdef12","timestamp":1,"params":[],"msg_id":")" +
           id + "\"}",
       "params"},
      {"rcanpy_confidence_range",
       R"({"rcan":"3.2","cmd":"x","target":"rcan://local.rcan/acme/rover/abcdef12","timestamp":1,"confidence":2,"msg_id":")" +
           id + "\"}",
       "confidence"},
      {"rcanpy_missing_cmd", R"({"rcan":"3.2","target":"rcan://local.rcan/acme/rover/abcdef12"})",
       "cmd"},
  };
}

INSTANTIATE_TEST_SUITE_P(Fields, MessageRejects, ::testing::ValuesIn(bad_fields()),
                         [](const auto& param_info) { return std::string(param_info.param.name); });

TEST(MessageCodec, BodyLimitAndMalformedJson) {
  CodecLimits lim;
  lim.max_body_bytes = 100;
  auto m = parse_message(seed_msg(), lim);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.error().code, ErrorCode::kBodyTooLarge);
  EXPECT_EQ(http_status(m.error().code), 413);
  m = parse_message(R"({"version":"1.0.0",)");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.error().code, ErrorCode::kMalformedJson);
  EXPECT_EQ(http_status(m.error().code), 400);
}

TEST(MessageShape, OnlyPayloadIsNeededBeforeAuthentication) {
  // The live checker's RBAC probe: no id, no timestamp, a string scope, an unknown field.
  auto probe = json::parse(
      R"({"type":"COMMAND","version":"1.2","scope":"control","payload":{"action":"move_forward","speed_mps":0.1},"__test_role_override":"GUEST"})");
  ASSERT_TRUE(probe.ok());
  EXPECT_TRUE(check_shape(*probe).ok());
  auto schema = json::parse(R"({"version":"1.2","type":"COMMAND"})");
  ASSERT_TRUE(schema.ok());
  Status st = check_shape(*schema);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().field, "payload");
  EXPECT_EQ(error_body(st.error(), "", 0)
                .get("payload")
                ->get("detail")
                ->get("missing_field")
                ->as_string(),
            "payload");
}

}  // namespace
}  // namespace rcan
