// Signed messages through a real rcand: the `sig` block of an rcan-py-shape message is checked
// against the keys the config names — peer robots' (security.trusted_robot_keys) and
// operators'/integrators' (security.trusted_signer_keys). A verified signature is recorded in
// the audit record (sig_alg, sig_kid); an unknown key or a tampered message is refused with
// SIGNATURE_INVALID and nothing moves.
#include <gtest/gtest.h>

#include <string>

#include "node_fixture.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/message_sig.h"
#include "test_support.h"

namespace rcan::test {
namespace {

// The SDK form of the node's RURI (rcan-py's RobotURI carries a version segment).
std::string sdk_target() {
  std::string t = ControlNode::kRuri;
  size_t last = t.rfind('/');
  return t.substr(0, last) + "/v1" + t.substr(last);
}

json::Object rcanpy_move(const std::string& sender_type) {
  json::Object m{{"rcan", "3.2"},
                 {"msg_id", new_uuid_v4()},
                 {"timestamp", static_cast<double>(now_wall_ms()) / 1000.0},
                 {"cmd", "move"},
                 {"target", sdk_target()},
                 {"params", json::Object{{"linear", 0.1}, {"duration_ms", 100}}},
                 {"sender_type", sender_type}};
  if (sender_type == "robot")  // a robot acts for a human (§8.5 delegation chain)
    m.set("delegation_chain", json::Array{json::Object{{"issuer_ruri", ControlNode::kRuri},
                                                       {"human_subject", "operator-1"},
                                                       {"timestamp", now_wall_ms() / 1000},
                                                       {"scope", "control"}}});
  return m;
}

class SignedMessages : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::make_unique<TempDir>();
    // Three identities made with the CLI: an operator (signer), a peer robot, a stranger.
    for (const char* who : {"operator", "peer", "stranger"})
      ASSERT_EQ(run_cli({"keys", "generate", "--dir", dir_->path() + "/" + who}).exit_code, 0);
    std::string extra =
        "  trusted_signer_keys:\n    - {name: operator, mldsa65_pub_file: " + dir_->path() +
        "/operator/mldsa65.pub, ed25519_pub_file: " + dir_->path() +
        "/operator/ed25519.pub}\n"
        "  trusted_robot_keys:\n    - {name: peer, mldsa65_pub_file: " +
        dir_->path() + "/peer/mldsa65.pub}\n";
    node_ = std::make_unique<ControlNode>(dir_->path() + "/node", extra);
    ASSERT_TRUE(node_->start());
    token_ = node_->token("user", "operator-1", {"control", "status"});
  }

  keys::RobotKeys keys_of(const std::string& who) {
    auto k = keys::load_dir(dir_->path() + "/" + who);
    EXPECT_TRUE(k.ok()) << (k.ok() ? "" : k.error().message);
    return std::move(k).value();
  }

  HttpReply send(const json::Object& msg) {
    return node_->post("/rcan/v1/command", json::dump(json::Value(msg)), token_);
  }

  // The audit record of a command by its message id ("" fields when absent).
  json::Value record_of(const std::string& msg_id) {
    json::Value found;
    ControlNode::eventually([&] {
      // The audit log is the OWNER's to read.
      HttpReply r =
          node_->get("/api/audit?limit=1000", node_->token("owner", "auditor", {"status"}));
      json::Value v = parse_json(r.body);
      if (const json::Value* es = v.get("entries"); es && es->is_array())
        for (const auto& e : es->as_array())
          if (const json::Value* m = e.get("message_id");
              m && m->is_string() && m->as_string() == msg_id)
            found = e;
      return !found.is_null();
    });
    return found;
  }

  std::unique_ptr<TempDir> dir_;
  std::unique_ptr<ControlNode> node_;
  std::string token_;
};

TEST_F(SignedMessages, OperatorMlDsaSignatureIsVerifiedAndRecorded) {
  auto op = keys_of("operator");
  json::Object msg = rcanpy_move("human");
  ASSERT_TRUE(msgsig::sign_mldsa65(msg, op.mldsa65_sk.span(), op.pub.mldsa65_pk).ok());
  std::string id = msg.find("msg_id")->as_string();
  HttpReply r = send(msg);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value rec = record_of(id);
  ASSERT_FALSE(rec.is_null()) << "no audit record for " << id;
  const json::Value* detail = rec.get("detail");
  ASSERT_NE(detail, nullptr) << json::dump(rec);
  ASSERT_NE(detail->get("sig_kid"), nullptr) << json::dump(rec);
  EXPECT_EQ(detail->get("sig_kid")->as_string(), op.pub.kid());
  EXPECT_EQ(detail->get("sig_alg")->as_string(), "ml-dsa-65");
  // An operator's key does not make the sender a robot (§8.5): the record keeps "human".
  ASSERT_NE(rec.get("sender_type"), nullptr) << json::dump(rec);
  EXPECT_EQ(rec.get("sender_type")->as_string(), "human");
}

TEST_F(SignedMessages, OperatorEd25519SignatureIsVerified) {
  auto op = keys_of("operator");
  json::Object msg = rcanpy_move("human");
  ASSERT_TRUE(msgsig::sign_ed25519(msg, op.ed25519_seed.span()).ok());
  std::string id = msg.find("msg_id")->as_string();
  HttpReply r = send(msg);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value rec = record_of(id);
  ASSERT_FALSE(rec.is_null());
  ASSERT_NE(rec.get("detail"), nullptr);
  ASSERT_NE(rec.get("detail")->get("sig_alg"), nullptr) << json::dump(rec);
  EXPECT_EQ(rec.get("detail")->get("sig_alg")->as_string(), "ed25519");
}

TEST_F(SignedMessages, UnknownSignerIsRefusedAndNothingMoves) {
  auto stranger = keys_of("stranger");
  json::Object msg = rcanpy_move("human");
  ASSERT_TRUE(msgsig::sign_mldsa65(msg, stranger.mldsa65_sk.span(), stranger.pub.mldsa65_pk).ok());
  HttpReply r = send(msg);
  EXPECT_GE(r.status, 400) << r.body;
  EXPECT_EQ(error_code_of(r), "SIGNATURE_INVALID") << r.body;
  HttpReply st = node_->get("/api/status", token_);
  ASSERT_EQ(st.status, 200) << st.body;
  EXPECT_EQ(st.body.find("\"linear_mps\":0.1"), std::string::npos) << st.body;
}

TEST_F(SignedMessages, TamperedAfterSigningIsRefused) {
  auto op = keys_of("operator");
  json::Object msg = rcanpy_move("human");
  ASSERT_TRUE(msgsig::sign_mldsa65(msg, op.mldsa65_sk.span(), op.pub.mldsa65_pk).ok());
  msg.set("params",
          json::Object{{"linear", 0.5}, {"duration_ms", 100}});  // covered by the signature
  HttpReply r = send(msg);
  EXPECT_GE(r.status, 400) << r.body;
  EXPECT_EQ(error_code_of(r), "SIGNATURE_INVALID") << r.body;
}

TEST_F(SignedMessages, PeerRobotKeyStillGivesTheRobotVerdict) {
  auto peer = keys_of("peer");
  json::Object msg = rcanpy_move("robot");
  ASSERT_TRUE(msgsig::sign_mldsa65(msg, peer.mldsa65_sk.span(), peer.pub.mldsa65_pk).ok());
  std::string id = msg.find("msg_id")->as_string();
  HttpReply r = send(msg);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value rec = record_of(id);
  ASSERT_FALSE(rec.is_null());
  ASSERT_NE(rec.get("detail"), nullptr);
  ASSERT_NE(rec.get("detail")->get("sig_kid"), nullptr) << json::dump(rec);
  EXPECT_EQ(rec.get("detail")->get("sig_kid")->as_string(), peer.pub.kid());
}

TEST_F(SignedMessages, OperatorKeyCannotClaimToBeARobot) {
  // sender_type "robot" needs a peer robot's signature (§8.5); an operator's key is not one.
  auto op = keys_of("operator");
  json::Object msg = rcanpy_move("robot");
  ASSERT_TRUE(msgsig::sign_mldsa65(msg, op.mldsa65_sk.span(), op.pub.mldsa65_pk).ok());
  HttpReply r = send(msg);
  EXPECT_GE(r.status, 400) << r.body;
  EXPECT_EQ(error_code_of(r), "AUTH_INVALID") << r.body;
  EXPECT_NE(r.body.find("known robot key"), std::string::npos) << r.body;
}

}  // namespace
}  // namespace rcan::test
