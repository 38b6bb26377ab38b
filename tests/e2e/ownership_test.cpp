// Leases, ownership transfer, consent requests, network partition and what survives a
// restart — against a real rcand, driven over HTTP, WebSocket and the rcan CLI
// (docs/SESSIONS.md).
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>

#include "node_fixture.h"
#include "rcan/errors.h"

namespace rcan {
namespace {

using test::ControlNode;
using test::HttpReply;
using test::parse_json;

std::string write_token(const std::string& path, const std::string& token) {
  {
    std::ofstream out(path);
    out << token << "\n";
  }
  ::chmod(path.c_str(), 0600);
  return path;
}

class OwnershipE2E : public ::testing::Test {
 protected:
  void start(const std::string& yaml = "") {
    node_ = std::make_unique<ControlNode>(dir_.path() + "/n", yaml);
    ASSERT_TRUE(node_->start());
    owner_ = node_->token("owner", "alice", {"control", "config", "status"});
    owner_file_ = write_token(dir_.file("owner.token"), owner_);
  }
  ControlNode& n() { return *node_; }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(node_->port()); }
  test::RunResult cli(std::vector<std::string> args, const std::string& token_file) {
    args.insert(args.end(), {"--url", url(), "--token-file", token_file});
    return test::run_cli(args);
  }
  std::string mode() {
    auto r = n().get("/rcan/v1/status");
    json::Value v = parse_json(r.body);
    const json::Value* m = v.get("mode");
    return m != nullptr && m->is_string()
               ? m->as_string()
               : "(no mode: " + std::to_string(r.status) + " " + r.body + ")";
  }
  test::TempDir dir_;
  std::unique_ptr<ControlNode> node_;
  std::string owner_, owner_file_;
};

TEST_F(OwnershipE2E, LeaseExpiryMidCommandRevokesEverythingDerivedFromIt) {
  start();
  std::string leasee = n().token("leasee", "lee"), outsider = n().token("user", "outsider"),
              guest_in = n().token("user", "u-in-lease");
  auto granted = cli({"lease", "grant", "--leasee", "lee", "--duration", "3s"}, owner_file_);
  ASSERT_EQ(granted.exit_code, 0) << granted.out << granted.err;
  std::string lease_id = parse_json(granted.out).get("lease_id")->as_string();
  // Only the leasee and those it allows may claim while the lease runs.
  HttpReply out = n().post("/rcan/v1/auth/claim", "{}", outsider);
  EXPECT_EQ(out.status, 409);
  EXPECT_NE(out.body.find("leased"), std::string::npos) << out.body;
  std::string lee_file = write_token(dir_.file("lee.token"), leasee);
  EXPECT_EQ(cli({"lease", "allow", lease_id, "--user", "u-in-lease", "--role", "owner"}, lee_file)
                .exit_code,
            1);
  ASSERT_EQ(cli({"lease", "allow", lease_id, "--user", "u-in-lease", "--role", "user", "--duration",
                 "1h"},
                lee_file)
                .exit_code,
            0);
  EXPECT_EQ(cli({"lease", "allow", lease_id, "--user", "x"},
                write_token(dir_.file("out.token"), outsider))
                .exit_code,
            1);
  auto list = cli({"lease", "list"}, lee_file);
  ASSERT_EQ(list.exit_code, 0) << list.err;
  json::Value leases = parse_json(list.out);
  ASSERT_EQ(leases.get("leases")->as_array().size(), 1u);
  EXPECT_EQ(leases.get("leases")->as_array()[0].get("grants")->as_array().size(), 1u);
  // The leasee's grantee holds control under the lease, bounded by it.
  HttpReply gi = n().post("/rcan/v1/auth/claim", "{}", guest_in);
  ASSERT_EQ(gi.status, 200) << gi.body;
  EXPECT_EQ(parse_json(gi.body).get("payload")->get("lease_id")->as_string(), lease_id);
  EXPECT_LE(parse_json(gi.body).get("payload")->get("expires_in")->as_int(), 3);
  ASSERT_EQ(n().call("DELETE", "/rcan/v1/auth/release", "{}", guest_in).status, 200);
  test::Stream ls(n().port(), leasee);
  HttpReply c = n().post("/rcan/v1/auth/claim", "{}", leasee);
  ASSERT_EQ(c.status, 200) << c.body;
  json::Value g = parse_json(c.body);
  EXPECT_EQ(g.get("payload")->get("lease_id")->as_string(), lease_id);
  EXPECT_EQ(g.get("payload")->get("role")->as_string(), "LEASEE");
  EXPECT_LE(g.get("payload")->get("expires_in")->as_int(), 3);
  // A long drive is under way when the lease ends.
  ASSERT_EQ(n().post("/rcan/v1/command",
                     test::command_msg("move", {{"linear", 0.3}, {"duration_ms", 5000}}), leasee)
                .status,
            200);
  auto revoked = ls.wait_for("SESSION_REVOKED", 8000);
  ASSERT_TRUE(revoked.has_value());
  EXPECT_EQ(revoked->get("session_id")->as_string(),
            g.get("payload")->get("session_id")->as_string());
  ASSERT_TRUE(ControlNode::eventually([&] {
    json::Value st = parse_json(n().get("/rcan/v1/status", owner_).body);
    return st.get("robot")->get("robot")->get("base")->get("linear_mps")->to_double() == 0.0;
  }));
  HttpReply after =
      n().post("/rcan/v1/command", test::command_msg("move", {{"linear", 0.1}}), leasee);
  EXPECT_EQ(after.status, 401);
  EXPECT_EQ(test::error_code_of(after), "SESSION_EXPIRED");
  EXPECT_FALSE(n().audit_eventually("LEASE_ENDED", owner_).empty());
  EXPECT_FALSE(n().audit_eventually("SESSION_REVOKED", owner_).empty());
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", outsider).status, 200);
  // A lease revoked by the owner ends at once.
  auto g2 = cli({"lease", "grant", "--leasee", "lee", "--duration", "1h"}, owner_file_);
  ASSERT_EQ(g2.exit_code, 0) << g2.out;
  std::string id2 = parse_json(g2.out).get("lease_id")->as_string();
  EXPECT_EQ(cli({"lease", "revoke", id2}, lee_file).exit_code, 1);  // only an OWNER revokes
  EXPECT_EQ(cli({"lease", "revoke", id2}, owner_file_).exit_code, 0);
  EXPECT_EQ(parse_json(cli({"lease", "list"}, owner_file_).out).get("leases")->as_array().size(),
            0u);
}

TEST_F(OwnershipE2E, TransferAcceptedClearsPersonalDataKeepsTheChainAndCapsTheFormerOwner) {
  start();
  std::string bob = n().token("owner", "bob", {"control", "config", "status"}),
              eve = n().token("owner", "eve"), user = n().token("user", "someone");
  std::string bob_file = write_token(dir_.file("bob.token"), bob);
  ASSERT_EQ(n().post("/rcan/v1/auth/claim", "{}", user).status, 200);
  ASSERT_EQ(cli({"lease", "grant", "--leasee", "lee", "--duration", "1h"}, owner_file_).exit_code,
            0);
  test::Stream us(n().port(), user);
  auto req = cli({"transfer", "request", "--to", "bob", "--note", "sold"}, owner_file_);
  ASSERT_EQ(req.exit_code, 0) << req.out << req.err;
  std::string tid = parse_json(req.out).get("transfer_id")->as_string();
  auto st = cli({"transfer", "status"}, bob_file);
  ASSERT_EQ(st.exit_code, 0);
  json::Value sv = parse_json(st.out);
  EXPECT_EQ(sv.get("state")->as_string(), "TRANSFER_PENDING");
  EXPECT_EQ(sv.get("pending")->get("to")->as_string(), "bob");
  EXPECT_EQ(
      cli({"transfer", "accept", tid, "--agreement", "x"}, write_token(dir_.file("eve.token"), eve))
          .exit_code,
      1);
  auto acc = cli({"transfer", "accept", tid, "--agreement", "invoice-42"}, bob_file);
  ASSERT_EQ(acc.exit_code, 0) << acc.out << acc.err;
  json::Value av = parse_json(acc.out);
  EXPECT_EQ(av.get("state")->as_string(), "OWNED");
  EXPECT_EQ(av.get("owner")->as_string(), "bob");
  EXPECT_EQ(av.get("users")->as_int(), 0);
  EXPECT_TRUE(us.wait_for("SESSION_REVOKED").has_value());
  json::Value status = parse_json(n().get("/rcan/v1/status", bob).body);
  EXPECT_EQ(status.get("active_sessions")->as_int(), 0);
  EXPECT_EQ(parse_json(n().get("/rcan/v1/leases", bob).body).get("leases")->as_array().size(), 0u);
  // The former owner's token is a GUEST now; the new owner has the owner's powers.
  HttpReply old_claim = n().post("/rcan/v1/auth/claim", "{}", owner_);
  EXPECT_EQ(old_claim.status, 403);
  // …on every route that reads a bearer token, not only the control routes: the owner-only
  // chain export refuses it too.
  EXPECT_EQ(n().get("/api/v1/audit?format=jsonl", owner_).status, 403);
  EXPECT_EQ(n().get("/api/v1/audit?format=jsonl", bob).status, 200);
  EXPECT_EQ(cli({"lease", "grant", "--leasee", "x"}, owner_file_).exit_code, 1);
  EXPECT_EQ(cli({"transfer", "request", "--to", "alice"}, owner_file_).exit_code, 1);
  EXPECT_EQ(cli({"lease", "grant", "--leasee", "x", "--duration", "10m"}, bob_file).exit_code, 0);
  // Every step is in the (unbroken) chain.
  auto reqs = n().audit("TRANSFER_REQUEST", bob);
  auto accs = n().audit("TRANSFER_ACCEPT", bob);
  ASSERT_EQ(reqs.size(), 1u);
  ASSERT_EQ(accs.size(), 1u);
  EXPECT_EQ(accs[0].get("detail")->get("to")->as_string(), "bob");
  EXPECT_EQ(accs[0].get("detail")->get("agreement")->as_string(), "invoice-42");
  EXPECT_FALSE(n().audit_eventually("TRANSFER_DENIED", bob).empty());
  n().stop();
  auto verify = test::run_cli({"audit", "verify", "--data-dir", n().data_dir(), "--secret-file",
                               n().data_dir() + "/audit.secret"});
  EXPECT_EQ(verify.exit_code, 0) << verify.out << verify.err;
}

// Two trusted issuers may both know a subject "bob": they are two principals. A transfer, a
// handoff and a lease name issuer and subject (the requester's issuer unless the request says
// another), and only that principal accepts, claims or acts as the owner.
// R13: below OWNER, the HiTL pending list shows one's own held commands — one's own by issuer
// and subject, not by subject alone.
TEST_F(OwnershipE2E, THePendingListBelowOwnerIsOnesOwnByIssuerAndSubject) {
  start("      - issuer: partner.example\n        key_file: " + dir_.path() +
        "/n/issuer.pub.pem\n"
        "agent:\n  hitl_gates:\n    - {action_types: [arm_move], require_auth: true,"
        " auth_timeout_ms: 60000, on_timeout: block}\n");
  const std::string dan = n().token("leasee", "dan", {"control", "status"});
  const std::string partner_dan = n().token("leasee", "dan", {"control", "status"}, 3600,
                                            json::Object{{"iss", "partner.example"}});
  const std::string id = new_uuid_v4();
  json::Object cmd{{"version", "1.0.0"},
                   {"message_id", id},
                   {"type", "COMMAND"},
                   {"timestamp_ms", test::now_wall_ms()},
                   {"payload", json::Object{{"action", "arm_move"},
                                            {"joints", json::Array{0.1, 0, 0, 0, 0, 0}}}}};
  HttpReply held = n().post("/rcan/v1/command", json::dump(json::Value(cmd)), dan);
  ASSERT_EQ(held.status, 202) << held.body;
  auto listed = [&](const std::string& token) {
    HttpReply r = n().get("/rcan/v1/pending", token);
    EXPECT_EQ(r.status, 200) << r.body;
    return r.body;
  };
  EXPECT_NE(listed(dan).find(id), std::string::npos);
  EXPECT_EQ(listed(partner_dan).find(id), std::string::npos) << "another issuer's dan sees it";
  EXPECT_NE(listed(owner_).find(id), std::string::npos);
  EXPECT_NE(listed(owner_).find("\"requested_by_iss\":\"ops.example\""), std::string::npos);
}

TEST_F(OwnershipE2E, TwoIssuersWithTheSameSubjectAreTwoPrincipals) {
  start("      - issuer: partner.example\n        key_file: " + dir_.path() +
        "/n/issuer.pub.pem\n");
  auto partner = [&](const std::string& role, const std::string& sub,
                     std::vector<std::string> scopes = {"control"}) {
    return n().token(role, sub, std::move(scopes), 3600, json::Object{{"iss", "partner.example"}});
  };
  auto transfer = [&](const std::string& token, json::Object body) {
    return n().post("/rcan/v1/transfer", json::dump(json::Value(std::move(body))), token);
  };
  // Ownership: alice (ops.example) transfers to bob — bob of ops.example.
  HttpReply req = transfer(owner_, {{"action", "request"}, {"new_owner", "bob"}});
  ASSERT_EQ(req.status, 200) << req.body;
  json::Value rv = parse_json(req.body);
  std::string tid = rv.get("transfer_id")->as_string();
  ASSERT_NE(rv.get("pending"), nullptr) << req.body;
  EXPECT_EQ(json::string_field(*rv.get("pending"), "to_iss"), "ops.example") << req.body;
  const std::string partner_bob = partner("owner", "bob", {"control", "config", "status"});
  HttpReply stolen =
      transfer(partner_bob, {{"action", "accept"}, {"transfer_id", tid}, {"agreement", "x"}});
  EXPECT_EQ(stolen.status, 403) << stolen.body;
  EXPECT_EQ(test::error_code_of(stolen), "INSUFFICIENT_PRIVILEGES");
  const std::string bob = n().token("owner", "bob", {"control", "config", "status"});
  HttpReply acc = transfer(bob, {{"action", "accept"}, {"transfer_id", tid}, {"agreement", "y"}});
  ASSERT_EQ(acc.status, 200) << acc.body;
  json::Value av = parse_json(acc.body);
  EXPECT_EQ(json::string_field(av, "owner"), "bob");
  EXPECT_EQ(json::string_field(av, "owner_iss"), "ops.example") << acc.body;
  // The other issuer's bob is not the owner: it may not give the robot away.
  HttpReply not_owner = transfer(partner_bob, {{"action", "request"}, {"new_owner", "mallory"}});
  EXPECT_EQ(not_owner.status, 403) << not_owner.body;
  // A transfer may name a principal of another issuer explicitly.
  HttpReply named = transfer(
      bob, {{"action", "request"}, {"new_owner", "bob"}, {"new_owner_iss", "partner.example"}});
  ASSERT_EQ(named.status, 200) << named.body;
  json::Value nv = parse_json(named.body);
  ASSERT_NE(nv.get("pending"), nullptr) << named.body;
  EXPECT_EQ(json::string_field(*nv.get("pending"), "to_iss"), "partner.example") << named.body;
  ASSERT_EQ(transfer(bob, {{"action", "cancel"}}).status, 200);

  // Handoff to carol (ops.example): the other issuer's carol may not take the reserved control.
  const std::string dan = n().token("user", "dan");
  HttpReply claim = n().post("/rcan/v1/auth/claim", "{}", dan);
  ASSERT_EQ(claim.status, 200) << claim.body;
  std::string sid = parse_json(claim.body).get("payload")->get("session_id")->as_string();
  HttpReply handoff = n().post(
      "/rcan/v1/handoff",
      json::dump(json::Value(json::Object{{"session_id", sid}, {"target_user_id", "carol"}})), dan);
  ASSERT_EQ(handoff.status, 200) << handoff.body;
  HttpReply wrong_carol = n().post("/rcan/v1/auth/claim", "{}", partner("user", "carol"));
  EXPECT_EQ(wrong_carol.status, 409) << wrong_carol.body;
  const std::string carol = n().token("user", "carol");
  HttpReply carol_claim = n().post("/rcan/v1/auth/claim", "{}", carol);
  ASSERT_EQ(carol_claim.status, 200) << carol_claim.body;
  ASSERT_EQ(n().call("DELETE", "/rcan/v1/auth/release", "{}", carol).status, 200);

  // A lease to lee (ops.example): the other issuer's lee is an outsider to it.
  HttpReply lease =
      n().post("/rcan/v1/leases",
               json::dump(json::Value(json::Object{{"leasee", "lee"}, {"duration_s", 3600}})), bob);
  ASSERT_EQ(lease.status, 201) << lease.body;
  EXPECT_EQ(json::string_field(parse_json(lease.body), "leasee_iss"), "ops.example") << lease.body;
  HttpReply wrong_lee = n().post("/rcan/v1/auth/claim", "{}", partner("leasee", "lee"));
  EXPECT_EQ(wrong_lee.status, 409) << wrong_lee.body;
  EXPECT_NE(wrong_lee.body.find("leased"), std::string::npos) << wrong_lee.body;
  HttpReply lee = n().post("/rcan/v1/auth/claim", "{}", n().token("leasee", "lee"));
  EXPECT_EQ(lee.status, 200) << lee.body;
}

TEST_F(OwnershipE2E, TransferCancelAndATransferAcceptedAfterExpiryChangesNothing) {
  start("control:\n  transfer_window_s: 1\n");
  std::string bob = n().token("user", "bob");
  std::string bob_file = write_token(dir_.file("bob.token"), bob);
  auto r1 = cli({"transfer", "request", "--to", "bob"}, owner_file_);
  ASSERT_EQ(r1.exit_code, 0) << r1.out;
  EXPECT_EQ(cli({"transfer", "cancel"}, owner_file_).exit_code, 0);
  EXPECT_EQ(parse_json(cli({"transfer", "status"}, owner_file_).out).get("state")->as_string(),
            "OWNED");
  EXPECT_FALSE(n().audit("TRANSFER_CANCEL", owner_).empty());
  auto r2 = cli({"transfer", "request", "--to", "bob"}, owner_file_);
  ASSERT_EQ(r2.exit_code, 0);
  std::string tid = parse_json(r2.out).get("transfer_id")->as_string();
  ASSERT_TRUE(ControlNode::eventually(
      [&] { return !n().audit("TRANSFER_EXPIRED", owner_).empty(); }, 5000));
  HttpReply late = n().post(
      "/rcan/v1/transfer",
      "{\"action\":\"accept\",\"transfer_id\":\"" + tid + "\",\"agreement\":\"paid\"}", bob);
  EXPECT_EQ(late.status, 404) << late.body;  // the expired transfer is gone
  json::Value st = parse_json(n().get("/rcan/v1/transfer", owner_).body);
  EXPECT_EQ(st.get("state")->as_string(), "OWNED");
  EXPECT_TRUE(st.get("owner")->is_null());
  // The owner still acts as the owner.
  EXPECT_EQ(cli({"lease", "grant", "--leasee", "lee", "--duration", "10m"}, owner_file_).exit_code,
            0);
}

TEST_F(OwnershipE2E, ConsentFromACloudFunctionNotifiesTheOwnerWithItsIdentity) {
  test::TinyHttpServer hook;
  ASSERT_TRUE(hook.start());
  start("control:\n  consent_webhook: " + hook.url("/notify") + "\n");
  test::Stream os(n().port(), owner_);
  std::string fn =
      n().token("user", "firebase-cloud-functions", {"control"}, 3600,
                json::Object{{"sender_type", "cloud_function"}, {"cloud_provider", "firebase"}});
  json::Object msg{{"type", "CONSENT_REQUEST"},
                   {"sender_type", "cloud_function"},
                   {"cloud_provider", "firebase"},
                   {"function_name", "castor-bridge-v2"},
                   {"payload", json::Object{{"scopes", json::Array{"control"}},
                                            {"on_behalf_of", "Craig"},
                                            {"duration_s", 600}}}};
  HttpReply r = n().post("/rcan/v1/consent", json::dump(json::Value(msg)), fn);
  ASSERT_EQ(r.status, 202) << r.body;
  json::Value rv = parse_json(r.body);
  std::string cid = rv.get("consent_id")->as_string();
  const std::string body =
      "Firebase function 'castor-bridge-v2' (on behalf of Craig) is requesting\naccess to Robot B "
      "with scope: [control]";
  auto ev = os.wait_for("CONSENT_REQUEST");
  ASSERT_TRUE(ev.has_value());
  EXPECT_EQ(ev->get("notification")->get("title")->as_string(),
            "\xE2\x9A\xA0\xEF\xB8\x8F Service Consent Request");
  EXPECT_EQ(ev->get("notification")->get("body")->as_string(), body);
  EXPECT_EQ(ev->get("notification")->get("highlight")->as_string(),
            "cloud_function: castor-bridge-v2 via firebase");
  ASSERT_TRUE(ControlNode::eventually([&] { return !hook.bodies().empty(); }));
  json::Value posted = parse_json(hook.bodies()[0]);
  EXPECT_EQ(posted.get("body")->as_string(), body);
  EXPECT_EQ(posted.get("highlight")->as_string(), "cloud_function: castor-bridge-v2 via firebase");
  ASSERT_TRUE(
      ControlNode::eventually([&] { return !n().audit("CONSENT_NOTIFIED", owner_).empty(); }));
  // A cloud function cannot pass itself off as one without its identity.
  json::Object bad = msg;
  bad.erase("function_name");
  EXPECT_GE(n().post("/rcan/v1/consent", json::dump(json::Value(bad)), fn).status, 400);
  // The owner sees it and grants a lease; a human's request is denied.
  auto list = cli({"consent", "list"}, owner_file_);
  ASSERT_EQ(list.exit_code, 0) << list.err;
  EXPECT_NE(list.out.find(cid), std::string::npos);
  EXPECT_EQ(cli({"consent", "grant", cid}, write_token(dir_.file("fn.token"), fn)).exit_code, 1);
  auto grant = cli({"consent", "grant", cid, "--duration", "10m"}, owner_file_);
  ASSERT_EQ(grant.exit_code, 0) << grant.out << grant.err;
  json::Value gv = parse_json(grant.out);
  EXPECT_EQ(gv.get("status")->as_string(), "GRANTED");
  json::Value leases = parse_json(n().get("/rcan/v1/leases", owner_).body);
  ASSERT_EQ(leases.get("leases")->as_array().size(), 1u);
  EXPECT_EQ(leases.get("leases")->as_array()[0].get("leasee")->as_string(),
            "firebase-cloud-functions");
  EXPECT_EQ(cli({"consent", "grant", cid}, owner_file_).exit_code, 1);  // decided once
  std::string craig = n().token("user", "Craig", {"control"});
  HttpReply hr =
      n().post("/rcan/v1/consent", "{\"payload\":{\"scopes\":[\"status\",\"chat\"]}}", craig);
  ASSERT_EQ(hr.status, 202) << hr.body;
  json::Value hv = parse_json(hr.body);
  EXPECT_EQ(hv.get("notification")->get("title")->as_string(), "Consent Request");
  EXPECT_EQ(hv.get("notification")->get("body")->as_string(),
            "Craig is requesting access to Robot B with scope: [status, chat]");
  auto deny = cli({"consent", "deny", hv.get("consent_id")->as_string(), "--reason", "not today"},
                  owner_file_);
  ASSERT_EQ(deny.exit_code, 0) << deny.out;
  EXPECT_EQ(parse_json(deny.out).get("status")->as_string(), "DENIED");
  // Audited with the sender identity.
  auto reqs = n().audit("CONSENT_REQUEST", owner_);
  ASSERT_EQ(reqs.size(), 2u);
  EXPECT_EQ(reqs[0].get("sender_type")->as_string(), "cloud_function");
  EXPECT_EQ(reqs[0].get("function_name")->as_string(), "castor-bridge-v2");
  EXPECT_EQ(reqs[0].get("cloud_provider")->as_string(), "firebase");
  EXPECT_EQ(reqs[1].get("sender_type")->as_string(), "human");
  auto granted = n().audit("CONSENT_GRANTED", owner_);
  ASSERT_EQ(granted.size(), 1u);
  EXPECT_EQ(granted[0].get("detail")->get("requester_sender_type")->as_string(), "cloud_function");
  EXPECT_EQ(n().audit("CONSENT_DENIED", owner_).size(), 1u);
  EXPECT_GE(n().audit_eventually("CONSENT_REFUSED", owner_, 2).size(),
            2u);  // the bad request and the non-owner's grant
}

TEST_F(OwnershipE2E, PartitionEnteringAndLeavingOfflineAutonomousAndLockdown) {
  test::TinyHttpServer issuer;
  ASSERT_TRUE(issuer.start());
  uint16_t issuer_port = issuer.port();
  start("offline:\n  issuer_url: " + issuer.url("/jwks.json") +
        "\n  issuer_poll_ms: 50\n  issuer_timeout_ms: 200\n  max_key_ttl_s: 4\n");
  ASSERT_TRUE(ControlNode::eventually([&] { return issuer.hits() > 0; }));
  EXPECT_EQ(mode(), "NORMAL");
  std::string a = n().token("user", "known"), b = n().token("user", "stranger");
  // `known` is validated while the issuer answers (and released again).
  HttpReply ca = n().post("/rcan/v1/auth/claim", "{}", a);
  ASSERT_EQ(ca.status, 200);
  ASSERT_EQ(n().call("DELETE", "/rcan/v1/auth/release", "{}", a).status, 200);
  issuer.stop();
  ASSERT_TRUE(ControlNode::eventually([&] { return mode() == "OFFLINE_AUTONOMOUS"; }));
  EXPECT_NE(n().get("/metrics").body.find("rcan_partition_mode 1"), std::string::npos);
  HttpReply cb = n().post("/rcan/v1/auth/claim", "{}", b);
  EXPECT_EQ(cb.status, 503);
  EXPECT_EQ(test::error_code_of(cb), "LOCKDOWN");
  HttpReply drive = n().post("/rcan/v1/command", test::command_msg("move", {{"linear", 0.1}}), b);
  EXPECT_EQ(drive.status,
            503);  // no session-less control for a principal the node cannot vouch for
  EXPECT_EQ(test::error_code_of(drive), "LOCKDOWN");
  HttpReply ca2 = n().post("/rcan/v1/auth/claim", "{}", a);
  ASSERT_EQ(ca2.status, 200) << ca2.body;  // continues with cached credentials
  auto claims = n().audit("CLAIM", owner_);
  ASSERT_FALSE(claims.empty());
  EXPECT_EQ(claims.back().get("detail")->get("partition_mode")->as_string(), "OFFLINE_AUTONOMOUS");
  EXPECT_TRUE(claims.back().get("detail")->get("sync_pending")->as_bool());
  // The cache runs out: LOCKDOWN. The existing session is kept; no new ones.
  ASSERT_TRUE(ControlNode::eventually([&] { return mode() == "LOCKDOWN"; }, 8000));
  EXPECT_EQ(n().post("/rcan/v1/command",
                     test::command_msg("move", {{"linear", 0.1}, {"duration_ms", 100}}), a)
                .status,
            200);
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", b).status, 503);
  json::Value st = parse_json(n().get("/rcan/v1/status", owner_).body);
  EXPECT_EQ(st.get("partition")->get("issuer_reachable")->as_bool(), false);
  // The issuer comes back: NORMAL, and every change was recorded.
  test::TinyHttpServer again;
  ASSERT_TRUE(again.start(issuer_port));
  ASSERT_TRUE(ControlNode::eventually([&] { return mode() == "NORMAL"; }));
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", b).status,
            409);  // a's session still holds: plain conflict
  auto modes = n().audit_eventually("PARTITION_MODE", owner_, 3);
  ASSERT_GE(modes.size(), 3u);
  EXPECT_EQ(modes[modes.size() - 3].get("detail")->get("to")->as_string(), "OFFLINE_AUTONOMOUS");
  EXPECT_EQ(modes[modes.size() - 2].get("detail")->get("to")->as_string(), "LOCKDOWN");
  EXPECT_EQ(modes.back().get("detail")->get("to")->as_string(), "NORMAL");
}

TEST_F(OwnershipE2E, LeasesTransferConsentAndTheCredentialCacheSurviveARestart) {
  test::TinyHttpServer issuer;
  ASSERT_TRUE(issuer.start());
  start("offline:\n  issuer_url: " + issuer.url("/jwks.json") +
        "\n  issuer_poll_ms: 100\n  max_key_ttl_s: 600\n");
  std::string a = n().token("user", "known");
  ASSERT_EQ(n().post("/rcan/v1/auth/claim", "{}", a).status, 200);
  auto lease = cli({"lease", "grant", "--leasee", "known", "--duration", "1h"}, owner_file_);
  ASSERT_EQ(lease.exit_code, 0);
  std::string lease_id = parse_json(lease.out).get("lease_id")->as_string();
  ASSERT_EQ(cli({"transfer", "request", "--to", "bob"}, owner_file_).exit_code, 0);
  HttpReply cr = n().post("/rcan/v1/consent", "{\"payload\":{\"scopes\":[\"control\"]}}",
                          n().token("user", "asker"));
  ASSERT_EQ(cr.status, 202);
  std::string cid = parse_json(cr.body).get("consent_id")->as_string();
  EXPECT_EQ(n().stop(), 0);
  for (const char* f : {"leases.json", "ownership.json", "consent.json", "credentials.json"}) {
    struct stat sb {};
    ASSERT_EQ(::stat((n().data_dir() + "/" + f).c_str(), &sb), 0) << f;
    EXPECT_EQ(sb.st_mode & 0777, 0600u) << f;
  }
  issuer.stop();  // the node comes back up partitioned
  ASSERT_TRUE(n().start());
  json::Value leases = parse_json(n().get("/rcan/v1/leases", owner_).body);
  ASSERT_EQ(leases.get("leases")->as_array().size(), 1u);
  EXPECT_EQ(leases.get("leases")->as_array()[0].get("lease_id")->as_string(), lease_id);
  json::Value tr = parse_json(n().get("/rcan/v1/transfer", owner_).body);
  EXPECT_EQ(tr.get("state")->as_string(), "TRANSFER_PENDING");
  EXPECT_EQ(tr.get("pending")->get("to")->as_string(), "bob");
  EXPECT_NE(n().get("/rcan/v1/consent", owner_).body.find(cid), std::string::npos);
  // The credential cache came back: offline, the known principal still gets a session.
  ASSERT_TRUE(ControlNode::eventually([&] { return mode() == "OFFLINE_AUTONOMOUS"; }));
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", a).status, 200);
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", n().token("user", "stranger")).status, 503);
}

}  // namespace
}  // namespace rcan
