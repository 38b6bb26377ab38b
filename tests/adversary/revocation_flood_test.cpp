// Revocations as a flood (docs/THREATS.md T4): a registrant of the registry a robot trusts turns
// its own tokens into revocations, which every trusting robot copies from the registry's feed.
// Two halves, each against real processes on loopback: the registry (rcan-registry) bounds what
// one key may revoke; the robot (rcand) keeps the feed in a table of its own, appends instead of
// rewriting, and reads on past what it cannot keep. The robot's half is fed by the registry
// stand-in (tests/support/fake_registry.h) serving what a registry that let a flood through
// would serve.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "fake_registry.h"
#include "joining_robot.h"
#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {
namespace {

HttpReply form_post(uint16_t port, const std::string& path, const std::string& body) {
  return http(port, "POST", path, body, {{"Content-Type", "application/x-www-form-urlencoded"}});
}

// T4, the registry's half (review finding F4). Before the fix every one of these revocations
// was taken (201): the feed grew by whatever a registrant chose to revoke.
TEST(AdversaryRevocationFlood, OneRegistrantKeyCannotFloodTheRevocationFeed) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  auto k = reg.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"mallory"})",
                    reg.admin_key());
  ASSERT_EQ(k.status, 201) << k.body;
  const std::string mallory = str(json_of(k.body), "key");
  auto own = reg.register_proven(mallory, "evil", "bot", "v1", "deadbeef",
                                 R"({"ruri":"rcan://local.rcan/evil/bot/deadbeef"})");
  ASSERT_EQ(own.status, 201) << own.body;
  const std::string rrn = str(json_of(own.body), "rrn");
  auto c = reg.send("POST", "/api/v1/clients", R"({"name":"flood"})", mallory);
  ASSERT_EQ(c.status, 201) << c.body;
  const json::Value client = json_of(c.body);
  ASSERT_EQ(reg.send("POST", "/api/v1/grants",
                     R"({"principal":")" + str(client, "client_id") + R"(","robot":")" + rrn +
                         R"(","role":"user","scope":["status"]})",
                     mallory)
                .status,
            201);
  int taken = 0, limited = 0;
  std::string refusal;
  for (int i = 0; i < 75 && limited == 0; ++i) {
    auto t = form_post(reg.port(), "/oauth/token",
                       "grant_type=client_credentials&client_id=" + str(client, "client_id") +
                           "&client_secret=" + str(client, "client_secret") + "&resource=" + rrn);
    ASSERT_EQ(t.status, 200) << t.body;
    auto r = reg.send("POST", "/api/v1/revocations",
                      R"({"token":")" + str(json_of(t.body), "access_token") + R"("})", mallory);
    if (r.status == 201) ++taken;
    if (r.status == 429) {
      ++limited;
      refusal = r.body;
      EXPECT_FALSE(r.header("retry-after").empty());
    }
    // Under the key's write limit (10/s): the only limit left to hit is the revocations'.
    std::this_thread::sleep_for(std::chrono::milliseconds(120));
  }
  EXPECT_EQ(taken, 60);
  EXPECT_EQ(limited, 1);
  EXPECT_NE(refusal.find("revocation_rate"), std::string::npos) << refusal;
  // An admin is not held by it.
  EXPECT_EQ(
      reg.send("POST", "/api/v1/revocations", R"({"sub":"rcc_0123456789ab"})", reg.admin_key())
          .status,
      201);
}

// T4, the robot's half (review finding F4). Before the fix the robot rewrote and synced its
// whole revocations.json per feed entry (so a flood took minutes and more to read), and at
// 10,000 entries it refused the OWNER's own revocations and stalled its feed cursor on the
// refused entry forever.
TEST(AdversaryRevocationFlood, AFloodedFeedNeitherCrowdsOutTheOwnerNorStallsTheRobot) {
  TempDir dir;
  constexpr int kTotal = 10'050;
  // The registry stand-in serves a feed of kTotal revocations of tokens valid for an hour.
  const std::string root = dir.file("registry");
  std::filesystem::create_directories(root);
  std::ofstream(root + "/jwks.json") << R"({"keys":[]})";
  json::Array feed_entries;
  const int64_t exp = std::chrono::duration_cast<std::chrono::seconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count() +
                      3600;
  for (int seq = 1; seq <= kTotal; ++seq)
    feed_entries.emplace_back(json::Object{{"seq", seq},
                                           {"jti", "junk-" + std::to_string(seq)},
                                           {"sub", json::Value()},
                                           {"exp", exp},
                                           {"revoked_at", "2026-12-01T00:00:00Z"}});
  std::ofstream(root + "/revocations.json") << json::dump(json::Value(std::move(feed_entries)));
  std::ofstream(dir.file("registry.py")) << kFakeRegistry;
  const uint16_t feed_port = free_port();
  const std::string feed_url = "http://127.0.0.1:" + std::to_string(feed_port);
  Process feed;
  ASSERT_TRUE(feed.start(
      {"/usr/bin/env", "python3", dir.file("registry.py"), std::to_string(feed_port), root}));
  ASSERT_TRUE(feed.wait_for_line("fake registry serving", 15000)) << feed.err();
  // A robot that trusts the feed's registry (it joins nothing: no registrant key is valid there).
  write_private(dir.file("none.key"), "rcan_0123456789abcdef_" + std::string(64, '0') + "\n");
  JoiningRobot robot(dir.file("robot"), feed_url, dir.file("none.key"), kRuri,
                     "  trust_tokens: true\n  revocations_refresh_s: 1\n");
  ASSERT_FALSE(robot.start().empty());
  const std::string owner = first_line(robot.owner_token_file());
  auto status = [&] {
    return json_of(
        http(robot.port(), "GET", "/api/status", "", {{"Authorization", "Bearer " + owner}}).body);
  };
  auto since = [&]() -> int64_t {
    const json::Value st = status();
    const json::Value* reg = st.get("registry");
    const json::Value* revs = reg != nullptr ? reg->get("revocations") : nullptr;
    const json::Value* s = revs != nullptr ? revs->get("since") : nullptr;
    return s != nullptr && s->is_int() ? s->as_int() : -1;
  };
  // The whole feed is read, past what the robot's table for it cannot hold.
  EXPECT_TRUE(eventually([&] { return since() == kTotal; }, 90'000)) << since();
  const std::string metrics = http(robot.port(), "GET", "/metrics", "", {}).body;
  EXPECT_EQ(metric_value(metrics, "rcan_registry_revocations_applied_total"), 10'000);
  EXPECT_EQ(metric_value(metrics, "rcan_registry_revocations_skipped_total"), kTotal - 10'000);
  // The OWNER still revokes: its own table is untouched by the flood.
  auto mine = http(robot.port(), "POST", "/rcan/v1/revocations", R"({"sub":"mallory"})",
                   {{"Authorization", "Bearer " + owner}, {"Content-Type", "application/json"}});
  EXPECT_EQ(mine.status, 201) << mine.body;
  // What was skipped is on record.
  auto audit = http(robot.port(), "GET", "/api/audit?event=TOKEN_REVOKED&limit=5", "",
                    {{"Authorization", "Bearer " + owner}});
  EXPECT_NE(audit.body.find("revocation_feed_full"), std::string::npos)
      << audit.body.substr(0, 500);
}

}  // namespace
}  // namespace rcan::test
