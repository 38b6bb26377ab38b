// Federation sync between two real rcan-registry daemons (docs/REGISTRY.md "Federation sync"):
// GET /api/v1/sync on an authoritative node, a root that pulls it (--sync-from) and resolves the
// delegated RRN itself, follows updates and deletes, and refuses the records of a node the prefix
// is not delegated to.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {
namespace {

json::Value body_of(const HttpReply& r) {
  auto v = json::parse(r.body);
  EXPECT_TRUE(v.ok()) << r.status << " " << r.body;
  return v.ok() ? *v : json::Value(json::Object{});
}

std::string str(const json::Value& v, std::string_view key) {
  const json::Value* m = v.get(key);
  return m != nullptr && m->is_string() ? m->as_string() : std::string();
}

int64_t num(const json::Value& v, std::string_view key) {
  const json::Value* m = v.get(key);
  return m != nullptr && m->is_int() ? m->as_int() : -1;
}

template <class F>
bool wait_for(F cond, int ms) {
  auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
  while (std::chrono::steady_clock::now() < end) {
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return cond();
}

std::string register_robot(RegistryDaemon& d, const std::string& device) {
  auto k = d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"t"})", d.admin_key());
  EXPECT_EQ(k.status, 201) << k.body;
  auto r = d.send(
      "POST", "/api/v1/robots",
      R"({"manufacturer":"Acme","model":"arm","version":"v2","device_id":")" + device + "\"}",
      str(body_of(k), "key"));
  EXPECT_EQ(r.status, 201) << r.body;
  return str(body_of(r), "rrn");
}

TEST(RegistrySync, SyncAnswerHasTheReferenceShape) {
  TempDir dir;
  RegistryDaemon bd(dir.path(), {"--prefix", "BD"});
  std::string rrn = register_robot(bd, "unit-1");
  auto r = bd.get("/api/v1/sync?since=1970-01-01T00:00:00Z&limit=10");
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value v = body_of(r);
  EXPECT_EQ(str(v, "protocol"), "rcan-sync/1.0");
  EXPECT_EQ(str(v, "from_node"), bd.url());
  EXPECT_EQ(str(v, "since"), "1970-01-01T00:00:00.000Z");
  EXPECT_EQ(num(v, "count"), 1);
  EXPECT_FALSE(v.get("has_more")->as_bool());
  const auto& recs = v.get("records")->as_array();
  ASSERT_EQ(recs.size(), 1u);
  EXPECT_EQ(str(recs[0], "rrn"), rrn);
  EXPECT_EQ(str(v, "next_since"), str(recs[0], "updated_at"));
  auto again = bd.get("/api/v1/sync?since=" + str(v, "next_since"));
  EXPECT_EQ(num(body_of(again), "count"), 0);
  EXPECT_EQ(bd.get("/api/v1/sync?since=yesterday").status, 400);
  EXPECT_EQ(bd.get("/api/v1/sync?since=2026-01-01T00:00:00'%3BDROP").status, 400);
  register_robot(bd, "unit-2");
  auto page = body_of(bd.get("/api/v1/sync?limit=1"));
  EXPECT_EQ(num(page, "count"), 1);
  EXPECT_TRUE(page.get("has_more")->as_bool());
}

TEST(RegistrySync, RootPullsTheDelegatedNodeAndResolvesItsRobotsItself) {
  TempDir d1, d2, d3;
  RegistryDaemon bd(d1.path(), {"--prefix", "BD"});
  RegistryDaemon impostor(d2.path(), {"--prefix", "BD"});  // BD is not delegated to it
  std::string rrn = register_robot(bd, "real-one");
  ASSERT_EQ(register_robot(impostor, "fake-one"), rrn);  // the same RRN on both
  RegistryDaemon root(d3.path(), {"--allow-http-node-urls", "--sync-from", impostor.url(),
                                  "--sync-from", bd.url() + "/", "--sync-interval", "0.3"});
  // Pulls before the delegation refuse everything; the delegation makes the root pull again.
  auto metrics = [&] { return root.get("/metrics").body; };
  ASSERT_TRUE(wait_for(
      [&] { return metric_value(metrics(), "rcan_registry_sync_refused_total") >= 2; }, 5000));
  auto n = root.send("POST", "/api/v1/nodes",
                     R"({"prefix":"BD","operator":"BD Robotics","node_url":")" + bd.url() + "\"}",
                     root.admin_key());
  ASSERT_EQ(n.status, 201) << n.body;

  auto resolved = [&] { return root.get("/api/v1/resolve/" + rrn); };
  ASSERT_TRUE(wait_for([&] { return resolved().status == 200; }, 15000)) << resolved().body;
  json::Value v = body_of(resolved());
  EXPECT_EQ(str(v, "resolved_by"), bd.url());
  EXPECT_EQ(str(v, "cache_status"), "SYNCED");
  EXPECT_EQ(str(*v.get("record"), "device_id"), "real-one");
  // The counter goes up just after the write the resolve saw.
  EXPECT_TRUE(wait_for(
      [&] { return metric_value(metrics(), "rcan_registry_sync_imported_total") >= 1; }, 5000));

  // An update at the authoritative node reaches the root's copy; a delete removes it.
  ASSERT_EQ(bd.send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"moved"})", bd.admin_key())
                .status,
            200);
  ASSERT_TRUE(wait_for(
      [&] { return str(*body_of(resolved()).get("record"), "description") == "moved"; }, 10000));
  EXPECT_EQ(str(*body_of(resolved()).get("record"), "device_id"), "real-one");
  ASSERT_EQ(bd.send("DELETE", "/api/v1/robots/" + rrn, "", bd.admin_key()).status, 200);
  ASSERT_TRUE(wait_for([&] { return resolved().status == 307; }, 10000));

  // Every change a pull made is in the root's audit chain, by the node it came from: the copy,
  // the update and the delete.
  auto exported = run_cli(
      {"audit", "export", "--data-dir", d3.path(), "--secret-file", d3.path() + "/audit.secret"});
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  int imports = 0, deletes = 0;
  size_t at = 0;
  while ((at = exported.out.find("REGISTRY_SYNC_IMPORTED", at)) != std::string::npos) {
    const size_t line_end = exported.out.find('\n', at);
    const size_t line_start = exported.out.rfind('\n', at) + 1;
    const std::string line = exported.out.substr(line_start, line_end - line_start);
    EXPECT_NE(line.find("sync:" + bd.url()), std::string::npos) << line;
    EXPECT_EQ(line.find("fake-one"), std::string::npos) << "a refused record was written";
    if (line.find(rrn) != std::string::npos) ++imports;
    if (line.find("\"deleted\":true") != std::string::npos) ++deletes;
    at = line_end;
  }
  EXPECT_GE(imports, 3) << exported.out;
  EXPECT_EQ(deletes, 1) << exported.out;
}

// A deleted robot is a tombstone in every sync answer — its RRN, deleted, status and the time —
// to anyone who asks (no credentials, as a federation peer pulls, or an admin key): never its
// description, contact, metadata, endpoints or keys. A root that pulled the robot learns of the
// deletion from the tombstone and keeps no content either.
TEST(RegistrySync, DeletedRobotIsATombstoneInSync) {
  TempDir d1, d2;
  RegistryDaemon bd(d1.path(), {"--prefix", "BD"});
  auto r = bd.send("POST", "/api/v1/robots",
                   R"({"manufacturer":"acme","model":"arm","version":"v2","device_id":"gone-1",)"
                   R"("description":"secret plans","contact_email":"ops@acme.example",)"
                   R"("metadata":{"site":"lab-7"},"endpoints":["https://r1.acme.example/rcan"]})",
                   bd.admin_key());
  ASSERT_EQ(r.status, 201) << r.body;
  const std::string rrn = str(body_of(r), "rrn");
  RegistryDaemon root(
      d2.path(), {"--allow-http-node-urls", "--sync-from", bd.url(), "--sync-interval", "0.3"});
  ASSERT_EQ(root.send("POST", "/api/v1/nodes",
                      R"({"prefix":"BD","operator":"BD","node_url":")" + bd.url() + R"("})",
                      root.admin_key())
                .status,
            201);
  auto at_root = [&] { return root.get("/api/v1/resolve/" + rrn).status; };
  ASSERT_TRUE(wait_for([&] { return at_root() == 200; }, 15000));
  ASSERT_EQ(bd.send("DELETE", "/api/v1/robots/" + rrn, "", bd.admin_key()).status, 200);
  ASSERT_TRUE(wait_for([&] { return at_root() != 200; }, 10000));

  auto tombstone_only = [&](const RegistryDaemon& d, const std::string& key) {
    auto a = d.get("/api/v1/sync?since=1970-01-01T00:00:00Z", key);
    ASSERT_EQ(a.status, 200) << a.body;
    EXPECT_EQ(a.body.find("secret plans"), std::string::npos) << a.body;
    EXPECT_EQ(a.body.find("lab-7"), std::string::npos) << a.body;
    EXPECT_EQ(a.body.find("r1.acme.example"), std::string::npos) << a.body;
    EXPECT_EQ(a.body.find("ops@acme.example"), std::string::npos) << a.body;
    const json::Value v = body_of(a);
    const auto& recs = v.get("records")->as_array();
    ASSERT_EQ(recs.size(), 1u) << a.body;
    EXPECT_EQ(str(recs[0], "rrn"), rrn);
    EXPECT_TRUE(recs[0].get("deleted")->as_bool());
    EXPECT_EQ(str(recs[0], "status"), "deleted");
    for (const char* k : {"description", "metadata", "endpoints", "contact_email", "source",
                          "ed25519_public_key", "mldsa65_public_key"})
      EXPECT_EQ(recs[0].get(k), nullptr) << k << ": " << a.body;
  };
  tombstone_only(bd, "");
  tombstone_only(bd, bd.admin_key());
  tombstone_only(root, "");
}

TEST(RegistrySync, SyncDelegationsPullsEveryDelegatedNode) {
  TempDir d1, d2;
  RegistryDaemon bd(d1.path(), {"--prefix", "BD"});
  std::string rrn = register_robot(bd, "unit-9");
  RegistryDaemon root(d2.path(),
                      {"--allow-http-node-urls", "--sync-delegations", "--sync-interval", "0.3"});
  EXPECT_EQ(root.get("/api/v1/resolve/" + rrn).status, 404);  // no delegation yet
  auto n = root.send("POST", "/api/v1/nodes",
                     R"({"prefix":"BD","operator":"BD Robotics","node_url":")" + bd.url() + "\"}",
                     root.admin_key());
  ASSERT_EQ(n.status, 201) << n.body;
  ASSERT_TRUE(wait_for([&] { return root.get("/api/v1/resolve/" + rrn).status == 200; }, 15000));
  EXPECT_EQ(str(body_of(root.get("/api/v1/resolve/" + rrn)), "resolved_by"), bd.url());
}

}  // namespace
}  // namespace rcan::test
