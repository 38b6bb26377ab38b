// `rcand init`: a configured robot from an empty directory — the files it writes and their
// modes, `rcand --config` on its output serving, the printed OWNER token driving the robot with
// the rcan CLI, a second run that changes no secret, and a configured robot without its
// identity saying to run it.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "config/config.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan {
namespace {

namespace fs = std::filesystem;
using test::run;
using test::run_cli;

unsigned mode_of(const std::string& path) {
  struct stat st {};
  return ::lstat(path.c_str(), &st) == 0 ? (st.st_mode & 0777) : 0;
}

// A loopback port nobody listens on now.

// Every regular file under `dir` → SHA-256 of its bytes.
std::map<std::string, std::string> hashes(const std::string& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out[e.path().string()] = sha256_hex(test::read_file(e.path()));
  return out;
}

std::string ruri_of(const std::string& yaml_path) {
  std::ifstream in(yaml_path);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("ruri: ", 0) == 0) return line.substr(6);
  return {};
}

class InitTest : public ::testing::Test {
 protected:
  test::RunResult init(std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {RCAND_PATH, "init", "--dir", dir_, "--yes"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return run(argv);
  }
  test::TempDir tmp_;
  std::string dir_ = tmp_.file("robot");
};

TEST_F(InitTest, AConfiguredRobotFromAnEmptyDirectoryServesAndItsOwnerTokenDrivesIt) {
  const int port = test::free_port();
  ASSERT_GT(port, 0);
  auto r = init({"--name", "Yard rover", "--manufacturer", "acme", "--model", "yard-rover",
                 "--port", std::to_string(port)});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::string yaml = dir_ + "/robot.rcan.yaml";
  // The files, and every secret 0600 in a 0700 directory.
  EXPECT_EQ(mode_of(dir_), 0700u);
  EXPECT_EQ(mode_of(yaml), 0644u);
  EXPECT_EQ(mode_of(dir_ + "/audit.secret"), 0600u);
  EXPECT_EQ(mode_of(dir_ + "/keys"), 0700u);
  EXPECT_EQ(mode_of(dir_ + "/keys/mldsa65.seed"), 0600u);
  EXPECT_EQ(mode_of(dir_ + "/keys/ed25519.seed"), 0600u);
  EXPECT_EQ(mode_of(dir_ + "/issuer"), 0700u);
  EXPECT_EQ(mode_of(dir_ + "/issuer/ed25519.seed"), 0600u);
  EXPECT_EQ(mode_of(dir_ + "/issuer/ed25519.pub.pem"), 0644u);
  EXPECT_EQ(mode_of(dir_ + "/owner.token"), 0600u);
  const std::string ruri = ruri_of(yaml);
  EXPECT_EQ(ruri.rfind("rcan://local.rcan/acme/yard-rover/", 0), 0u) << ruri;
  // What to do next, with this robot's paths.
  EXPECT_NE(r.out.find("rcand --config " + yaml), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("RCAN_TOKEN_FILE=" + dir_ + "/owner.token"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("MiB"), std::string::npos) << "the audit log's footprint is stated";

  test::Process node;
  ASSERT_TRUE(node.start({RCAND_PATH, "--config", yaml}));
  ASSERT_TRUE(node.wait_for_line("\"listening\"", 20000).has_value()) << node.err();
  const std::vector<std::string> env = {"RCAN_URL=http://127.0.0.1:" + std::to_string(port),
                                        "RCAN_TOKEN_FILE=" + dir_ + "/owner.token"};
  auto status = run_cli({"status", "--json"}, {}, env);
  ASSERT_EQ(status.exit_code, 0) << status.out << status.err;
  EXPECT_NE(status.out.find(ruri), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("Yard rover"), std::string::npos) << status.out;
  auto claim = run_cli({"claim"}, {}, env);
  EXPECT_EQ(claim.exit_code, 0) << claim.out << claim.err;
  auto move = run_cli({"command", "move", "--linear", "0.2", "--duration-ms", "300"}, {}, env);
  EXPECT_EQ(move.exit_code, 0) << move.out << move.err;
  EXPECT_NE(move.out.find("ACK"), std::string::npos) << move.out;
  EXPECT_EQ(node.stop(SIGTERM, 10000), 0) << node.err();
}

TEST_F(InitTest, RunningItAgainChangesNoSecretAndRenewsOnlyAnExpiredOwnerToken) {
  ASSERT_EQ(init().exit_code, 0);
  auto before = hashes(dir_);
  ASSERT_GE(before.size(), 9u);
  auto again = init({"--name", "another-name", "--model", "other-model"});
  ASSERT_EQ(again.exit_code, 0) << again.out << again.err;
  EXPECT_EQ(again.out.find("created"), std::string::npos) << again.out;
  EXPECT_EQ(hashes(dir_), before) << "a second run must change nothing";
  // An owner token that is no longer valid is replaced, and nothing else.
  const std::string token = dir_ + "/owner.token";
  {
    std::ofstream out(token, std::ios::trunc);
    out << "not-a-jwt\n";
  }
  auto renewed = init();
  ASSERT_EQ(renewed.exit_code, 0) << renewed.out << renewed.err;
  EXPECT_NE(renewed.out.find("renewed"), std::string::npos) << renewed.out;
  auto after = hashes(dir_);
  for (const auto& [path, h] : before) {
    if (path == token)
      EXPECT_NE(after[path], h);
    else
      EXPECT_EQ(after[path], h) << path;
  }
  EXPECT_EQ(mode_of(token), 0600u);
}

TEST_F(InitTest, AConfiguredRobotWithoutItsIdentitySaysToRunInit) {
  ASSERT_EQ(init({"--port", std::to_string(test::free_port())}).exit_code, 0);
  fs::remove_all(dir_ + "/keys");
  auto r = run({RCAND_PATH, "--config", dir_ + "/robot.rcan.yaml"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("rcand init --dir"), std::string::npos) << r.err;
  // init puts back what is missing (new keys) and keeps the rest.
  auto before = hashes(dir_);
  auto again = init();
  ASSERT_EQ(again.exit_code, 0) << again.out << again.err;
  EXPECT_TRUE(fs::exists(dir_ + "/keys/mldsa65.seed"));
  for (const auto& [path, h] : before) EXPECT_EQ(hashes(dir_)[path], h) << path;
}

// --driver ros2 / process: the template is a valid configuration of that driver, commented.
TEST_F(InitTest, RosAndProcessDriverTemplatesAreValidConfigurations) {
  for (const char* driver : {"ros2", "process"}) {
    test::TempDir tmp;
    const std::string dir = tmp.file("robot");
    auto r = run({RCAND_PATH, "init", "--dir", dir, "--yes", "--driver", driver});
    ASSERT_EQ(r.exit_code, 0) << driver << ": " << r.out << r.err;
    auto cfg = config::load_config(dir + "/robot.rcan.yaml");
    ASSERT_TRUE(cfg.ok()) << driver << ": " << cfg.error().field << ": " << cfg.error().message;
    EXPECT_EQ(cfg->driver.type, driver);
    if (std::string(driver) == "ros2") {
      EXPECT_EQ(cfg->driver.ros2.cmd_vel_topic, "cmd_vel");
      EXPECT_EQ(cfg->driver.ros2.odom_timeout_ms, 1000u);
    } else {
      ASSERT_FALSE(cfg->driver.process.command.empty());
      EXPECT_NE(cfg->driver.process.command.back(), "");
    }
  }
}

TEST_F(InitTest, BadArgumentsAreRefusedWithUsageAndNothingIsWritten) {
  for (const std::vector<std::string>& bad :
       {std::vector<std::string>{"--manufacturer", "Not A Segment"},
        std::vector<std::string>{"--model", "x/y"},
        std::vector<std::string>{"--registry", "bad registry"},
        std::vector<std::string>{"--driver", "warp"}, std::vector<std::string>{"--port", "70000"},
        std::vector<std::string>{"--name"}, std::vector<std::string>{"--frobnicate", "1"}}) {
    auto r = init(bad);
    EXPECT_EQ(r.exit_code, 2) << bad[0] << ": " << r.out << r.err;
    EXPECT_FALSE(r.err.empty()) << bad[0];
    EXPECT_FALSE(fs::exists(dir_)) << bad[0];
  }
  auto help = run({RCAND_PATH, "init", "--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("usage: rcand init"), std::string::npos);
}

// `rcan keys issuer`: the verb that replaces openssl for a token issuer's key pair; its PEM
// verifies what its seed signs, and running it again keeps both files.
TEST_F(InitTest, KeysIssuerMakesAKeyPairWhoseTokensVerify) {
  const std::string d = tmp_.file("iss");
  auto r = run_cli({"keys", "issuer", "--dir", d, "--name", "ops.example"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(mode_of(d + "/ed25519.seed"), 0600u);
  EXPECT_NE(r.out.find("{issuer: ops.example, key_file: " + d + "/ed25519.pub.pem}"),
            std::string::npos)
      << r.out;
  auto before = hashes(d);
  ASSERT_EQ(run_cli({"keys", "issuer", "--dir", d}).exit_code, 0);
  EXPECT_EQ(hashes(d), before);
  auto tok =
      run_cli({"token", "issue", "--key", d + "/ed25519.seed", "--iss", "ops.example", "--sub",
               "alice", "--role", "user", "--aud", "rcan://local.rcan/a/b/0a1b2c3d"});
  ASSERT_EQ(tok.exit_code, 0) << tok.err;
  std::string jwt = tok.out.substr(0, tok.out.find_last_not_of("\n") + 1);
  auto ok =
      run_cli({"token", "inspect", jwt, "--key", d + "/ed25519.pub.pem", "--iss", "ops.example"});
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  // A PEM that is not the seed's public key is refused, never silently kept.
  ASSERT_EQ(run_cli({"keys", "issuer", "--dir", tmp_.file("other")}).exit_code, 0);
  fs::copy_file(tmp_.file("other") + "/ed25519.pub.pem", d + "/ed25519.pub.pem",
                fs::copy_options::overwrite_existing);
  auto bad = run_cli({"keys", "issuer", "--dir", d});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.err.find("is not the public key"), std::string::npos) << bad.err;
}

// `rcan doctor` on a robot rcand init made: what it finds, and what it says to do.
TEST_F(InitTest, DoctorChecksTheInstallationAndSaysWhatToFix) {
  const int port = test::free_port();
  ASSERT_EQ(init({"--port", std::to_string(port)}).exit_code, 0);
  const std::string yaml = dir_ + "/robot.rcan.yaml";
  const std::vector<std::string> env = {"RCAN_TOKEN_FILE=" + dir_ + "/owner.token"};
  auto level_of = [](const json::Value& report, const std::string& check) -> std::string {
    for (const auto& c : report.get("checks")->as_array())
      if (c.get("check")->as_string() == check) return c.get("level")->as_string();
    return "absent";
  };
  // The node is not running: that is the one failure.
  auto down = run_cli({"doctor", "--config", yaml, "--json"}, {}, env);
  EXPECT_EQ(down.exit_code, 1) << down.out << down.err;
  auto dv = json::parse(down.out);
  ASSERT_TRUE(dv.ok()) << down.out;
  EXPECT_EQ(level_of(*dv, "node"), "FAIL");
  EXPECT_EQ(level_of(*dv, "configuration"), "ok");
  EXPECT_EQ(level_of(*dv, "chain secret"), "ok");
  EXPECT_EQ(level_of(*dv, "robot key (ML-DSA-65)"), "ok");
  EXPECT_EQ(level_of(*dv, "disk"), "ok");
  // Running: no failure (the clock may only warn on a machine without NTP).
  test::Process node;
  ASSERT_TRUE(node.start({RCAND_PATH, "--config", yaml}));
  ASSERT_TRUE(node.wait_for_line("\"listening\"", 20000).has_value()) << node.err();
  auto up = run_cli({"doctor", "--config", yaml, "--json"}, {}, env);
  EXPECT_EQ(up.exit_code, 0) << up.out << up.err;
  auto uv = json::parse(up.out);
  ASSERT_TRUE(uv.ok()) << up.out;
  EXPECT_EQ(level_of(*uv, "node"), "ok");
  EXPECT_EQ(level_of(*uv, "audit log"), "ok");
  EXPECT_EQ(level_of(*uv, "ESTOP"), "ok");
  // A secret others can read is a failure, with the command that fixes it.
  fs::permissions(dir_ + "/audit.secret", fs::perms::others_read | fs::perms::group_read,
                  fs::perm_options::add);
  auto leak = run_cli({"doctor", "--config", yaml}, {}, env);
  EXPECT_EQ(leak.exit_code, 1);
  EXPECT_NE(leak.out.find("FAIL  chain secret"), std::string::npos) << leak.out;
  EXPECT_NE(leak.out.find("chmod 600 " + dir_ + "/audit.secret"), std::string::npos) << leak.out;
  // A broker of the fleet list that does not answer is a failure, named.
  const int dead = test::free_port();
  {
    std::ofstream out(yaml, std::ios::app);
    out << "mqtt:\n  enabled: true\n  broker: [mqtt://127.0.0.1:" << dead << "]\n";
  }
  auto nobroker = run_cli({"doctor", "--config", yaml}, {}, env);
  EXPECT_EQ(nobroker.exit_code, 1);
  EXPECT_NE(
      nobroker.out.find("FAIL  MQTT broker            mqtt://127.0.0.1:" + std::to_string(dead)),
      std::string::npos)
      << nobroker.out;
  // A broken configuration names the key.
  {
    std::ofstream out(yaml, std::ios::app);
    out << "safety_typo: 1\n";
  }
  auto broken = run_cli({"doctor", "--config", yaml}, {}, env);
  EXPECT_EQ(broken.exit_code, 1);
  EXPECT_NE(broken.out.find("safety_typo"), std::string::npos) << broken.out;
  EXPECT_EQ(node.stop(SIGTERM, 10000), 0);
}

}  // namespace
}  // namespace rcan
