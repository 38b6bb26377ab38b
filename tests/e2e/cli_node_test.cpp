// The rcan CLI against a real rcand, verb by verb: discover, status, claim, command, stream,
// estop, resume, release, handoff, audit export/verify/tail; pending, authorize, thoughts and
// watermark verify against an in-process fake node serving the documented contracts; --help on
// every verb, exit codes, RCAN_URL / RCAN_TOKEN_FILE, --json, and the completion script.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>

#include "fake_node.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

json::Value parse(const std::string& s) {
  auto v = json::parse(s, {.max_depth = 128, .max_bytes = 64u << 20});
  EXPECT_TRUE(v.ok()) << s.substr(0, 400);
  return v.ok() ? *v : json::Value();
}

class CliNodeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir();
    daemon_ = new test::RcandDaemon(dir_->path() + "/node");
  }
  static void TearDownTestSuite() {
    delete daemon_;
    delete dir_;
  }
  // The CLI with the node's URL and the OWNER token in the environment, as rcand suggests.
  static test::RunResult cli(const std::vector<std::string>& args, const std::string& in = {},
                             const std::string& token_file = "") {
    return test::run_cli(
        args, in,
        {"RCAN_URL=" + daemon_->url(),
         "RCAN_TOKEN_FILE=" + (token_file.empty() ? daemon_->owner_token_file() : token_file),
         "NO_COLOR=1"});
  }
  static std::string token_file(const std::string& role, const std::vector<std::string>& scopes,
                                const std::string& sub) {
    std::string path = dir_->file(sub + ".token");
    std::ofstream(path) << daemon_->token(role, scopes, sub) << "\n";
    return path;
  }
  static test::TempDir* dir_;
  static test::RcandDaemon* daemon_;
};
test::TempDir* CliNodeTest::dir_ = nullptr;
test::RcandDaemon* CliNodeTest::daemon_ = nullptr;

TEST_F(CliNodeTest, EveryVerbHasHelpAndTheMainHelpListsThem) {
  auto top = test::run_cli({"--help"});
  ASSERT_EQ(top.exit_code, 0);
  for (const char* verb :
       {"discover", "status", "claim",   "release",   "handoff", "command",   "stream",
        "estop",    "resume", "pending", "authorize", "audit",   "thoughts",  "watermark",
        "keys",     "token",  "ruri",    "json",      "message", "completion"}) {
    EXPECT_NE(top.out.find(std::string("  ") + verb + " "), std::string::npos) << verb;
    auto h = test::run_cli({verb, "--help"});
    EXPECT_EQ(h.exit_code, 0) << verb << ": " << h.err;
    EXPECT_NE(h.out.find("usage"), std::string::npos) << verb;
  }
  EXPECT_NE(top.out.find("3 node unreachable"), std::string::npos);
}

TEST_F(CliNodeTest, DiscoverProbesHostsAndTheEnvironmentsNode) {
  std::string host = "127.0.0.1:" + std::to_string(daemon_->port());
  auto r = test::run_cli({"discover", "--no-mdns", "--hosts", host + ",127.0.0.1:1", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json::Value v = parse(r.out);
  const auto& robots = v.get("robots")->as_array();
  ASSERT_EQ(robots.size(), 1u);  // the dead host is left out
  EXPECT_EQ(robots[0].get("ruri")->as_string(), daemon_->ruri());
  EXPECT_EQ(robots[0].get("source")->as_string(), "probe");
  EXPECT_EQ(robots[0].get("status")->as_string(), "available");
  // No --hosts: $RCAN_URL is probed; readable table.
  auto t = cli({"discover", "--no-mdns"});
  ASSERT_EQ(t.exit_code, 0) << t.err;
  EXPECT_NE(t.out.find("NAME"), std::string::npos);
  EXPECT_NE(t.out.find(daemon_->ruri()), std::string::npos);
  EXPECT_EQ(test::run_cli({"discover", "--no-mdns", "--hosts", "127.0.0.1:1", "--timeout", "500"})
                .exit_code,
            1);
  EXPECT_EQ(test::run_cli({"discover", "--timeout", "abc"}).exit_code, 2);
}

TEST_F(CliNodeTest, StatusTableAndJson) {
  auto t = cli({"status"});
  ASSERT_EQ(t.exit_code, 0) << t.err;
  EXPECT_NE(t.out.find(daemon_->ruri()), std::string::npos);
  EXPECT_NE(t.out.find("estop"), std::string::npos);
  EXPECT_EQ(t.out.find("\x1b["), std::string::npos);  // no colour off a terminal
  auto j = cli({"status", "--json"});
  ASSERT_EQ(j.exit_code, 0);
  EXPECT_EQ(parse(j.out).get("ruri")->as_string(), daemon_->ruri());
  EXPECT_EQ(test::run_cli({"status", "--url", "http://127.0.0.1:1"}).exit_code, 3);
  EXPECT_EQ(test::run_cli({"status", "--url", "gopher://x"}).exit_code, 2);
  EXPECT_EQ(test::run_cli({"status", "--bogus"}).exit_code, 2);
}

TEST_F(CliNodeTest, ClaimDriveStopResumeRelease) {
  std::string alice = token_file("user", {"status", "chat", "control"}, "cli-alice");
  std::string bob = token_file("user", {"status", "control"}, "cli-bob");
  auto c = cli({"claim", "--json"}, "", alice);
  ASSERT_EQ(c.exit_code, 0) << c.err;
  std::string session = parse(c.out).get("payload")->get("session_id")->as_string();
  EXPECT_FALSE(session.empty());
  auto conflict = cli({"claim"}, "", bob);
  EXPECT_EQ(conflict.exit_code, 1);
  EXPECT_NE(conflict.err.find("CONTROL_CONFLICT"), std::string::npos) << conflict.err;

  auto move = cli({"command", "move", "--linear", "0.3", "--angular", "0", "--duration-ms", "300"},
                  "", alice);
  ASSERT_EQ(move.exit_code, 0) << move.err;
  EXPECT_NE(move.out.find("ACK"), std::string::npos);
  auto payload =
      cli({"command", R"({"action":"chat","text":"where are you?"})", "--json"}, "", alice);
  ASSERT_EQ(payload.exit_code, 0) << payload.err;
  EXPECT_EQ(parse(payload.out).get("type")->as_string(), "ACK");
  auto whole = cli({"command", "-"}, R"({"type":"COMMAND","payload":{"action":"status"}})", alice);
  EXPECT_EQ(whole.exit_code, 0) << whole.err;
  auto hb = cli({"command", "heartbeat"}, "", alice);
  EXPECT_EQ(hb.exit_code, 0) << hb.err;
  EXPECT_EQ(cli({"command"}, "", alice).exit_code, 2);
  EXPECT_EQ(cli({"command", "move", "--linear"}, "", alice).exit_code, 2);
  EXPECT_EQ(cli({"command", "{not json"}, "", alice).exit_code, 2);
  EXPECT_EQ(cli({"command", "move", "--confidence", "7"}, "", alice).exit_code, 2);

  auto stop = cli({"estop", "--reason", "cli test"}, "", bob);  // any authenticated role may stop
  ASSERT_EQ(stop.exit_code, 0) << stop.err;
  auto refused = cli({"command", "move", "--linear", "0.1"}, "", alice);
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.err.find("estop_active"), std::string::npos) << refused.err;
  auto st = cli({"status", "--json"});
  EXPECT_TRUE(parse(st.out).get("estop_active")->as_bool());
  auto weak = cli({"resume"}, "", alice);
  EXPECT_EQ(weak.exit_code, 1);
  EXPECT_NE(weak.err.find("INSUFFICIENT_PRIVILEGES"), std::string::npos);
  ASSERT_EQ(cli({"resume"}).exit_code, 0);

  auto rel = cli({"release"}, "", alice);
  ASSERT_EQ(rel.exit_code, 0) << rel.err;
  EXPECT_NE(rel.out.find("RELEASED"), std::string::npos);
  EXPECT_EQ(cli({"release"}, "", alice).exit_code, 1);  // nothing held any more
  EXPECT_EQ(test::run_cli({"claim", "--url", daemon_->url()}).exit_code, 2);  // no token
  // bob queued behind alice and her release promoted him: he lets go, so that the suite's next
  // test (same rcand) finds the robot free.
  EXPECT_EQ(cli({"release"}, "", bob).exit_code, 0);
}

TEST_F(CliNodeTest, MessageSendChecksLocallyThenSendsAsIs) {
  int64_t now = std::chrono::duration_cast<std::chrono::milliseconds>(
                    std::chrono::system_clock::now().time_since_epoch())
                    .count();
  std::string id = new_uuid_v4();
  std::string msg = R"({"version":"1.0.0","type":"COMMAND","message_id":")" + id +
                    R"(","timestamp_ms":)" + std::to_string(now) +
                    R"(,"payload":{"action":"chat","text":"hello"}})";
  auto r = cli({"message", "send"}, msg);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(parse(r.out).get("type")->as_string(), "ACK");
  auto replay = cli({"message", "send"}, msg);  // same message_id again
  EXPECT_EQ(replay.exit_code, 1);
  EXPECT_NE(replay.err.find("REPLAY_DETECTED"), std::string::npos) << replay.err;
  auto bad = cli({"message", "send"}, R"({"version":"2.0","type":"COMMAND","payload":{}})");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.out.find("VERSION_INCOMPATIBLE"), std::string::npos) << bad.out;
}

TEST_F(CliNodeTest, HandoffToANamedUser) {
  std::string carol = token_file("user", {"status", "control"}, "cli-carol");
  std::string dave = token_file("user", {"status", "control"}, "cli-dave");
  auto c = cli({"claim", "--json"}, "", carol);
  ASSERT_EQ(c.exit_code, 0) << c.err;
  std::string session = parse(c.out).get("payload")->get("session_id")->as_string();
  EXPECT_EQ(cli({"handoff", session}, "", carol).exit_code, 2);  // --to missing
  auto h = cli({"handoff", session, "--to", "cli-dave", "--reason", "shift change"}, "", carol);
  ASSERT_EQ(h.exit_code, 0) << h.err;
  EXPECT_NE(h.out.find("AVAILABLE"), std::string::npos);
  auto d = cli({"claim"}, "", dave);
  EXPECT_EQ(d.exit_code, 0) << d.err;
  EXPECT_EQ(cli({"release"}, "", dave).exit_code, 0);
}

TEST_F(CliNodeTest, StreamPrintsTelemetryAndEvents) {
  auto s = cli({"stream", "--count", "3", "--hz", "20", "--json"});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  std::vector<std::string> lines;
  size_t pos = 0;
  while (pos < s.out.size()) {
    size_t nl = s.out.find('\n', pos);
    lines.push_back(s.out.substr(pos, nl - pos));
    pos = nl == std::string::npos ? s.out.size() : nl + 1;
  }
  ASSERT_EQ(lines.size(), 3u) << s.out;
  EXPECT_EQ(parse(lines[0]).get("type")->as_string(), "CONNECT_ACK");
  EXPECT_NE(s.err.find("connected"), std::string::npos);
  auto readable = cli({"stream", "--count", "3", "--hz", "20"});
  ASSERT_EQ(readable.exit_code, 0) << readable.err;
  EXPECT_NE(readable.out.find("telemetry"), std::string::npos);
  // Commands typed on stdin go over the stream and their answers come back.
  auto sent = cli({"stream", "--no-telemetry", "--count", "2", "--send-stdin", "--json"},
                  "{\"action\":\"chat\",\"text\":\"hi\"}\n");
  ASSERT_EQ(sent.exit_code, 0) << sent.err;
  EXPECT_NE(sent.out.find("\"reply_to\""), std::string::npos) << sent.out;
  auto denied = test::run_cli(
      {"stream", "--count", "1", "--url", daemon_->url(), "--token-file", "/dev/null"});
  EXPECT_EQ(denied.exit_code, 1) << denied.err;  // CONNECT refused, not retried
  EXPECT_EQ(test::run_cli({"stream", "--url", "http://127.0.0.1:1", "--token-file",
                           daemon_->owner_token_file(), "--max-attempts", "1"})
                .exit_code,
            3);
}

TEST_F(CliNodeTest, AuditExportVerifyAndTail) {
  ASSERT_EQ(cli({"command", "chat", "--text", "audit me"}).exit_code, 0);
  std::string out = dir_->file("chain.jsonl");
  auto e = cli({"audit", "export", "--out", out});
  ASSERT_EQ(e.exit_code, 0) << e.err;
  std::string secret = daemon_->dir() + "/audit.secret";
  auto v = test::run_cli({"audit", "verify", out, "--secret-file", secret});
  ASSERT_EQ(v.exit_code, 0) << v.out << v.err;
  EXPECT_NE(v.out.find("records verified"), std::string::npos);
  auto live = cli({"audit", "verify", "--secret-file", secret});  // fetched from the node
  EXPECT_EQ(live.exit_code, 0) << live.out << live.err;
  std::string text = test::read_file(out);
  size_t at = text.find("SYSTEM_START");
  ASSERT_NE(at, std::string::npos);
  text[at + 11] = 'X';  // tamper with the first record
  std::ofstream(out, std::ios::trunc) << text;
  EXPECT_EQ(test::run_cli({"audit", "verify", out, "--secret-file", secret}).exit_code, 1);

  auto t = cli({"audit", "tail", "-n", "5"});
  ASSERT_EQ(t.exit_code, 0) << t.err;
  EXPECT_NE(t.out.find("EVENT"), std::string::npos);
  EXPECT_NE(t.out.find("COMMAND"), std::string::npos);
  auto tj = cli({"audit", "tail", "-n", "3", "--json"});
  ASSERT_EQ(tj.exit_code, 0);
  EXPECT_EQ(std::count(tj.out.begin(), tj.out.end(), '\n'), 3);
  std::string user = token_file("user", {"status", "control"}, "cli-auditor");
  auto denied = cli({"audit", "export"}, "", user);
  EXPECT_EQ(denied.exit_code, 1);
  EXPECT_NE(denied.err.find("INSUFFICIENT_PRIVILEGES"), std::string::npos);
  // The listing is the OWNER's too, and every read is recorded.
  auto denied_tail = cli({"audit", "tail"}, "", user);
  EXPECT_EQ(denied_tail.exit_code, 1);
  EXPECT_NE(denied_tail.err.find("INSUFFICIENT_PRIVILEGES"), std::string::npos) << denied_tail.err;
  auto reads = cli({"audit", "tail", "-n", "20"});
  ASSERT_EQ(reads.exit_code, 0) << reads.err;
  EXPECT_NE(reads.out.find("AUDIT_READ"), std::string::npos) << reads.out;
}

TEST(CliFakeNode, WatermarkVerifyAndThePendingExitCode) {
  test::FakeNode fake;
  test::TempDir dir;
  std::string tok = dir.file("t");
  std::ofstream(tok) << test::FakeNode::kGoodToken << "\n";
  std::vector<std::string> env{"RCAN_URL=" + fake.url(), "RCAN_TOKEN_FILE=" + tok, "NO_COLOR=1"};
  auto w = test::run_cli(
      {"watermark", "verify", test::FakeNode::kWatermark, "--rrn", "RRN-000000000001"}, "", env);
  ASSERT_EQ(w.exit_code, 0) << w.err;
  EXPECT_NE(w.out.find("valid"), std::string::npos);
  auto wm = test::run_cli({"watermark", "verify", "rcan-wm-v1:00000000000000000000000000000000"},
                          "", env);
  EXPECT_EQ(wm.exit_code, 1);
  EXPECT_NE(wm.err.find("HTTP_404"), std::string::npos);

  // A gated command: 202 PENDING_AUTH → exit 4 with the way to decide it.
  auto g = test::run_cli({"command", "arm_move", "--joints", "[0,0,0,0,0,0]"}, "", env);
  EXPECT_EQ(g.exit_code, 4) << g.err;
  EXPECT_NE(g.out.find("rcan authorize"), std::string::npos);
}

TEST(CliCompletion, BashScriptIsValidAndKnowsTheVerbs) {
  auto c = test::run_cli({"completion", "bash"});
  ASSERT_EQ(c.exit_code, 0);
  test::TempDir dir;
  std::string f = dir.file("rcan.bash");
  std::ofstream(f) << c.out;
  auto check = test::run({"/bin/bash", "-n", f});
  EXPECT_EQ(check.exit_code, 0) << check.err;
  auto use =
      test::run({"/bin/bash", "-c",
                 "source " + f +
                     "; COMP_WORDS=(rcan cla); COMP_CWORD=1; _rcan; echo \"${COMPREPLY[*]}\"; "
                     "COMP_WORDS=(rcan audit ta); COMP_CWORD=2; _rcan; echo \"${COMPREPLY[*]}\""});
  ASSERT_EQ(use.exit_code, 0) << use.err;
  EXPECT_EQ(use.out, "claim\ntail\n");
}

}  // namespace
}  // namespace rcan
