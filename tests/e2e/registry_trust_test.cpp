// rcand trusts, follows and falls back on its registry's token authority (registry.trust_tokens,
// node/admission/registry_trust.h): a real rcand against a small registry stand-in (python3's
// http.server, started as a child process, serving the JWKS, the revocation feed and /healthz
// from files the test writes). Tokens are signed here with keys whose public halves the
// stand-in publishes.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <thread>

#include "fake_registry.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan {
namespace {

int64_t now_s() {
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

json::Value parse(const std::string& s) {
  auto v = json::parse(s, {.max_depth = 128, .max_bytes = 64u << 20});
  EXPECT_TRUE(v.ok()) << s.substr(0, 300);
  return v.ok() ? *v : json::Value();
}

void write(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::trunc);
  out << text;
}

using test::eventually;

struct RegistryKey {
  std::string kid;
  Bytes seed;
  json::Value jwk() const {
    auto pk = ed25519::public_key_from_seed(seed);
    EXPECT_TRUE(pk.ok());
    return json::Object{{"kty", "OKP"}, {"crv", "Ed25519"}, {"x", base64url_encode(*pk)},
                        {"kid", kid},   {"use", "sig"},     {"alg", "EdDSA"}};
  }
};

class RegistryTrustTest : public ::testing::Test {
 protected:
  void SetUp() override {
    reg_dir_ = dir_.file("registry");
    data_ = dir_.file("data");
    std::filesystem::create_directories(reg_dir_);
    std::filesystem::create_directories(data_);
    script_ = dir_.file("fake_registry.py");
    write(script_, test::kFakeRegistry);
    reg_port_ = test::free_port();
    registry_url_ = "http://127.0.0.1:" + std::to_string(reg_port_);
    ASSERT_EQ(test::run_cli({"keys", "generate", "--dir", data_ + "/keys"}).exit_code, 0);
    ASSERT_EQ(test::run_cli({"audit", "new-secret", "--out", data_ + "/audit.secret"}).exit_code,
              0);
    k1_ = {"k1", test::hex("1111111111111111111111111111111111111111111111111111111111111111")};
    k2_ = {"k2", test::hex("2222222222222222222222222222222222222222222222222222222222222222")};
    publish({k1_});
  }
  void TearDown() override {
    if (rcand_ && rcand_->running()) rcand_->stop(SIGTERM, 10000);
    if (registry_ && registry_->running()) registry_->stop(SIGTERM, 5000);
  }

  void publish(const std::vector<RegistryKey>& keys) {
    json::Array a;
    for (const auto& k : keys) a.push_back(k.jwk());
    write(reg_dir_ + "/jwks.json", json::dump(json::Value(json::Object{{"keys", a}})));
  }

  void start_registry() {
    registry_ = std::make_unique<test::Process>();
    ASSERT_TRUE(registry_->start(
        {"/usr/bin/env", "python3", script_, std::to_string(reg_port_), reg_dir_}));
    ASSERT_TRUE(registry_->wait_for_line("fake registry serving", 15000)) << registry_->err();
  }
  void stop_registry() { registry_->stop(SIGTERM, 5000); }

  int count_requests(const std::string& path) {
    std::ifstream in(reg_dir_ + "/requests.log");
    int n = 0;
    for (std::string line; std::getline(in, line);)
      if (line == path) ++n;
    return n;
  }

  // rcand with the registry block and `extra` (YAML lines under `registry:`), `offline`.
  void start_rcand(const std::string& registry_extra, const std::string& offline = {}) {
    const std::string cfg = dir_.file("robot.rcan.yaml");
    write(cfg,
          "rcan_version: \"1.2\"\nruri: rcan://local.rcan/acme/rover/0a1b2c3d\n"
          "robot:\n  name: test-rover\n  manufacturer: acme\n  model: rover\n  type: mobile\n"
          "safety:\n  local_safety_wins: true\n  max_linear_speed_mps: 0.4\n"
          // The refusals below are on purpose: no address budget for them.
          "security:\n  failed_auth_per_address_per_minute: 0\n"
          "registry:\n  registry_url: " +
              registry_url_ + "\n  trust_tokens: true\n" + registry_extra + offline);
    rcand_ = std::make_unique<test::Process>();
    ASSERT_TRUE(rcand_->start({RCAND_PATH, "--config", cfg, "--port", "0", "--data-dir", data_}));
    auto line = rcand_->wait_for_line("\"event\":\"listening\"", 30000);
    ASSERT_TRUE(line.has_value()) << rcand_->err();
    json::Value lv = parse(*line);
    const std::string url = lv.get("url")->as_string();
    port_ = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
    ruri_ = lv.get("ruri")->as_string();
    rrn_ = lv.get("rrn")->as_string();
  }
  void stop_rcand() { EXPECT_EQ(rcand_->stop(SIGTERM, 15000), 0) << rcand_->err(); }

  // A token as the registry issues one for this robot (its RURI in aud, its RRN in rrn);
  // `change` edits the claims first.
  std::string token(const RegistryKey& k, const std::string& jti, const std::string& sub = "ops",
                    const std::string& aud = {},
                    const std::function<void(json::Object&)>& change = {}) {
    auto key = jwt::SigningKey::ed25519_seed(k.seed);
    EXPECT_TRUE(key.ok());
    const int64_t now = now_s();
    json::Object claims{{"iss", registry_url_},
                        {"sub", sub},
                        {"aud", aud.empty() ? ruri_ : aud},
                        {"rrn", rrn_},
                        {"role", "owner"},
                        {"scope", json::Array{"status", "control", "config"}},
                        {"jti", jti},
                        {"iat", now - 5},
                        {"exp", now + 3600}};
    if (change) change(claims);
    auto t = jwt::issue(claims, *key, k.kid);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }

  test::HttpReply get(const std::string& target, const std::string& tok = {}) {
    std::vector<std::pair<std::string, std::string>> h;
    if (!tok.empty()) h.emplace_back("Authorization", "Bearer " + tok);
    return test::http(port_, "GET", target, "", h);
  }
  int status_code(const std::string& tok) { return get("/api/status", tok).status; }
  std::string mode() {
    json::Value v = parse(get("/api/status").body);
    const json::Value* m = v.get("mode");
    return m && m->is_string() ? m->as_string() : "";
  }
  std::vector<std::string> audit_events(const std::string& tok) {
    json::Value v = parse(get("/api/audit?limit=500", tok).body);
    std::vector<std::string> out;
    if (const json::Value* e = v.get("entries"); e && e->is_array())
      for (const auto& x : e->as_array()) {
        std::string ev = x.get("event")->as_string();
        if (ev == "PARTITION_MODE") ev += ":" + x.get("detail")->get("to")->as_string();
        out.push_back(ev);
      }
    return out;
  }

  test::TempDir dir_;
  std::string reg_dir_, data_, script_, registry_url_, ruri_, rrn_;
  uint16_t reg_port_ = 0, port_ = 0;
  RegistryKey k1_, k2_;
  std::unique_ptr<test::Process> registry_, rcand_;
};

bool has(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

TEST_F(RegistryTrustTest, RegistryTokenIsAcceptedAndARotatedKeyAfterOneEarlyFetch) {
  start_registry();
  start_rcand("  jwks_refresh_s: 3600\n");
  EXPECT_EQ(status_code(token(k1_, "a1")), 200);
  json::Value st = parse(get("/api/status", token(k1_, "a1")).body);
  const json::Value* reg = st.get("registry");
  ASSERT_NE(reg, nullptr) << st.get("partition");
  EXPECT_EQ(reg->get("issuer")->as_string(), registry_url_);
  EXPECT_EQ(reg->get("jwks")->get("key_count")->as_int(), 1);
  EXPECT_TRUE(reg->get("jwks")->get("fetched_at_ms")->is_int());
  EXPECT_EQ(reg->get("jwks")->get("source")->as_string(), "fetched");
  EXPECT_FALSE(reg->get("rrn")->as_string().empty());
  // A token of another issuer's key under the registry's name is refused.
  RegistryKey stranger{"k1", test::hex(std::string(64, '3'))};
  EXPECT_EQ(status_code(token(stranger, "x1")), 401);

  // The registry rotates: k2 appears in the JWKS. The first k2 token asks for an early fetch
  // (the scheduled one is an hour away); the key is in use without a restart.
  const int fetches = count_requests("/.well-known/jwks.json");
  publish({k1_, k2_});
  const std::string t2 = token(k2_, "a2");
  EXPECT_TRUE(eventually([&] { return status_code(t2) == 200; }, 5000)) << rcand_->err();
  EXPECT_EQ(status_code(token(k1_, "a3")), 200);  // the old key stays while it is published
  // At most one early fetch a minute, whatever the unknown kids keep coming.
  RegistryKey k3{"k3", test::hex(std::string(64, '4'))};
  for (int i = 0; i < 5; ++i) EXPECT_EQ(status_code(token(k3, "a4")), 401);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_EQ(count_requests("/.well-known/jwks.json"), fetches + 1);
  EXPECT_TRUE(has(audit_events(t2), "REGISTRY_KEYS_UPDATED"));
}

// docs/THREATS.md T1: the registry's token authority signs for every registrant of the
// registry, so its signature alone says nothing about which robot a token is for. A token of
// the registry must name this robot exactly — its RURI without a wildcard, and its RRN — or,
// for a fleet token, list its RRN. Before the fix every one of these was accepted as OWNER.
TEST_F(RegistryTrustTest, ARegistryTokenMustNameThisRobotExactlyByRuriAndRrn) {
  start_registry();
  start_rcand("");
  ASSERT_FALSE(rrn_.empty());
  EXPECT_EQ(status_code(token(k1_, "e0")), 200);
  auto refused_with = [&](const std::string& tok, const std::string& reason) {
    auto r = get("/api/audit?limit=1", tok);
    EXPECT_EQ(r.status, 401) << r.body;
    EXPECT_NE(r.body.find(reason), std::string::npos) << r.body;
  };
  // Wildcards that aud_matches() would take from a configured issuer.
  for (const char* aud :
       {"rcan://*/*/*/*", "rcan://local.rcan/acme/rover/*", "rcan://*/acme/rover/0a1b2c3d"})
    refused_with(token(k1_, std::string("e1") + aud, "mallory", aud), "aud_not_exact");
  refused_with(token(k1_, "e2", "mallory", {},
                     [&](json::Object& c) {
                       c.set("aud", json::Array{"rcan://*/*/*/*", "rcan://fleet/other"});
                     }),
               "aud_not_exact");
  // The exact RURI but another robot's RRN, or none.
  refused_with(
      token(k1_, "e3", "mallory", {}, [](json::Object& c) { c.set("rrn", "RRN-000000000777"); }),
      "rrn_mismatch");
  refused_with(token(k1_, "e4", "mallory", {}, [](json::Object& c) { c.erase("rrn"); }),
               "rrn_mismatch");
  // A fleet token of the registry lists this robot's RRN, not only its device id.
  refused_with(token(k1_, "e5", "mallory", {},
                     [&](json::Object& c) {
                       c.erase("rrn");
                       c.set("fleet", json::Array{"0a1b2c3d", ruri_, "RRN-000000000777"});
                     }),
               "fleet_mismatch");
  EXPECT_EQ(status_code(token(k1_, "e6", "ops", {},
                              [&](json::Object& c) {
                                c.erase("rrn");
                                c.set("fleet", json::Array{"RRN-000000000777", rrn_});
                              })),
            200);
}

TEST_F(RegistryTrustTest, MalformedJwksKeepsTheKeysInUse) {
  start_registry();
  start_rcand("  jwks_refresh_s: 1\n");
  const std::string t1 = token(k1_, "b1");
  EXPECT_EQ(status_code(t1), 200);
  const int fetches = count_requests("/.well-known/jwks.json");
  write(reg_dir_ + "/jwks.json", "{\"keys\": [{\"kty\": \"OKP\", \"crv\": \"Ed25519\"}]}");
  ASSERT_TRUE(
      eventually([&] { return count_requests("/.well-known/jwks.json") >= fetches + 2; }, 5000));
  EXPECT_EQ(status_code(token(k1_, "b2")), 200);
  write(reg_dir_ + "/jwks.json", "not json at all");
  ASSERT_TRUE(
      eventually([&] { return count_requests("/.well-known/jwks.json") >= fetches + 4; }, 5000));
  EXPECT_EQ(status_code(token(k1_, "b3")), 200);
  json::Value st = parse(get("/api/status", t1).body);
  EXPECT_EQ(st.get("registry")->get("jwks")->get("key_count")->as_int(), 1);
  EXPECT_TRUE(st.get("registry")->get("last_error")->is_string());
  EXPECT_TRUE(has(audit_events(t1), "REGISTRY_KEYS_REJECTED"));
}

TEST_F(RegistryTrustTest, TokenRevokedAtTheRegistryIsRefusedWithinTheInterval) {
  start_registry();
  start_rcand("  revocations_refresh_s: 1\n");
  const std::string revoked = token(k1_, "c1"), kept = token(k1_, "c2");
  const std::string alice = token(k1_, "c3", "alice");
  EXPECT_EQ(status_code(revoked), 200);
  EXPECT_EQ(status_code(kept), 200);
  EXPECT_EQ(status_code(alice), 200);
  write(reg_dir_ + "/revocations.json",
        "[{\"seq\": 1, \"jti\": \"c1\", \"sub\": null, \"exp\": " + std::to_string(now_s() + 3600) +
            ", \"revoked_at\": \"2026-01-01T00:00:00Z\"},"
            " {\"seq\": 2, \"jti\": null, \"sub\": \"alice\", \"exp\": null, \"revoked_at\": \"" +
            "2100-01-01T00:00:00Z\"}]");
  EXPECT_TRUE(eventually([&] { return status_code(revoked) == 401; }, 3500));
  EXPECT_TRUE(eventually([&] { return status_code(alice) == 401; }, 3500));
  EXPECT_EQ(status_code(kept), 200);
  json::Value st = parse(get("/api/status", kept).body);
  EXPECT_EQ(st.get("registry")->get("revocations")->get("since")->as_int(), 2);
  auto revoked_records = [&] {
    auto events = audit_events(kept);
    return std::count(events.begin(), events.end(), "TOKEN_REVOKED");
  };
  // Each is recorded once it is in force (the record follows the list's file).
  EXPECT_TRUE(eventually([&] { return revoked_records() == 2; }, 3000));

  // The cursor survives a restart: nothing is read twice, and the list still refuses c1.
  stop_rcand();
  start_rcand("  revocations_refresh_s: 1\n");
  EXPECT_EQ(status_code(revoked), 401);
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(revoked_records(), 2);
}

TEST_F(RegistryTrustTest, RestartWithTheRegistryDownUsesTheCachedKeys) {
  start_registry();
  start_rcand("");
  EXPECT_EQ(status_code(token(k1_, "d1")), 200);
  stop_rcand();
  auto mode = std::filesystem::status(data_ + "/registry/jwks.json").permissions();
  EXPECT_EQ(mode & std::filesystem::perms::all,
            std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  stop_registry();
  start_rcand("");
  const std::string t = token(k1_, "d2");
  EXPECT_EQ(status_code(t), 200);
  json::Value st = parse(get("/api/status", t).body);
  EXPECT_EQ(st.get("registry")->get("jwks")->get("source")->as_string(), "cache");
  EXPECT_TRUE(st.get("registry")->get("last_error")->is_string());
}

// Seed §6.1 with the registry as the issuer: its /healthz is probed, and the keys are fresh for
// max_key_age_s after their last successful fetch.
TEST_F(RegistryTrustTest, RegistryDownGoesOfflineThenLockdownAndBackToNormal) {
  start_registry();
  start_rcand("  max_key_age_s: 4\n",
              "offline:\n  issuer_poll_ms: 100\n  issuer_timeout_ms: 300\n");
  const std::string t = token(k1_, "e1");
  EXPECT_EQ(status_code(t), 200);
  EXPECT_TRUE(eventually([&] { return mode() == "NORMAL"; }, 3000));
  stop_registry();
  EXPECT_TRUE(eventually([&] { return mode() == "OFFLINE_AUTONOMOUS"; }, 3000)) << mode();
  EXPECT_TRUE(eventually([&] { return mode() == "LOCKDOWN"; }, 6000)) << mode();
  start_registry();
  EXPECT_TRUE(eventually([&] { return mode() == "NORMAL"; }, 3000)) << mode();
  auto events = audit_events(t);
  EXPECT_TRUE(has(events, "PARTITION_MODE:OFFLINE_AUTONOMOUS"));
  EXPECT_TRUE(has(events, "PARTITION_MODE:LOCKDOWN"));
  EXPECT_TRUE(has(events, "PARTITION_MODE:NORMAL"));
}

}  // namespace
}  // namespace rcan

namespace rcan {
namespace {

// RFC 7662: a token naming the registry whose key the robot cannot get is put to the registry,
// off the transport thread, once; the answer decides its next uses and is still checked here.
TEST_F(RegistryTrustTest, IntrospectionDecidesATokenItsKeysCannotVerifyOnceAndIsCached) {
  std::filesystem::create_directories(data_ + "/registry");
  write(data_ + "/registry/state.json",
        "{\"registry_url\":\"" + registry_url_ +
            "\",\"rrn\":\"RRN-000000000042\",\"robot_key\":\"rk-test\"}");
  write(reg_dir_ + "/active.json", "[\"i1\", \"i3\"]");
  start_registry();
  start_rcand("  jwks_refresh_s: 3600\n");
  RegistryKey kx{"kx", test::hex(std::string(64, '5'))};  // never in the JWKS
  const std::string vouched = token(kx, "i1"), inactive = token(kx, "i2");
  EXPECT_EQ(status_code(vouched), 401);  // refused now; the registry is asked meanwhile
  EXPECT_TRUE(eventually([&] { return status_code(vouched) == 200; }, 5000)) << rcand_->err();
  for (int i = 0; i < 5; ++i) EXPECT_EQ(status_code(vouched), 200);
  EXPECT_EQ(count_requests("/oauth/introspect"), 1);
  json::Value st = parse(get("/api/status", vouched).body);
  EXPECT_EQ(st.get("rrn")->as_string(), "RRN-000000000042");
  EXPECT_EQ(st.get("registry")->get("rrn")->as_string(), "RRN-000000000042");

  // Inactive: refused, and asked about once for the next 30 s.
  EXPECT_EQ(status_code(inactive), 401);
  EXPECT_TRUE(eventually([&] { return count_requests("/oauth/introspect") == 2; }, 5000));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  for (int i = 0; i < 3; ++i) EXPECT_EQ(status_code(inactive), 401);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(count_requests("/oauth/introspect"), 2);

  // Active for the registry, but for another robot: the answer's aud is checked here.
  const std::string elsewhere = token(kx, "i3", "ops", "rcan://local.rcan/acme/rover/ffffffff");
  EXPECT_EQ(status_code(elsewhere), 401);
  EXPECT_TRUE(eventually([&] { return count_requests("/oauth/introspect") == 3; }, 5000));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(status_code(elsewhere), 401);
}

}  // namespace
}  // namespace rcan
