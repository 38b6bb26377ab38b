// A robot joins its registry (docs/REGISTRY.md §A robot joins its registry), and the CLI's
// registry verbs: a real rcan-registry and a real rcand, both started here.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include "joining_robot.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/registry_proof.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/registry.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {
namespace {

namespace fs = std::filesystem;

template <typename F>
bool eventually(F f, int timeout_ms) {
  for (int waited = 0; waited < timeout_ms; waited += 50) {
    if (f()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return f();
}

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

TEST(RegistryJoin, ARobotRegistersWithProofOfPossessionAndKeepsItsRrn) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  const std::string key =
      registrant_key_file(reg, dir.file("registry"), dir.file("registrant.key"));
  JoiningRobot robot(dir.file("robot"), reg.url(), key);
  const std::string rrn = robot.start();
  ASSERT_EQ(rrn.rfind("RRN-", 0), 0u) << rrn;

  // The registry holds the robot under that RRN, with the keys it proved it holds.
  auto got = reg.get("/api/v1/robots/" + rrn);
  ASSERT_EQ(got.status, 200) << got.body;
  json::Value rec = json_of(got.body);
  EXPECT_EQ(str(rec, "manufacturer"), "acme");
  EXPECT_EQ(str(rec, "model"), "rover");
  EXPECT_EQ(str(rec, "device_id"), "0a1b2c3d");
  const Bytes ed = to_bytes(read_file(robot.data() + "/keys/ed25519.pub"));
  const Bytes ml = to_bytes(read_file(robot.data() + "/keys/mldsa65.pub"));
  EXPECT_EQ(str(rec, "ed25519_public_key"), base64url_encode(ed));
  EXPECT_EQ(str(rec, "mldsa65_public_key"), base64url_encode(ml));
  ASSERT_NE(rec.get("metadata"), nullptr);
  EXPECT_EQ(str(*rec.get("metadata"), "ruri"), kRuri);

  // Its own registry key is kept with the RRN, readable by the robot alone.
  struct stat st {};
  ASSERT_EQ(::stat((robot.data() + "/registry/state.json").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  json::Value state = json_of(read_file(robot.data() + "/registry/state.json"));
  EXPECT_EQ(str(state, "rrn"), rrn);
  EXPECT_EQ(str(state, "robot_key").rfind("rcan_", 0), 0u);

  // The link's first refresh (signed with the robot's key) is taken.
  EXPECT_TRUE(eventually(
      [&] {
        json::Value now_rec = json_of(reg.get("/api/v1/robots/" + rrn).body);
        return str(now_rec, "updated_at") > str(now_rec, "registered_at");
      },
      5000));
  EXPECT_EQ(robot.proc().err().find("registry_refresh_failed"), std::string::npos)
      << robot.proc().err();

  // Anyone resolves the robot's RURI to where it answers and to its keys.
  auto res = run_cli({"resolve", kRuri, "--registry", reg.url()});
  EXPECT_EQ(res.exit_code, 0) << res.out << res.err;
  EXPECT_NE(res.out.find("rrn: " + rrn), std::string::npos) << res.out;
  EXPECT_NE(res.out.find("endpoint: " + robot.url()), std::string::npos) << res.out;
  EXPECT_NE(res.out.find("ed25519_public_key: " + base64url_encode(ed)), std::string::npos);

  // The CLI reaches the robot by its RRN or its RURI, through the registry.
  const std::string token = robot.owner_token_file();
  for (const std::string& name : {rrn, std::string(kRuri)}) {
    auto status = run_cli(
        {"status", "--url", name, "--registry", reg.url(), "--token-file", token, "--json"});
    EXPECT_EQ(status.exit_code, 0) << name << ": " << status.out << status.err;
    EXPECT_NE(status.out.find(rrn), std::string::npos) << status.out;
  }
  auto unknown = run_cli(
      {"status", "--url", "RRN-000000009999", "--registry", reg.url(), "--token-file", token});
  EXPECT_NE(unknown.exit_code, 0);
  EXPECT_NE(unknown.err.find("does not know RRN-000000009999"), std::string::npos) << unknown.err;

  // A restart keeps the RRN and registers nothing new.
  EXPECT_EQ(robot.stop(), 0);
  EXPECT_EQ(robot.start(), rrn);
  auto list = json_of(reg.get("/api/v1/robots").body);
  EXPECT_EQ(list.get("total")->as_int(), 1);
}

// `rcand init --join` writes the registry block; the robot it made joins at its first start.
TEST(RegistryJoin, RcandInitJoinMakesARobotThatRegistersAtItsFirstStart) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  const std::string key =
      registrant_key_file(reg, dir.file("registry"), dir.file("registrant.key"));
  const uint16_t port = free_port();
  const std::string endpoint = "http://127.0.0.1:" + std::to_string(port);
  auto init =
      run({RCAND_PATH, "init", "--dir", dir.file("robot"), "--yes", "--port", std::to_string(port),
           "--join", reg.url(), "--registry-key", key, "--endpoint", endpoint});
  ASSERT_EQ(init.exit_code, 0) << init.out << init.err;
  EXPECT_EQ(
      run({RCAND_PATH, "init", "--dir", dir.file("other"), "--yes", "--join", reg.url()}).exit_code,
      2);  // --join without a key
  Process rcand;
  ASSERT_TRUE(rcand.start({RCAND_PATH, "--config", dir.file("robot") + "/robot.rcan.yaml"}));
  auto line = rcand.wait_for_line("\"event\":\"listening\"", 60000);
  ASSERT_TRUE(line.has_value()) << rcand.err();
  const std::string rrn = str(json_of(*line), "rrn");
  auto rec = reg.get("/api/v1/robots/" + rrn);
  ASSERT_EQ(rec.status, 200) << rrn << " " << rec.body;
  auto res = json_of(reg.get("/api/v1/resolve/" + rrn).body);
  ASSERT_TRUE(res.get("endpoints") != nullptr && res.get("endpoints")->is_array());
  EXPECT_EQ(str(res.get("endpoints")->as_array().at(0), "url"), endpoint);
  EXPECT_EQ(rcand.stop(SIGTERM, 15000), 0);
}

TEST(RegistryJoin, AnUnusableRegistryDoesNotStopTheRobotAndTheLinkRegistersLater) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  // A key the registry does not know: registration is refused at start.
  const std::string key = dir.file("registrant.key");
  write_private(key, "rcan_0123456789abcdef_" + std::string(64, '0') + "\n");
  JoiningRobot robot(dir.file("robot"), reg.url(), key);
  const std::string local = robot.start();
  ASSERT_FALSE(local.empty());
  EXPECT_NE(robot.proc().err().find("registry_registration_failed"), std::string::npos);
  EXPECT_FALSE(fs::exists(robot.data() + "/registry/state.json"));

  // With a good key in place, the background link registers (first retry after 5 s).
  registrant_key_file(reg, dir.file("registry"), dir.file("good.key"));
  fs::rename(dir.file("good.key"), key);
  bool registered = false;
  for (int i = 0; i < 150 && !registered; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    registered = fs::exists(robot.data() + "/registry/state.json");
  }
  ASSERT_TRUE(registered) << robot.proc().err();
  const std::string rrn = str(json_of(read_file(robot.data() + "/registry/state.json")), "rrn");
  EXPECT_EQ(reg.get("/api/v1/robots/" + rrn).status, 200);
  // Adopted at the next start.
  EXPECT_EQ(robot.stop(), 0);
  EXPECT_EQ(robot.start(), rrn);
}

// Seed §4.1–4.2 and §6.1 with every party real: a registry, two robots that register
// themselves and trust its tokens, and an operator who gets a USER token for one of them from
// the registry and drives it by RRN with rcan.
TEST(RegistryEndToEnd,
     ATokenFromTheRegistryDrivesItsRobotOnlyUntilRevokedAndTheRobotFollowsTheRegistry) {
  TempDir dir;
  const uint16_t reg_port = free_port();
  auto reg = std::make_unique<RegistryDaemon>(
      dir.file("registry"), std::vector<std::string>{"--port", std::to_string(reg_port)});
  ASSERT_FALSE(reg->url().empty());
  const std::string url = reg->url();
  const std::string key =
      registrant_key_file(*reg, dir.file("registry"), dir.file("registrant.key"));
  const std::string trust =
      "  trust_tokens: true\n  revocations_refresh_s: 1\n  max_key_age_s: 4\n";
  const std::string offline = "offline:\n  issuer_poll_ms: 100\n  issuer_timeout_ms: 300\n";
  JoiningRobot a(dir.file("a"), url, key, "rcan://local.rcan/acme/rover/0a1b2c3d", trust, offline);
  JoiningRobot b(dir.file("b"), url, key, "rcan://local.rcan/acme/rover/0a1b2c3e", trust, offline);
  const std::string rrn_a = a.start(), rrn_b = b.start();
  ASSERT_FALSE(rrn_a.empty());
  ASSERT_FALSE(rrn_b.empty());
  ASSERT_NE(rrn_a, rrn_b);

  // The registrant (who registered both robots) makes a client and grants it USER on robot A.
  auto c = reg->send("POST", "/api/v1/clients", R"({"name":"alice-cli","auth":"client_secret"})",
                     read_file(key).substr(0, read_file(key).find('\n')));
  ASSERT_EQ(c.status, 201) << c.body;
  const json::Value client = json_of(c.body);
  write_private(dir.file("client.secret"), str(client, "client_secret"));
  auto g = reg->send("POST", "/api/v1/grants",
                     R"({"principal":")" + str(client, "client_id") + R"(","robot":")" + rrn_a +
                         R"(","role":"user","scope":["status","control"],"max_ttl_s":600})",
                     read_file(key).substr(0, read_file(key).find('\n')));
  ASSERT_EQ(g.status, 201) << g.body;
  auto t = run_cli({"token", "get", "--registry", url, "--client-id", str(client, "client_id"),
                    "--client-secret-file", dir.file("client.secret"), "--robot", rrn_a, "--save",
                    dir.file("user.token")});
  ASSERT_EQ(t.exit_code, 0) << t.out << t.err;
  const std::string token = dir.file("user.token");

  // Robot A takes it (by RRN, through the registry): status, a claim, a move.
  const std::vector<std::string> at_a{"--url", rrn_a, "--registry", url, "--token-file", token};
  auto with = [](std::vector<std::string> v, const std::vector<std::string>& more) {
    v.insert(v.end(), more.begin(), more.end());
    return v;
  };
  auto st = run_cli(with({"status", "--json"}, at_a));
  EXPECT_EQ(st.exit_code, 0) << st.out << st.err;
  auto claim = run_cli(with({"claim"}, at_a));
  EXPECT_EQ(claim.exit_code, 0) << claim.out << claim.err;
  auto move = run_cli(with({"command", "move", "--linear", "0.2", "--duration-ms", "300"}, at_a));
  EXPECT_EQ(move.exit_code, 0) << move.out << move.err;
  // Robot B refuses it: not its audience.
  auto at_b = run_cli({"status", "--url", rrn_b, "--registry", url, "--token-file", token});
  EXPECT_EQ(at_b.exit_code, 1) << at_b.out << at_b.err;

  // Revoked at the registry by the robot's owner: robot A refuses it within its poll interval.
  auto rv = reg->send("POST", "/api/v1/revocations",
                      R"({"token":")" + read_file(token).substr(0, read_file(token).find('\n')) +
                          R"(","reason":"laptop lost"})",
                      read_file(key).substr(0, read_file(key).find('\n')));
  ASSERT_EQ(rv.status, 201) << rv.body;
  EXPECT_TRUE(eventually([&] { return run_cli(with({"status"}, at_a)).exit_code == 1; }, 10'000));

  // §6.1: the registry stops → OFFLINE_AUTONOMOUS, then (keys older than max_key_age_s)
  // LOCKDOWN; it comes back → NORMAL.
  auto mode = [&] {
    return metric_value(http(a.port(), "GET", "/metrics", "", {}).body, "rcan_partition_mode");
  };
  EXPECT_TRUE(eventually([&] { return mode() == 0; }, 5000)) << mode();
  reg.reset();
  EXPECT_TRUE(eventually([&] { return mode() == 1; }, 5000)) << mode();
  EXPECT_TRUE(eventually([&] { return mode() == 2; }, 10'000)) << mode();
  reg = std::make_unique<RegistryDaemon>(
      dir.file("registry"), std::vector<std::string>{"--port", std::to_string(reg_port)});
  EXPECT_TRUE(eventually([&] { return mode() == 0; }, 5000)) << mode();
}

// A robot that proved its keys changes its record only by requests it signs, fresh and once.
TEST(RegistryCli, SignedUpdatesAreFreshOnceAndByTheRobotsOwnKey) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  const std::string key =
      registrant_key_file(reg, dir.file("registry"), dir.file("registrant.key"));
  ASSERT_EQ(run_cli({"keys", "generate", "--dir", dir.file("keys")}).exit_code, 0);
  ASSERT_EQ(run_cli({"keys", "generate", "--dir", dir.file("other")}).exit_code, 0);
  auto r = run_cli({"registry", "register", "--manufacturer", "acme", "--model", "arm", "--version",
                    "v1", "--device-id", "u1", "--keys-dir", dir.file("keys"), "--save-key",
                    dir.file("robot.key"), "--registry", reg.url(), "--key-file", key});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::string rrn = str(json_of(r.out), "rrn");
  const std::string robot_key = read_file(dir.file("robot.key")).substr(0, 86);
  auto k = keys::load_dir(dir.file("keys"));
  auto other = keys::load_dir(dir.file("other"));
  ASSERT_TRUE(k.ok() && other.ok());
  const std::string body = R"({"description":"signed"})";
  auto patch = [&](int64_t ts, const keys::RobotKeys& by) {
    auto sig = registry::sign_update(by, registry::update_message(rrn, ts, body));
    EXPECT_TRUE(sig.ok());
    return http(reg.port(), "PATCH", "/api/v1/robots/" + rrn, body,
                {{"Authorization", "Bearer " + robot_key},
                 {"Content-Type", "application/json"},
                 {"X-RCAN-Timestamp", std::to_string(ts)},
                 {"X-RCAN-Signature", *sig}});
  };
  const int64_t now = now_ms();
  auto ok = patch(now, *k);
  EXPECT_EQ(ok.status, 200) << ok.body;
  auto replay = patch(now, *k);  // the same request again
  EXPECT_EQ(replay.status, 401) << replay.body;
  EXPECT_NE(replay.body.find("replayed"), std::string::npos) << replay.body;
  // Signed by another key, at a time the record has already passed: refused for its signature.
  auto forged = patch(now, *other);
  EXPECT_EQ(forged.status, 401);
  EXPECT_NE(forged.body.find("bad_signature"), std::string::npos) << forged.body;
  auto stale = patch(now - 600'000, *k);
  EXPECT_EQ(stale.status, 401);
  EXPECT_NE(stale.body.find("timestamp_skew"), std::string::npos) << stale.body;
  // The signature covers the body: another body under the same signature is refused.
  auto sig = registry::sign_update(*k, registry::update_message(rrn, now + 20, body));
  auto moved = http(reg.port(), "PATCH", "/api/v1/robots/" + rrn,
                    R"({"description":"moved","endpoints":["https://evil.example"]})",
                    {{"Authorization", "Bearer " + robot_key},
                     {"Content-Type", "application/json"},
                     {"X-RCAN-Timestamp", std::to_string(now + 20)},
                     {"X-RCAN-Signature", *sig}});
  EXPECT_EQ(moved.status, 401) << moved.body;
  EXPECT_EQ(str(json_of(reg.get("/api/v1/robots/" + rrn).body), "description"), "signed");
  // An admin may still correct a record without the robot's key.
  EXPECT_EQ(
      reg.send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"by admin"})", reg.admin_key())
          .status,
      200);
}

TEST(RegistryCli, RegisterWithProofGetListUpdateResolveDelete) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  const std::string key =
      registrant_key_file(reg, dir.file("registry"), dir.file("registrant.key"));
  ASSERT_EQ(run_cli({"keys", "generate", "--dir", dir.file("keys")}).exit_code, 0);
  const std::vector<std::string> env{"RCAN_REGISTRY=" + reg.url(), "RCAN_REGISTRY_KEY_FILE=" + key};
  auto r = run_cli({"registry", "register", "--manufacturer", "Acme Robotics", "--model", "Arm X",
                    "--version", "v2", "--device-id", "unit-7", "--keys-dir", dir.file("keys"),
                    "--save-key", dir.file("robot.key")},
                   {}, env);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value reg_answer = json_of(r.out);
  const std::string rrn = str(reg_answer, "rrn");
  ASSERT_EQ(rrn.rfind("RRN-", 0), 0u) << r.out;
  struct stat st {};
  ASSERT_EQ(::stat(dir.file("robot.key").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);

  r = run_cli({"registry", "get", rrn}, {}, env);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(str(json_of(r.out), "manufacturer"), "acme-robotics");
  r = run_cli({"registry", "list", "--q", "arm"}, {}, env);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json_of(r.out).get("total")->as_int(), 1);

  // Updates are the robot's own (its key) — the registrant key is refused.
  r = run_cli({"registry", "update", rrn, "--endpoint", "https://arm7.example"}, {}, env);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  // It proved its keys, so its own key alone is not enough either: it signs its updates.
  r = run_cli({"registry", "update", rrn, "--endpoint", "https://arm7.example", "--key-file",
               dir.file("robot.key")},
              {}, env);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("signature_required"), std::string::npos) << r.out;
  r = run_cli({"registry", "update", rrn, "--endpoint", "https://arm7.example", "--key-file",
               dir.file("robot.key"), "--keys-dir", dir.file("keys")},
              {}, env);
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  r = run_cli({"resolve", rrn}, {}, env);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("endpoint: https://arm7.example"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("mldsa65_public_key: "), std::string::npos) << r.out;

  // Bad input is a usage error before anything is sent; a missing robot is a refusal.
  EXPECT_EQ(run_cli({"registry", "get", "not-an-rrn"}, {}, env).exit_code, 2);
  EXPECT_EQ(run_cli({"registry", "register", "--model", "x"}, {}, env).exit_code, 2);
  EXPECT_EQ(run_cli({"resolve", "RRN-000000009999"}, {}, env).exit_code, 1);
  EXPECT_EQ(run_cli({"registry", "delete", rrn}, {"RCAN_REGISTRY=" + reg.url()}).exit_code, 2);

  r = run_cli({"registry", "delete", rrn, "--key-file", dir.file("robot.key")}, {}, env);
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_EQ(run_cli({"registry", "get", rrn}, {}, env).exit_code, 1);
  // Nobody there: exit 3.
  EXPECT_EQ(
      run_cli({"registry", "list", "--registry", "http://127.0.0.1:" + std::to_string(free_port())})
          .exit_code,
      3);
}

}  // namespace
}  // namespace rcan::test
