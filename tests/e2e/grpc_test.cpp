// gRPC transport end to end: the real rcand (configured, gRPC on an ephemeral port) driven by
// the C++ gRPC client (generated stubs of proto/rcan.proto) and by Python's grpcio; the
// status-code table; the stream's answers and events; audit parity with the WebSocket stream.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <set>
#include <thread>

#include "configured_node.h"
#include "rcan.grpc.pb.h"
#include "rcan/errors.h"
#include "transport/grpc_convert.h"

namespace rcan {
namespace {

using test::ConfiguredNode;
using test::now_wall_ms;
using test::parse_json;
using v1::RCANMessage;

std::unique_ptr<v1::Rcan::Stub> stub_for(uint16_t port) {
  auto ch =
      grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials());
  return v1::Rcan::NewStub(ch);
}

RCANMessage command_msg(const std::string& action, json::Object params,
                        const std::string& id = "") {
  RCANMessage m;
  m.set_version("1.0.0");
  m.set_message_id(id.empty() ? new_uuid_v4() : id);
  m.set_type(RCANMessage::COMMAND);
  json::Object payload{{"action", action}};
  for (auto& p : params) payload.set(p.first, p.second);
  m.set_payload(json::dump(json::Value(payload)));
  m.set_timestamp_ms(now_wall_ms());
  m.set_priority(RCANMessage::NORMAL);
  return m;
}

RCANMessage typed_msg(RCANMessage::MessageType t, json::Object payload,
                      const std::string& id = "") {
  RCANMessage m;
  m.set_version("1.0.0");
  m.set_message_id(id.empty() ? new_uuid_v4() : id);
  m.set_type(t);
  m.set_payload(json::dump(json::Value(payload)));
  m.set_timestamp_ms(now_wall_ms());
  if (t == RCANMessage::SAFETY_MESSAGE) m.set_priority(RCANMessage::SAFETY);
  return m;
}

json::Value payload_of(const RCANMessage& m) { return parse_json(m.payload()); }

std::string trailing(const grpc::ClientContext& ctx, const std::string& key) {
  auto md = ctx.GetServerTrailingMetadata();
  auto it = md.find(key);
  return it == md.end() ? "" : std::string(it->second.data(), it->second.size());
}

// A Stream call with a reader thread.
class StreamClient {
 public:
  StreamClient(v1::Rcan::Stub& stub, const std::string& token) {
    if (!token.empty()) ctx_.AddMetadata("authorization", "Bearer " + token);
    rw_ = stub.Stream(&ctx_);
    reader_ = std::thread([this] {
      RCANMessage m;
      while (rw_->Read(&m)) {
        std::lock_guard<std::mutex> lock(mu_);
        q_.push_back(m);
        cv_.notify_all();
      }
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
      cv_.notify_all();
    });
  }
  ~StreamClient() {
    if (!closed_) finish();
  }
  bool send(const RCANMessage& m) { return rw_->Write(m); }
  // The next message matching `pred` within timeout_ms (others are kept in `seen`).
  std::optional<RCANMessage> wait_for(const std::function<bool(const RCANMessage&)>& pred,
                                      int timeout_ms) {
    std::unique_lock<std::mutex> lock(mu_);
    auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (true) {
      for (auto it = q_.begin(); it != q_.end(); ++it) {
        if (pred(*it)) {
          RCANMessage m = *it;
          q_.erase(it);
          return m;
        }
      }
      if (done_ || cv_.wait_until(lock, until) == std::cv_status::timeout) {
        for (auto it = q_.begin(); it != q_.end(); ++it)
          if (pred(*it)) {
            RCANMessage m = *it;
            q_.erase(it);
            return m;
          }
        return std::nullopt;
      }
    }
  }
  std::optional<RCANMessage> reply_to(const std::string& id, int timeout_ms = 10000) {
    return wait_for([&](const RCANMessage& m) { return m.reply_to() == id; }, timeout_ms);
  }
  grpc::Status finish() {
    closed_ = true;
    rw_->WritesDone();
    if (reader_.joinable()) reader_.join();
    return rw_->Finish();
  }
  grpc::ClientContext& context() { return ctx_; }

 private:
  grpc::ClientContext ctx_;
  std::unique_ptr<grpc::ClientReaderWriter<RCANMessage, RCANMessage>> rw_;
  std::thread reader_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<RCANMessage> q_;
  bool done_ = false;
  bool closed_ = false;
};

class GrpcTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { node_ = new ConfiguredNode(); }
  static void TearDownTestSuite() {
    delete node_;
    node_ = nullptr;
  }
  ConfiguredNode& n() { return *node_; }
  static ConfiguredNode* node_;
};
ConfiguredNode* GrpcTest::node_ = nullptr;

TEST_F(GrpcTest, UnarySendDispatchesThroughThePipelineAndIsAudited) {
  ASSERT_NE(n().grpc_port(), 0) << n().proc().err();
  auto stub = stub_for(n().grpc_port());
  std::string owner = n().token("owner", {"control", "status", "config"}, "grpc-owner");
  RCANMessage req = command_msg("move", {{"linear", 0.2}, {"duration_ms", 200}});
  RCANMessage resp;
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", "Bearer " + owner);
  grpc::Status s = stub->Send(&ctx, req, &resp);
  ASSERT_TRUE(s.ok()) << s.error_code() << " " << s.error_message();
  EXPECT_EQ(resp.type(), RCANMessage::ACK);
  EXPECT_EQ(resp.reply_to(), req.message_id());
  EXPECT_FALSE(resp.message_id().empty());
  json::Value p = payload_of(resp);
  EXPECT_NE(p.get("result"), nullptr) << resp.payload();

  // The token may also travel in the message itself.
  RCANMessage req2 = typed_msg(RCANMessage::STATUS, {});
  req2.set_auth_token(owner);
  RCANMessage resp2;
  grpc::ClientContext ctx2;
  ASSERT_TRUE(stub->Send(&ctx2, req2, &resp2).ok());
  EXPECT_EQ(resp2.type(), RCANMessage::STATUS);
  EXPECT_NE(payload_of(resp2).get("ruri"), nullptr);

  bool found = false;
  for (const auto& e : n().audit(owner)) {
    if (e.get("message_id") && e.get("message_id")->is_string() &&
        e.get("message_id")->as_string() == req.message_id()) {
      found = true;
      EXPECT_EQ(e.get("event")->as_string(), "COMMAND");
      EXPECT_EQ(e.get("outcome")->as_string(), "ok");
      EXPECT_EQ(e.get("detail")->get("transport")->as_string(), "grpc");
      EXPECT_EQ(e.get("detail")->get("route")->as_string(), "/rcan.v1.Rcan/Send");
      EXPECT_EQ(e.get("sub")->as_string(), "grpc-owner");
    }
  }
  EXPECT_TRUE(found);
}

struct Refusal {
  grpc::StatusCode code;
  std::string rcan_code;
  std::string http;
  RCANMessage details;
};

Refusal send_expecting_error(v1::Rcan::Stub& stub, const RCANMessage& m, const std::string& token) {
  grpc::ClientContext ctx;
  if (!token.empty()) ctx.AddMetadata("authorization", "Bearer " + token);
  RCANMessage resp;
  grpc::Status s = stub.Send(&ctx, m, &resp);
  Refusal r{
      s.error_code(), trailing(ctx, "rcan-error-code"), trailing(ctx, "rcan-http-status"), {}};
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(r.details.ParseFromString(s.error_details()));
  return r;
}

TEST_F(GrpcTest, ErrorsMapOntoStatusCodesWithTheProfileBodyAsDetails) {
  auto stub = stub_for(n().grpc_port());
  std::string owner = n().token("owner", {"control", "status"});
  std::string guest = n().token("guest", {"status"}, "grpc-guest");
  // No token at all.
  Refusal r = send_expecting_error(*stub, command_msg("move", {{"linear", 0.1}}), "");
  EXPECT_EQ(r.code, grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(r.rcan_code, "AUTH_REQUIRED");
  EXPECT_EQ(r.http, "401");
  EXPECT_EQ(r.details.type(), RCANMessage::ERROR);
  EXPECT_EQ(payload_of(r.details).get("error_code")->as_string(), "AUTH_REQUIRED");
  // A forged token.
  r = send_expecting_error(*stub, command_msg("move", {{"linear", 0.1}}),
                           owner.substr(0, owner.size() - 4) + "AAAA");
  EXPECT_EQ(r.code, grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(r.rcan_code, "AUTH_INVALID");
  // A guest may not drive.
  r = send_expecting_error(*stub, command_msg("move", {{"linear", 0.1}}), guest);
  EXPECT_EQ(r.code, grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(r.rcan_code, "INSUFFICIENT_PRIVILEGES");
  // Payload that is not JSON: refused before the pipeline.
  RCANMessage bad = command_msg("move", {});
  bad.set_payload("{not json");
  r = send_expecting_error(*stub, bad, owner);
  EXPECT_EQ(r.code, grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(r.rcan_code, "MALFORMED_JSON");
  EXPECT_EQ(r.details.reply_to(), bad.message_id());
  // A payload that is JSON but not an object.
  bad.set_payload("[1,2]");
  EXPECT_EQ(send_expecting_error(*stub, bad, owner).rcan_code, "SCHEMA_VALIDATION_FAILED");
  // An enum value outside the proto's enum.
  RCANMessage odd = command_msg("move", {});
  odd.set_type(static_cast<RCANMessage::MessageType>(99));
  EXPECT_EQ(send_expecting_error(*stub, odd, owner).code, grpc::StatusCode::INVALID_ARGUMENT);
  // Replay of an accepted message id.
  RCANMessage once = command_msg("status", {});
  {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + owner);
    RCANMessage resp;
    ASSERT_TRUE(stub->Send(&ctx, once, &resp).ok());
  }
  r = send_expecting_error(*stub, once, owner);
  EXPECT_EQ(r.code, grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_EQ(r.rcan_code, "REPLAY_DETECTED");
  // Stale timestamp.
  RCANMessage stale = command_msg("status", {});
  stale.set_timestamp_ms(now_wall_ms() - 120'000);
  r = send_expecting_error(*stub, stale, owner);
  EXPECT_EQ(r.code, grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_EQ(r.rcan_code, "MESSAGE_STALE");
  // A major version the node does not speak.
  RCANMessage v2 = command_msg("status", {});
  v2.set_version("2.0.0");
  EXPECT_EQ(send_expecting_error(*stub, v2, owner).rcan_code, "VERSION_INCOMPATIBLE");
  // A message larger than the limit never reaches the pipeline.
  RCANMessage big = command_msg("chat", {{"text", std::string(100 * 1024, 'a')}});
  {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + owner);
    RCANMessage resp;
    EXPECT_EQ(stub->Send(&ctx, big, &resp).error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  }
  // The node still answers.
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", "Bearer " + owner);
  RCANMessage resp;
  EXPECT_TRUE(stub->Send(&ctx, typed_msg(RCANMessage::STATUS, {}), &resp).ok());
}

TEST_F(GrpcTest, StreamCarriesCommandsAnswersAndSafetyEvents) {
  auto stub = stub_for(n().grpc_port());
  std::string owner = n().token("owner", {"control", "status", "chat"}, "stream-owner");
  StreamClient s(*stub, owner);
  RCANMessage cmd = command_msg("move", {{"linear", 0.2}, {"duration_ms", 300}});
  ASSERT_TRUE(s.send(cmd));
  auto ack = s.reply_to(cmd.message_id());
  ASSERT_TRUE(ack.has_value());
  EXPECT_EQ(ack->type(), RCANMessage::ACK);
  // An error is answered in-band and the stream goes on.
  RCANMessage bad = command_msg("move", {});
  bad.set_payload("nope");
  ASSERT_TRUE(s.send(bad));
  auto err = s.reply_to(bad.message_id());
  ASSERT_TRUE(err.has_value());
  EXPECT_EQ(err->type(), RCANMessage::ERROR);
  EXPECT_EQ(payload_of(*err).get("error_code")->as_string(), "MALFORMED_JSON");
  // ESTOP over the stream: ACK, and the event pushed to the stream.
  RCANMessage estop =
      typed_msg(RCANMessage::SAFETY_MESSAGE, {{"safety_event", "ESTOP"}, {"reason", "grpc test"}});
  ASSERT_TRUE(s.send(estop));
  auto estop_ack = s.reply_to(estop.message_id());
  ASSERT_TRUE(estop_ack.has_value());
  EXPECT_EQ(estop_ack->type(), RCANMessage::ACK) << estop_ack->payload();
  auto ev = s.wait_for(
      [](const RCANMessage& m) {
        return m.reply_to().empty() && m.payload().find("ESTOP") != std::string::npos;
      },
      5000);
  EXPECT_TRUE(ev.has_value());
  // A command while latched: refused 423 → FAILED_PRECONDITION on the unary call.
  {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + owner);
    RCANMessage resp;
    grpc::Status st = stub->Send(&ctx, command_msg("move", {{"linear", 0.1}}), &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_EQ(trailing(ctx, "rcan-error-code"), "COMMAND_REJECTED");
    EXPECT_EQ(trailing(ctx, "rcan-http-status"), "423");
  }
  RCANMessage resume = typed_msg(RCANMessage::SAFETY_MESSAGE, {{"safety_event", "RESUME"}});
  ASSERT_TRUE(s.send(resume));
  auto resumed = s.reply_to(resume.message_id());
  ASSERT_TRUE(resumed.has_value());
  EXPECT_EQ(resumed->type(), RCANMessage::ACK) << resumed->payload();
  grpc::Status fin = s.finish();
  EXPECT_TRUE(fin.ok()) << fin.error_message();
}

// An event for one principal (a queued claim's PROMOTED; it carries no key, but says who holds)
// reaches that principal's gRPC stream and no one else's: a GUEST on another stream sees the
// events for everyone (the ESTOP after it) but never the promotion.
TEST_F(GrpcTest, EventsForOnePrincipalReachOnlyThatPrincipalsStream) {
  auto stub = stub_for(n().grpc_port());
  std::string a = n().token("user", {"control", "status"}, "grpc-user-a");
  std::string b = n().token("user", {"control", "status"}, "grpc-user-b");
  std::string guest = n().token("guest", {"status"}, "grpc-guest");
  std::string owner = n().token("owner", {"control", "status"}, "grpc-owner");
  StreamClient bs(*stub, b);
  StreamClient gs(*stub, guest);
  // Both streams are subscribed once they answer a STATUS.
  for (StreamClient* s : {&bs, &gs}) {
    RCANMessage st = typed_msg(RCANMessage::STATUS, {});
    ASSERT_TRUE(s->send(st));
    ASSERT_TRUE(s->reply_to(st.message_id()).has_value());
  }
  auto claimed = n().post("/rcan/v1/auth/claim", "{}", a);
  ASSERT_EQ(claimed.status, 200) << claimed.body;
  auto queued = n().post("/rcan/v1/auth/claim", "{}", b);
  ASSERT_EQ(queued.status, 409) << queued.body;
  ASSERT_NE(queued.body.find("\"queued\":true"), std::string::npos) << queued.body;
  auto released = n().post("/rcan/v1/auth/release", "{}", a);
  ASSERT_EQ(released.status, 200) << released.body;
  auto is_promoted = [](const RCANMessage& m) {
    return m.payload().find("PROMOTED") != std::string::npos ||
           m.payload().find("key_b64") != std::string::npos;
  };
  auto promoted = bs.wait_for(is_promoted, 5000);
  ASSERT_TRUE(promoted.has_value()) << "no PROMOTED event on B's own stream";
  // An event for everyone, published after the promotion: once the GUEST has it, anything
  // published before it has been forwarded (or not) already.
  auto stop = n().post("/api/stop", R"({"reason":"grpc audience test"})", owner);
  ASSERT_EQ(stop.status, 200) << stop.body;
  auto estop = gs.wait_for(
      [](const RCANMessage& m) {
        return m.reply_to().empty() && m.payload().find("ESTOP") != std::string::npos;
      },
      5000);
  ASSERT_TRUE(estop.has_value()) << "the GUEST stream got no ESTOP event";
  EXPECT_FALSE(gs.wait_for(is_promoted, 0).has_value())
      << "another principal's PROMOTED event reached a GUEST stream";
  auto resume = n().post(
      "/rcan/v1/command",
      json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                          {"message_id", new_uuid_v4()},
                                          {"type", "SAFETY"},
                                          {"priority", "SAFETY"},
                                          {"timestamp_ms", now_wall_ms()},
                                          {"payload", json::Object{{"safety_event", "RESUME"}}}})),
      owner);
  EXPECT_EQ(resume.status, 200) << resume.body;
  EXPECT_EQ(n().post("/rcan/v1/auth/release", "{}", b).status, 200);
  EXPECT_TRUE(bs.finish().ok());
  EXPECT_TRUE(gs.finish().ok());
}

TEST_F(GrpcTest, StreamWithABadTokenIsRefused) {
  auto stub = stub_for(n().grpc_port());
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", "Bearer not-a-token");
  auto rw = stub->Stream(&ctx);
  RCANMessage m;
  EXPECT_FALSE(rw->Read(&m));
  grpc::Status st = rw->Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAUTHENTICATED);
}

// docs/SECURITY.md R7: a stream keeps its CONNECT principal only until that token is revoked.
TEST_F(GrpcTest, StreamOfARevokedPrincipalEndsAtOnceUnauthenticated) {
  auto stub = stub_for(n().grpc_port());
  std::string user = n().token("user", {"control", "status"}, "grpc-revoked");
  std::string owner = n().token("owner", {"control", "status"}, "grpc-owner");
  StreamClient s(*stub, user);
  RCANMessage st = typed_msg(RCANMessage::STATUS, {});
  ASSERT_TRUE(s.send(st));
  ASSERT_TRUE(s.reply_to(st.message_id()).has_value());
  auto revoked =
      n().post("/rcan/v1/revocations",
               R"({"sub":"grpc-revoked","iss":"test.local","reason":"grpc test"})", owner);
  ASSERT_EQ(revoked.status, 201) << revoked.body;
  const auto t0 = std::chrono::steady_clock::now();
  grpc::Status ended = s.finish();
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::UNAUTHENTICATED) << ended.error_message();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(3));
  StreamClient again(*stub, user);
  EXPECT_EQ(again.finish().error_code(), grpc::StatusCode::UNAUTHENTICATED);
}

TEST_F(GrpcTest, StreamWithoutMetadataTakesTheTokenFromEachMessage) {
  auto stub = stub_for(n().grpc_port());
  std::string user = n().token("user", {"control", "status"});
  StreamClient s(*stub, "");
  RCANMessage with = typed_msg(RCANMessage::STATUS, {});
  with.set_auth_token(user);
  RCANMessage without = typed_msg(RCANMessage::STATUS, {});
  ASSERT_TRUE(s.send(with));
  ASSERT_TRUE(s.send(without));
  auto a = s.reply_to(with.message_id());
  auto b = s.reply_to(without.message_id());
  ASSERT_TRUE(a.has_value());
  ASSERT_TRUE(b.has_value());
  EXPECT_EQ(a->type(), RCANMessage::STATUS);
  EXPECT_EQ(b->type(), RCANMessage::ERROR);
  EXPECT_EQ(payload_of(*b).get("error_code")->as_string(), "AUTH_REQUIRED");
  EXPECT_TRUE(s.finish().ok());
}

TEST(GrpcConvert, EveryErrorCodeHasAStatusAndMessagesConvertBothWays) {
  using transport::grpc_status_code;
  struct Row {
    ErrorCode code;
    grpc::StatusCode want;
  };
  for (const Row& r :
       std::vector<Row>{{ErrorCode::kMalformedJson, grpc::INVALID_ARGUMENT},
                        {ErrorCode::kSchemaValidationFailed, grpc::INVALID_ARGUMENT},
                        {ErrorCode::kInvalidRuri, grpc::INVALID_ARGUMENT},
                        {ErrorCode::kVersionIncompatible, grpc::INVALID_ARGUMENT},
                        {ErrorCode::kMissingDelegationChain, grpc::INVALID_ARGUMENT},
                        {ErrorCode::kAuthRequired, grpc::UNAUTHENTICATED},
                        {ErrorCode::kAuthInvalid, grpc::UNAUTHENTICATED},
                        {ErrorCode::kSessionExpired, grpc::UNAUTHENTICATED},
                        {ErrorCode::kSignatureInvalid, grpc::UNAUTHENTICATED},
                        {ErrorCode::kInsufficientPrivileges, grpc::PERMISSION_DENIED},
                        {ErrorCode::kConfidenceGateFail, grpc::PERMISSION_DENIED},
                        {ErrorCode::kHitlDenied, grpc::PERMISSION_DENIED},
                        {ErrorCode::kNotFound, grpc::NOT_FOUND},
                        {ErrorCode::kMethodNotAllowed, grpc::UNIMPLEMENTED},
                        {ErrorCode::kNotImplemented, grpc::UNIMPLEMENTED},
                        {ErrorCode::kMessageStale, grpc::DEADLINE_EXCEEDED},
                        {ErrorCode::kHitlTimeout, grpc::DEADLINE_EXCEEDED},
                        {ErrorCode::kReplayDetected, grpc::ALREADY_EXISTS},
                        {ErrorCode::kControlConflict, grpc::ABORTED},
                        {ErrorCode::kBodyTooLarge, grpc::RESOURCE_EXHAUSTED},
                        {ErrorCode::kRateLimited, grpc::RESOURCE_EXHAUSTED},
                        {ErrorCode::kCommandRejected, grpc::FAILED_PRECONDITION},
                        {ErrorCode::kInternal, grpc::INTERNAL},
                        {ErrorCode::kSafeStop, grpc::UNAVAILABLE},
                        {ErrorCode::kLockdown, grpc::UNAVAILABLE},
                        {ErrorCode::kAuditUnavailable, grpc::UNAVAILABLE}}) {
    EXPECT_EQ(grpc_status_code(error_name(r.code), http_status(r.code)), r.want)
        << error_name(r.code);
    // The HTTP fallback agrees wherever the HTTP status alone is unambiguous.
    int http = http_status(r.code);
    if (http != 409 && http != 405 && http != 501 && http != 500) {
      EXPECT_EQ(grpc_status_code("", http), r.want) << error_name(r.code);
    }
  }
  RCANMessage m = command_msg("move", {{"linear", 0.5}});
  m.set_ttl_ms(250);
  m.add_scope("control");
  m.set_sender_type("cloud_function");
  m.set_cloud_provider("gcp");
  m.set_function_name("dispatch");
  m.set_ai(R"({"provider":"p","model":"m","confidence":0.75})");
  auto j = transport::grpc_to_json(m);
  ASSERT_TRUE(j.ok()) << j.error().message;
  EXPECT_EQ(j->get("type")->as_string(), "COMMAND");
  EXPECT_EQ(j->get("priority")->as_string(), "NORMAL");
  EXPECT_EQ(j->get("ttl_ms")->as_int(), 250);
  EXPECT_EQ(j->get("scope")->as_array().at(0).as_string(), "control");
  EXPECT_EQ(j->get("payload")->get("linear")->as_double(), 0.5);
  EXPECT_EQ(j->get("ai")->get("confidence")->as_double(), 0.75);
  EXPECT_EQ(j->get("auth_token"), nullptr);  // empty → absent
  RCANMessage safety = typed_msg(RCANMessage::SAFETY_MESSAGE, {{"safety_event", "ESTOP"}});
  auto sj = transport::grpc_to_json(safety);
  ASSERT_TRUE(sj.ok());
  EXPECT_EQ(sj->get("type")->as_string(), "SAFETY");
  EXPECT_EQ(sj->get("priority")->as_string(), "SAFETY");
  RCANMessage back;
  transport::json_to_grpc(
      json::Value(json::Object{{"type", "EVENT"}, {"event", "ESTOP"}, {"timestamp_ms", 5}}), back);
  EXPECT_EQ(back.type(), RCANMessage::EVENT);
  EXPECT_EQ(back.timestamp_ms(), 5);
  EXPECT_EQ(payload_of(back).get("event")->as_string(), "ESTOP");
  transport::json_to_grpc(json::Value(json::Object{{"type", "CONNECT_ACK"}, {"role", "OWNER"}}),
                          back);
  EXPECT_EQ(back.type(), RCANMessage::EVENT);
  EXPECT_EQ(payload_of(back).get("type")->as_string(), "CONNECT_ACK");
}

TEST(GrpcTls, TlsFromConfigAndPlaintextClientsRefused) {
  test::TempDir certs;
  auto gen = test::run({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                        "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", certs.file("key.pem"),
                        "-out", certs.file("cert.pem"), "-days", "1", "-subj", "/CN=localhost",
                        "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"});
  ASSERT_EQ(gen.exit_code, 0) << gen.err;
  ConfiguredNode node(
      "grpc:\n  enabled: true\n  port: 0\n  tls:\n    enabled: true\n    cert_file: " +
          certs.file("cert.pem") + "\n    key_file: " + certs.file("key.pem") + "\n",
      2000, /*transports=*/false);
  ASSERT_NE(node.grpc_port(), 0) << node.proc().err();
  EXPECT_NE(node.proc().err().find("\"tls\":true"), std::string::npos);
  std::string owner = node.token("owner", {"status"});
  grpc::SslCredentialsOptions so;
  so.pem_root_certs = test::read_file(certs.file("cert.pem"));
  auto ch = grpc::CreateChannel("127.0.0.1:" + std::to_string(node.grpc_port()),
                                grpc::SslCredentials(so));
  auto stub = v1::Rcan::NewStub(ch);
  {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + owner);
    RCANMessage resp;
    grpc::Status s = stub->Send(&ctx, typed_msg(RCANMessage::STATUS, {}), &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(resp.type(), RCANMessage::STATUS);
  }
  {
    auto plain = stub_for(node.grpc_port());
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    ctx.AddMetadata("authorization", "Bearer " + owner);
    RCANMessage resp;
    EXPECT_FALSE(plain->Send(&ctx, typed_msg(RCANMessage::STATUS, {}), &resp).ok());
  }
  // gRPC's own complaint about the plaintext client is a JSON log line like every other.
  EXPECT_TRUE(node.proc().wait_for_line("grpc.library", 5000).has_value());
  std::string err = node.proc().err();
  size_t start = 0;
  while (start < err.size()) {
    size_t end = err.find('\n', start);
    std::string line =
        err.substr(start, end == std::string::npos ? std::string::npos : end - start);
    if (!line.empty()) {
      EXPECT_EQ(line[0], '{') << line;
    }
    if (end == std::string::npos) break;
    start = end + 1;
  }
}

TEST(GrpcRobustness, ClientsVanishingMidStreamLeaveTheNodeServingAndItStopsCleanly) {
  ConfiguredNode node;
  ConfiguredNode& nd = node;
  auto n = [&]() -> ConfiguredNode& { return nd; };
  ASSERT_NE(n().grpc_port(), 0) << n().proc().err();
  auto stub = stub_for(n().grpc_port());
  std::string owner = n().token("owner", {"control", "status", "chat"}, "vanishing");
  for (int round = 0; round < 8; ++round) {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + owner);
    auto rw = stub->Stream(&ctx);
    for (int i = 0; i < 20; ++i) rw->Write(typed_msg(RCANMessage::STATUS, {}));
    if (round % 2 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    ctx.TryCancel();  // answers still in the pipeline find the stream gone
    EXPECT_EQ(rw->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  // Unary callers that give up (deadline) before the answer.
  for (int i = 0; i < 8; ++i) {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + owner);
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::microseconds(200));
    RCANMessage resp;
    (void)stub->Send(&ctx, command_msg("chat", {{"text", "hi"}}), &resp);
  }
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", "Bearer " + owner);
  RCANMessage resp;
  ASSERT_TRUE(stub->Send(&ctx, typed_msg(RCANMessage::STATUS, {}), &resp).ok());
  EXPECT_EQ(n().get("/healthz").status, 200);
  EXPECT_EQ(n().metric("rcan_audit_failures_total"), 0);
  // A stream left open at shutdown is ended by the node; rcand exits 0.
  StreamClient open(*stub, owner);
  RCANMessage m = typed_msg(RCANMessage::STATUS, {});
  ASSERT_TRUE(open.send(m));
  ASSERT_TRUE(open.reply_to(m.message_id()).has_value());
  EXPECT_EQ(node.terminate(), 0) << node.proc().err().substr(0, 2000);
  grpc::Status st = open.finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAVAILABLE) << st.error_message();
}

TEST(GrpcLimits, StreamsBeyondMaxStreamsAreRefused) {
  ConfiguredNode node("grpc:\n  enabled: true\n  port: 0\n  max_streams: 1\n", 2000,
                      /*transports=*/false);
  ASSERT_NE(node.grpc_port(), 0) << node.proc().err();
  std::string owner = node.token("owner", {"status"});
  auto stub = stub_for(node.grpc_port());
  StreamClient first(*stub, owner);
  RCANMessage ping = typed_msg(RCANMessage::STATUS, {});
  ASSERT_TRUE(first.send(ping));
  ASSERT_TRUE(first.reply_to(ping.message_id()).has_value());  // the first stream is open
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", "Bearer " + owner);
  auto second = stub->Stream(&ctx);
  RCANMessage m;
  EXPECT_FALSE(second->Read(&m));
  EXPECT_EQ(second->Finish().error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_TRUE(first.finish().ok());
  // Once the first has ended (the server counts it closed when its call is done, a moment after
  // the client has the status), a new stream is accepted.
  bool accepted = false;
  for (int i = 0; i < 50 && !accepted; ++i) {
    StreamClient third(*stub, owner);
    RCANMessage again = typed_msg(RCANMessage::STATUS, {});
    third.send(again);
    accepted = third.reply_to(again.message_id(), 2000).has_value();
    grpc::Status st = third.finish();
    if (!accepted) {
      EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    } else {
      EXPECT_TRUE(st.ok());
    }
  }
  EXPECT_TRUE(accepted);
}

// ---------------------------------------------------------------------------------------------
// The same command sequence over gRPC and over WebSocket yields the same audit records, apart
// from the transport fields (detail.transport, detail.route) and what differs by nature between
// two runs (message ids, time, chain position).

struct Step {
  std::string kind;  // "cmd", "status", "heartbeat", "estop", "resume", "replay"
  std::string action;
  json::Object params;
};

std::vector<Step> sequence() {
  return {
      {"cmd", "move", {{"linear", 0.2}, {"duration_ms", 200}}},
      {"status", "", {}},
      {"heartbeat", "", {}},
      {"cmd", "chat", {{"text", "hello"}}},
      {"cmd", "move", {{"linear", 5.0}, {"duration_ms", 100}}},            // clamped
      {"cmd", "arm_move", {{"joints", json::Array{9.0, 0, 0, 0, 0, 0}}}},  // out of range: rejected
      {"replay", "", {}},
      {"estop", "", {}},
      {"cmd", "move", {{"linear", 0.1}, {"duration_ms", 100}}},  // refused: latched
      {"resume", "", {}}};
}

json::Object message_json(const Step& st, const std::string& id, const std::string& replay_id) {
  json::Object m{{"version", "1.0.0"}, {"timestamp_ms", now_wall_ms()}};
  if (st.kind == "cmd") {
    json::Object p{{"action", st.action}};
    for (auto& kv : st.params) p.set(kv.first, kv.second);
    m.set("message_id", id);
    m.set("type", "COMMAND");
    m.set("payload", p);
  } else if (st.kind == "status") {
    m.set("message_id", id);
    m.set("type", "STATUS");
    m.set("payload", json::Object{});
  } else if (st.kind == "heartbeat") {
    m.set("message_id", id);
    m.set("type", "HEARTBEAT");
    m.set("payload", json::Object{});
  } else if (st.kind == "estop" || st.kind == "resume") {
    m.set("message_id", id);
    m.set("type", "SAFETY");
    m.set("priority", "SAFETY");
    m.set("payload", json::Object{{"safety_event", st.kind == "estop" ? "ESTOP" : "RESUME"}});
  } else {  // replay: the first command's id again
    m.set("message_id", replay_id);
    m.set("type", "COMMAND");
    m.set("payload", json::Object{{"action", "status"}});
  }
  return m;
}

RCANMessage to_proto(const json::Object& m) {
  RCANMessage p;
  p.set_version(m.find("version")->as_string());
  p.set_message_id(m.find("message_id")->as_string());
  p.set_type(static_cast<RCANMessage::MessageType>(
      transport::grpc_type_from_name(m.find("type")->as_string())));
  p.set_payload(json::dump(*m.find("payload")));
  p.set_timestamp_ms(m.find("timestamp_ms")->as_int());
  if (m.find("priority")) p.set_priority(RCANMessage::SAFETY);
  return p;
}

// The records of `ids`, in chain order, without the fields that legitimately differ.
std::vector<json::Value> normalised(const std::vector<json::Value>& records,
                                    const std::vector<std::string>& ids) {
  std::set<std::string> want(ids.begin(), ids.end());
  std::vector<json::Value> out;
  for (const auto& r : records) {
    const json::Value* id = r.get("message_id");
    if (!id || !id->is_string() || !want.count(id->as_string())) continue;
    json::Value c = r;
    auto& o = c.as_object();
    size_t index =
        static_cast<size_t>(std::find(ids.begin(), ids.end(), id->as_string()) - ids.begin());
    o.set("message_id", "#" + std::to_string(index));
    for (const char* k : {"seq", "prev_hash", "hmac", "timestamp_ms", "watermark_token"})
      o.erase(k);
    if (json::Value* d = c.get("detail"); d && d->is_object()) {
      d->as_object().erase("transport");
      d->as_object().erase("route");
      for (const char* k : {"latency_us", "stop_latency_us", "elapsed_ms", "duration_us"})
        d->as_object().erase(k);
    }
    out.push_back(std::move(c));
  }
  return out;
}

TEST(GrpcAuditParity, SameSequenceOverGrpcAndWebSocketGivesTheSameAuditRecords) {
  ConfiguredNode node;
  ASSERT_NE(node.grpc_port(), 0) << node.proc().err();
  std::string owner =
      node.token("owner", {"control", "status", "chat", "config"}, "parity-operator");

  auto run = [&](bool over_grpc) -> std::vector<std::string> {
    std::vector<std::string> ids;
    std::unique_ptr<v1::Rcan::Stub> stub;
    std::unique_ptr<StreamClient> gs;
    test::WsClient ws;
    if (over_grpc) {
      stub = stub_for(node.grpc_port());
      gs = std::make_unique<StreamClient>(*stub, owner);
    } else {
      EXPECT_EQ(ws.connect(node.http_port(), "/rcan/v1/stream"), 101);
      ws.send_text("{\"type\":\"CONNECT\",\"token\":\"" + owner + "\"}");
      auto ack = ws.recv_text(5000);
      EXPECT_TRUE(ack && ack->find("CONNECT_ACK") != std::string::npos);
    }
    for (const Step& st : sequence()) {
      std::string id = new_uuid_v4();
      json::Object m = message_json(st, id, ids.empty() ? id : ids.front());
      std::string sent_id = m.find("message_id")->as_string();
      if (st.kind != "replay") ids.push_back(id);
      if (over_grpc) {
        EXPECT_TRUE(gs->send(to_proto(m)));
        EXPECT_TRUE(gs->reply_to(sent_id).has_value()) << st.kind;
      } else {
        ws.send_text(json::dump(json::Value(m)));
        bool answered = false;
        auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (!answered && std::chrono::steady_clock::now() < until) {
          auto f = ws.recv_text(1000);
          if (!f) continue;
          json::Value v = parse_json(*f);
          const json::Value* rt = v.get("reply_to");
          answered = rt && rt->is_string() && rt->as_string() == sent_id;
        }
        EXPECT_TRUE(answered) << st.kind;
      }
    }
    if (gs) {
      EXPECT_TRUE(gs->finish().ok());
    }
    return ids;
  };
  std::vector<std::string> grpc_ids = run(true);
  std::vector<std::string> ws_ids = run(false);
  // Let the last records become durable.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  std::vector<json::Value> records = node.audit(owner);
  std::vector<json::Value> a = normalised(records, grpc_ids);
  std::vector<json::Value> b = normalised(records, ws_ids);
  ASSERT_GE(a.size(), sequence().size()) << "records for the gRPC run";
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i)
    EXPECT_EQ(json::dump(a[i]), json::dump(b[i])) << "record " << i;
  // And the transports really differed.
  size_t grpc_records = 0, ws_records = 0;
  for (const auto& r : records) {
    const json::Value* d = r.get("detail");
    const json::Value* t = d ? d->get("transport") : nullptr;
    if (t && t->is_string() && t->as_string() == "grpc") ++grpc_records;
    if (t && t->is_string() && t->as_string() == "ws") ++ws_records;
  }
  EXPECT_GE(grpc_records, a.size());
  EXPECT_GE(ws_records, b.size());
  std::printf("audit parity: %zu records per run identical apart from transport fields; e.g. %s\n",
              a.size(), json::dump(a.front()).c_str());
}

// ---------------------------------------------------------------------------------------------
// Python's grpcio (Debian's python3-grpcio) as a second, independent client.

TEST(GrpcPython, PythonGrpcioClientDrivesSendAndStream) {
  if (access("/usr/bin/python3", X_OK) != 0) {
    GTEST_SKIP() << "no /usr/bin/python3";
  }
  auto probe = test::run({"/usr/bin/python3", "-c", "import grpc, google.protobuf"});
  ASSERT_EQ(probe.exit_code, 0)
      << "python3-grpcio / python3-protobuf missing (scripts/install-deps.sh): " << probe.err;
  ConfiguredNode node;
  ASSERT_NE(node.grpc_port(), 0) << node.proc().err();
  std::string owner = node.token("owner", {"control", "status"}, "python-client");
  test::TempDir gen;
  auto pc = test::run({"/usr/bin/protoc", std::string("-I") + RCAN_PROTO_DIR,
                       "--python_out=" + gen.path(), "--grpc_out=" + gen.path(),
                       "--plugin=protoc-gen-grpc=/usr/bin/grpc_python_plugin",
                       std::string(RCAN_PROTO_DIR) + "/rcan.proto"});
  ASSERT_EQ(pc.exit_code, 0) << pc.err;
  auto r = test::run({"/usr/bin/python3", std::string(RCAN_PY_DIR) + "/grpc_client.py", gen.path(),
                      "127.0.0.1:" + std::to_string(node.grpc_port()), owner});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value v = parse_json(r.out);
  EXPECT_EQ(v.get("send")->get("type")->as_string(), "ACK");
  EXPECT_TRUE(v.get("send")->get("reply_matches")->as_bool());
  EXPECT_EQ(v.get("no_token")->get("code")->as_string(), "UNAUTHENTICATED");
  EXPECT_EQ(v.get("no_token")->get("rcan_error_code")->as_string(), "AUTH_REQUIRED");
  EXPECT_EQ(v.get("stream")->get("answers")->as_int(), 3);
  EXPECT_EQ(v.get("stream")->get("acks")->as_int(), 2);
  EXPECT_EQ(v.get("stream")->get("errors")->as_int(), 1);
  bool found = false;
  for (const auto& e : node.audit(owner)) {
    const json::Value* d = e.get("detail");
    if (e.get("sub") && e.get("sub")->is_string() && e.get("sub")->as_string() == "python-client" &&
        d && d->get("transport") && d->get("transport")->as_string() == "grpc")
      found = true;
  }
  EXPECT_TRUE(found);
}

}  // namespace
}  // namespace rcan
