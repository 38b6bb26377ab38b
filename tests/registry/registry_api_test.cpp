// rcan-registry's HTTP API over real sockets: the daemon binary started as a child process
// (docs/REGISTRY.md). Every endpoint, authentication and authorisation failures, rate limits,
// body limits, SQL metacharacters, proof of possession, the first start's files and a restart.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include "postgres.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/encoding.h"
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

// The admin keys (live or revoked) the registry holds, as GET /api/v1/keys lists them.
int admin_keys(const RegistryDaemon& d, const std::string& admin) {
  auto r = d.get("/api/v1/keys", admin);
  EXPECT_EQ(r.status, 200) << r.body;
  const json::Value v = body_of(r);
  int n = 0;
  if (const json::Value* keys = v.get("keys"); keys != nullptr && keys->is_array())
    for (const auto& k : keys->as_array()) n += str(k, "role") == "admin";
  return n;
}

std::string robot(const std::string& device, const std::string& extra = {}) {
  return R"({"manufacturer":"Acme Robotics","model":"arm","version":"v2","device_id":")" + device +
         "\"" + extra + "}";
}

unsigned mode_of(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 ? (st.st_mode & 0777) : 0;
}

// A registrant key created by the admin.
std::string registrant(const RegistryDaemon& d) {
  auto r = d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"test"})", d.admin_key());
  EXPECT_EQ(r.status, 201) << r.body;
  return str(body_of(r), "key");
}

TEST(RegistryApi, FirstStartFilesHealthMetricsAndSignedManifest) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  EXPECT_EQ(mode_of(dir.file("admin.key")), 0600u);
  EXPECT_EQ(mode_of(dir.file("node-ed25519.seed")), 0600u);
  EXPECT_EQ(mode_of(dir.file("registry.db")), 0600u);
  EXPECT_EQ(d.admin_key().rfind("rcan_", 0), 0u);
  // The banner's usage keeps the key off every command line (F12).
  EXPECT_NE(d.proc().err().find("RCAN_REGISTRY_KEY_FILE=" + dir.file("admin.key")),
            std::string::npos)
      << d.proc().err();
  EXPECT_EQ(d.proc().err().find("$(cat"), std::string::npos) << d.proc().err();

  auto h = d.get("/healthz");
  EXPECT_EQ(h.status, 200);
  EXPECT_EQ(str(body_of(h), "backend"), "sqlite");
  EXPECT_EQ(h.header("access-control-allow-origin"), "*");

  auto m = d.get("/.well-known/rcan-node.json");
  ASSERT_EQ(m.status, 200);
  json::Value man = body_of(m);
  EXPECT_EQ(str(man, "node_type"), "root");
  EXPECT_EQ(str(man, "api_base"), d.url() + "/api/v1");
  std::string pub = str(man, "ed25519_public_key");
  EXPECT_EQ(str(man, "public_key"), "ed25519:" + pub);
  auto pk = base64url_decode(pub);
  auto sig = base64url_decode(str(man, "signature"));
  ASSERT_TRUE(pk && sig);
  std::string signed_part = json::canonical_without(man.as_object(), "signature");
  EXPECT_TRUE(ed25519::verify(*pk, to_bytes(signed_part), *sig));
  // The key on disk is the manifest's.
  auto seed = read_file(dir.file("node-ed25519.seed"));
  auto derived = ed25519::public_key_from_seed(to_bytes(seed));
  ASSERT_TRUE(derived.ok());
  EXPECT_EQ(*derived, *pk);

  d.send("POST", "/api/v1/robots", robot("m-1"), d.admin_key());
  auto metrics = d.get("/metrics");
  EXPECT_EQ(metrics.status, 200);
  EXPECT_EQ(metric_value(metrics.body, "rcan_registry_robots"), 1.0);
  EXPECT_NE(metrics.body.find("route=\"/api/v1/robots\",status=\"201\""), std::string::npos)
      << metrics.body;
  EXPECT_NE(metrics.body.find("route=\"/healthz\""), std::string::npos);
}

TEST(RegistryApi, RegisterGetListSearchUpdateDelete) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  std::string reg = registrant(d);

  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("u-1")).status, 401);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("u-1"),
                   "rcan_0123456789abcdef_" + std::string(64, 'a'))
                .status,
            401);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("u-1"), "not-a-key").status, 401);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", R"({"manufacturer":"acme"})", reg).status, 400);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", "{not json", reg).status, 400);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("***"), reg).status, 400);

  auto created = d.send("POST", "/api/v1/robots",
                        robot("Unit 1", R"(,"description":"first","metadata":{"dof":6})"), reg);
  ASSERT_EQ(created.status, 201) << created.body;
  json::Value c = body_of(created);
  std::string rrn = str(c, "rrn");
  EXPECT_EQ(rrn, "RRN-000000000001");
  EXPECT_EQ(str(c, "rcan_uri"), "rcan://127.0.0.1/acme-robotics/arm/v2/unit-1");
  EXPECT_EQ(str(c, "manufacturer"), "acme-robotics");
  EXPECT_EQ(str(c, "verification_tier"), "community");
  std::string robot_key = str(c, "api_key");
  EXPECT_EQ(robot_key.rfind("rcan_", 0), 0u);
  // A robot key cannot register robots.
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("u-2"), robot_key).status, 403);

  auto again = d.send("POST", "/api/v1/robots", robot("unit-1"), reg);
  EXPECT_EQ(again.status, 200);
  EXPECT_EQ(body_of(again).get("already_existed")->as_bool(), true);
  EXPECT_EQ(str(body_of(again), "rrn"), rrn);

  auto got = d.get("/api/v1/robots/" + rrn);
  ASSERT_EQ(got.status, 200);
  json::Value g = body_of(got);
  EXPECT_EQ(str(g, "description"), "first");
  EXPECT_EQ(num(*g.get("metadata"), "dof"), 6);
  EXPECT_EQ(d.get("/api/v1/robots/rrn-000000000001").status, 200);  // case-insensitive
  EXPECT_EQ(d.get("/api/v1/robots/RRN-000000000099").status, 404);
  EXPECT_EQ(d.get("/api/v1/robots/RRN-12").status, 404);

  for (int i = 2; i <= 4; ++i)
    ASSERT_EQ(d.send("POST", "/api/v1/robots", robot("u-" + std::to_string(i)), reg).status, 201);
  auto list = body_of(d.get("/api/v1/robots?limit=2"));
  EXPECT_EQ(num(list, "total"), 4);
  EXPECT_EQ(list.get("robots")->as_array().size(), 2u);
  EXPECT_EQ(num(list, "next_offset"), 2);
  EXPECT_EQ(num(*list.get("meta"), "per_page"), 2);
  EXPECT_EQ(list.get("pagination")->get("has_next")->as_bool(), true);
  auto last = body_of(d.get("/api/v1/robots?limit=2&offset=2"));
  EXPECT_TRUE(last.get("next_offset")->is_null());
  auto page2 = body_of(d.get("/api/v1/robots?page=2&per_page=3"));
  EXPECT_EQ(page2.get("robots")->as_array().size(), 1u);
  EXPECT_EQ(num(*page2.get("meta"), "page"), 2);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots?manufacturer=Acme%20Robotics")), "total"), 4);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots?manufacturer=other")), "total"), 0);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots?q=acme")), "total"), 4);

  auto search = d.get("/api/v1/robots/search?q=acme");
  ASSERT_EQ(search.status, 200);
  EXPECT_EQ(num(body_of(search), "count"), 4);
  EXPECT_EQ(str(body_of(search).get("results")->as_array()[0], "uri").rfind("rcan://", 0), 0u);
  EXPECT_EQ(d.get("/api/v1/robots/search?q=a").status, 400);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots/search?model=arm")), "count"), 4);

  std::string patch = R"({"description":"updated","endpoints":["https://r1.example/rcan"]})";
  EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, patch).status, 401);
  EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, patch, registrant(d)).status, 403);
  auto p = d.send("PATCH", "/api/v1/robots/" + rrn, patch, robot_key);
  ASSERT_EQ(p.status, 200) << p.body;
  EXPECT_EQ(str(body_of(p), "description"), "updated");
  EXPECT_EQ(str(body_of(p).get("endpoints")->as_array()[0], "url"), "https://r1.example/rcan");
  EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, R"({"other":1})", robot_key).status, 400);
  EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, R"({"metadata":[1]})", robot_key).status, 400);
  EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, R"({"contact_email":"ops@example.com"})",
                   d.admin_key())
                .status,
            200);

  EXPECT_EQ(d.send("DELETE", "/api/v1/robots/" + rrn, "").status, 401);
  EXPECT_EQ(d.send("DELETE", "/api/v1/robots/" + rrn, "", registrant(d)).status, 403);
  auto del = d.send("DELETE", "/api/v1/robots/" + rrn, "", reg);  // the owner key
  EXPECT_EQ(del.status, 200) << del.body;
  EXPECT_EQ(d.get("/api/v1/robots/" + rrn).status, 404);
  EXPECT_EQ(d.send("DELETE", "/api/v1/robots/RRN-000000000002", "", robot_key).status, 403);
  EXPECT_EQ(d.send("PUT", "/api/v1/robots/" + rrn, "{}", reg).status, 405);
  EXPECT_EQ(d.get("/nothing").status, 404);
}

TEST(RegistryApi, ApiKeysCreateListRevoke) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  EXPECT_EQ(d.send("POST", "/api/v1/keys", R"({"role":"registrant"})").status, 401);
  auto k = d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"ci"})", d.admin_key());
  ASSERT_EQ(k.status, 201);
  std::string key = str(body_of(k), "key"), id = str(body_of(k), "id");
  EXPECT_EQ(key.substr(5, 16), id);
  EXPECT_EQ(d.send("POST", "/api/v1/keys", R"({"role":"registrant"})", key).status, 403);
  EXPECT_EQ(d.get("/api/v1/keys", key).status, 403);
  EXPECT_EQ(d.send("POST", "/api/v1/keys", R"({"role":"robot"})", d.admin_key()).status, 400);

  auto list = d.get("/api/v1/keys", d.admin_key());
  ASSERT_EQ(list.status, 200);
  EXPECT_EQ(num(body_of(list), "total"), 2);
  EXPECT_EQ(list.body.find(key.substr(22)), std::string::npos);  // no secret
  EXPECT_EQ(list.body.find("hash"), std::string::npos);
  EXPECT_EQ(list.body.find("salt"), std::string::npos);

  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("k-1"), key).status, 201);
  EXPECT_EQ(d.send("DELETE", "/api/v1/keys/" + id, "", key).status, 403);
  auto rev = d.send("DELETE", "/api/v1/keys/" + id, "", d.admin_key());
  EXPECT_EQ(rev.status, 200) << rev.body;
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("k-2"), key).status, 401);
  EXPECT_EQ(d.send("DELETE", "/api/v1/keys/" + id, "", d.admin_key()).status, 404);
  EXPECT_EQ(d.send("DELETE", "/api/v1/keys/ffffffffffffffff", "", d.admin_key()).status, 404);
  // A key with the right id and a wrong secret.
  std::string forged = key.substr(0, 22) + std::string(64, '0');
  EXPECT_EQ(
      d.get("/api/v1/keys", "rcan_" + d.admin_key().substr(5, 17) + std::string(64, '0')).status,
      401);
  (void)forged;
}

TEST(RegistryApi, SqlMetacharactersInEveryField) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  const std::string evil[] = {
      "'; DROP TABLE robots; --", "\\\" OR 1=1 --", "%_%", "a'||'b", "x\\u0000y", "ünïcødé ✓"};
  int created = 0;
  for (const auto& e : evil) {
    std::string q = json::dump(json::Value(e));
    std::string sq = json::dump(json::Value("m" + e));  // slugs need one [a-z0-9]
    std::string body = "{\"manufacturer\":" + sq + ",\"model\":" + sq + ",\"version\":" + sq +
                       ",\"device_id\":" + q + ",\"description\":" + q + ",\"source\":" + q +
                       ",\"metadata\":{" + q + ":" + q + "}}";
    auto r = d.send("POST", "/api/v1/robots", body, d.admin_key());
    // A device_id of punctuation only has no slug: 400, like the reference.
    ASSERT_TRUE(r.status == 201 || r.status == 400) << e << " → " << r.status << r.body;
    if (r.status != 201) continue;
    ++created;
    std::string rrn = str(body_of(r), "rrn");
    auto g = body_of(d.get("/api/v1/robots/" + rrn));
    EXPECT_EQ(str(g, "description"), e);
    EXPECT_EQ(str(*g.get("metadata"), e), e);
    auto key = str(body_of(r), "api_key");
    EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, "{\"description\":" + q + "}", key).status,
              200);
  }
  EXPECT_GE(created, 4);
  // contact_email, endpoints and the key label carry metacharacters too.
  auto r =
      d.send("POST", "/api/v1/robots",
             robot("meta-2",
                   R"(,"contact_email":"o';DROP--@x.y","endpoints":["https://x.example/'--%_"])"),
             d.admin_key());
  ASSERT_EQ(r.status, 201) << r.body;
  ++created;
  auto e = body_of(d.get("/api/v1/robots/" + str(body_of(r), "rrn")));
  EXPECT_EQ(str(e.get("endpoints")->as_array()[0], "url"), "https://x.example/'--%_");
  EXPECT_EQ(
      d.send("POST", "/api/v1/keys",
             R"({"role":"registrant","label":"x'); DELETE FROM api_keys; --"})", d.admin_key())
          .status,
      201);
  EXPECT_EQ(d.get("/api/v1/keys", d.admin_key()).status, 200);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots")), "total"), created);
  // LIKE metacharacters in q are literal; a quote in q is only text.
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots?q=%25%25")), "total"), 0);
  EXPECT_EQ(d.get("/api/v1/robots?q=%27%20OR%201%3D1%20--").status, 200);
  EXPECT_EQ(d.get("/api/v1/robots/search?q=%27%3B%20DROP").status, 200);
  EXPECT_EQ(d.get("/api/v1/robots?tier=%27%20OR%20%271%27%3D%271").status, 200);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots?tier=%27%20OR%20%271%27%3D%271")), "total"), 0);
  EXPECT_EQ(d.get("/api/v1/resolve/RRN-'%3B--").status, 400);
  EXPECT_EQ(d.get("/api/v1/nodes/'%3BDROP").status, 404);
  EXPECT_EQ(
      d.send("POST", "/api/v1/nodes",
             R"({"prefix":"X'--","operator":"o","node_url":"https://x.example"})", d.admin_key())
          .status,
      400);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots")), "total"), created);
}

struct PopKeys {
  Bytes ed_seed = ed25519::random_seed();
  Bytes ed_pub;
  mldsa65::KeyPair ml;
  PopKeys() {
    ed_pub = *ed25519::public_key_from_seed(ed_seed);
    ml = *mldsa65::keygen_random();
  }
  // A registration of acme/arm/v2/<device> carrying both keys and a proof over `challenge`.
  std::string body(const std::string& device, const json::Value& challenge, bool forge = false) {
    std::string msg = "rcan-registry-pop:" + str(challenge, "challenge_id") + ":" +
                      str(challenge, "nonce") + ":acme/arm/v2/" + device;
    Bytes ed_sig = *ed25519::sign(ed_seed, to_bytes(msg));
    if (forge) ed_sig[0] ^= 1;
    Bytes ml_sig = *mldsa65::sign(ml.secret_key, to_bytes(msg));
    json::Object o{{"manufacturer", "acme"},
                   {"model", "arm"},
                   {"version", "v2"},
                   {"device_id", device},
                   {"ed25519_public_key", base64url_encode(ed_pub)},
                   {"mldsa65_public_key", base64url_encode(ml.public_key)}};
    o.set("proof", json::Object{{"challenge_id", str(challenge, "challenge_id")},
                                {"ed25519_sig", base64url_encode(ed_sig)},
                                {"mldsa65_sig", base64url_encode(ml_sig)}});
    return json::dump(json::Value(std::move(o)));
  }
};

TEST(RegistryApi, ProofOfPossession) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  PopKeys keys;
  auto ch = d.get("/api/v1/challenge");
  ASSERT_EQ(ch.status, 200) << ch.body;
  json::Value c = body_of(ch);
  EXPECT_EQ(str(c, "challenge_id").size(), 32u);
  EXPECT_FALSE(str(c, "nonce").empty());
  EXPECT_FALSE(str(c, "expires_at").empty());

  // Keys without a proof are refused.
  std::string no_proof =
      R"({"manufacturer":"acme","model":"arm","version":"v2","device_id":"p-0","ed25519_public_key":")" +
      base64url_encode(keys.ed_pub) + "\"}";
  EXPECT_EQ(d.send("POST", "/api/v1/robots", no_proof, d.admin_key()).status, 400);
  // A forged signature: 401, nothing stored, and the challenge is used up.
  auto forged = d.send("POST", "/api/v1/robots", keys.body("p-1", c, true), d.admin_key());
  EXPECT_EQ(forged.status, 401) << forged.body;
  EXPECT_NE(forged.body.find("does not verify"), std::string::npos);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots")), "total"), 0);
  auto reused_after_failure = d.send("POST", "/api/v1/robots", keys.body("p-1", c), d.admin_key());
  EXPECT_EQ(reused_after_failure.status, 401);

  auto posted = d.send("POST", "/api/v1/challenge", "{}");
  EXPECT_EQ(posted.status, 201);
  json::Value c2 = body_of(posted);
  auto ok = d.send("POST", "/api/v1/robots", keys.body("p-2", c2), d.admin_key());
  ASSERT_EQ(ok.status, 201) << ok.body;
  std::string rrn = str(body_of(ok), "rrn");
  auto g = body_of(d.get("/api/v1/robots/" + rrn));
  EXPECT_EQ(str(g, "ed25519_public_key"), base64url_encode(keys.ed_pub));
  EXPECT_EQ(str(g, "mldsa65_public_key"), base64url_encode(keys.ml.public_key));
  auto res = body_of(d.get("/api/v1/resolve/" + rrn));
  EXPECT_EQ(str(*res.get("keys"), "ed25519"), base64url_encode(keys.ed_pub));
  // Reusing a consumed challenge for another device.
  auto reused = d.send("POST", "/api/v1/robots", keys.body("p-3", c2), d.admin_key());
  EXPECT_EQ(reused.status, 401);
  EXPECT_NE(reused.body.find("already used"), std::string::npos);
  // A proof made for another device does not verify for this one.
  json::Value c3 = body_of(d.get("/api/v1/challenge"));
  std::string other = keys.body("p-4", c3);
  std::string swapped = other.replace(other.find("p-4"), 3, "p-5");
  EXPECT_EQ(d.send("POST", "/api/v1/robots", swapped, d.admin_key()).status, 401);
  EXPECT_EQ(num(body_of(d.get("/api/v1/robots")), "total"), 1);
  // An unknown challenge.
  json::Value fake = json::Object{{"challenge_id", std::string(32, 'a')}, {"nonce", "AAAA"}};
  EXPECT_EQ(d.send("POST", "/api/v1/robots", keys.body("p-6", fake), d.admin_key()).status, 401);
}

TEST(RegistryApi, RateLimitsAnswer429WithRetryAfter) {
  TempDir dir;
  RegistryDaemon d(dir.path(), {"--write-rate", "1", "--write-burst", "3", "--read-rate", "5"});
  int limited = 0;
  std::string retry;
  for (int i = 0; i < 6; ++i) {
    auto r = d.send("POST", "/api/v1/robots", robot("rl-" + std::to_string(i)), d.admin_key());
    if (r.status == 429) {
      ++limited;
      retry = r.header("retry-after");
      EXPECT_NE(r.body.find("RATE_LIMITED"), std::string::npos);
    }
  }
  EXPECT_GE(limited, 2);
  EXPECT_GE(std::stoi(retry.empty() ? "0" : retry), 1);
  int read_limited = 0;
  for (int i = 0; i < 30; ++i)
    if (d.get("/api/v1/robots").status == 429) ++read_limited;
  EXPECT_GE(read_limited, 10);
}

TEST(RegistryApi, OversizeBodyIs413) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  std::string big = robot("big", ",\"description\":\"" + std::string(70 * 1024, 'x') + "\"");
  EXPECT_EQ(d.send("POST", "/api/v1/robots", big, d.admin_key()).status, 413);
  std::string long_field = robot("big", ",\"description\":\"" + std::string(2000, 'x') + "\"");
  EXPECT_EQ(d.send("POST", "/api/v1/robots", long_field, d.admin_key()).status, 400);
  EXPECT_EQ(d.get("/healthz").status, 200);
}

TEST(RegistryApi, NodesDelegationAndResolve) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  std::string node =
      R"({"prefix":"bd","operator":"Boston Dynamics","node_url":"https://bd.example/","contact":"ops@bd.example"})";
  EXPECT_EQ(d.send("POST", "/api/v1/nodes", node).status, 401);
  EXPECT_EQ(d.send("POST", "/api/v1/nodes", node, registrant(d)).status, 403);
  auto added = d.send("POST", "/api/v1/nodes", node, d.admin_key());
  ASSERT_EQ(added.status, 201) << added.body;
  EXPECT_EQ(str(body_of(added), "prefix"), "BD");
  EXPECT_EQ(d.send("POST", "/api/v1/nodes", node, d.admin_key()).status, 409);
  EXPECT_EQ(d.send("POST", "/api/v1/nodes",
                   R"({"prefix":"XY","operator":"o","node_url":"http://x"})", d.admin_key())
                .status,
            400);

  auto nodes = body_of(d.get("/api/v1/nodes"));
  EXPECT_EQ(num(nodes, "total"), 2);
  EXPECT_EQ(str(nodes.get("nodes")->as_array()[0], "node_type"), "root");
  auto bd = body_of(d.get("/api/v1/nodes?prefix=BD"));
  EXPECT_EQ(str(bd.get("nodes")->as_array()[0], "namespace_prefix"), "BD");
  EXPECT_EQ(str(bd.get("nodes")->as_array()[0], "api_base"), "https://bd.example/api/v1");
  EXPECT_EQ(num(body_of(d.get("/api/v1/nodes?prefix=QQ")), "total"), 1);  // the root alone
  EXPECT_EQ(str(*body_of(d.get("/api/v1/nodes/bd")).get("node"), "node_url"), "https://bd.example");
  EXPECT_EQ(str(*body_of(d.get("/api/v1/nodes/RRN")).get("node"), "node_type"), "root");
  EXPECT_EQ(d.get("/api/v1/nodes/ZZ").status, 404);

  auto redirect = d.get("/api/v1/resolve/RRN-BD-00000001");
  EXPECT_EQ(redirect.status, 307);
  // Sent on in the canonical form (12 digits, as both registries mint them).
  EXPECT_EQ(redirect.header("location"), "https://bd.example/api/v1/resolve/RRN-BD-000000000001");
  EXPECT_EQ(str(body_of(redirect), "authoritative_node"), "https://bd.example");
  auto missing = d.get("/api/v1/resolve/RRN-ZZ-00000001");
  EXPECT_EQ(missing.status, 404);
  EXPECT_EQ(str(body_of(missing), "error"), "NODE_DELEGATION_NOT_FOUND");
  EXPECT_EQ(d.get("/api/v1/resolve/RRN-000000000042").status, 404);
  auto bad = d.get("/api/v1/resolve/not-an-rrn");
  EXPECT_EQ(bad.status, 400);
  EXPECT_EQ(str(body_of(bad), "error"), "INVALID_RRN_FORMAT");

  auto r = d.send("POST", "/api/v1/robots", robot("res-1"), d.admin_key());
  std::string rrn = str(body_of(r), "rrn");
  auto res = d.get("/api/v1/resolve/" + rrn);
  ASSERT_EQ(res.status, 200);
  EXPECT_EQ(str(body_of(res), "namespace"), "root");
  EXPECT_EQ(str(*body_of(res).get("record"), "rrn"), rrn);
  EXPECT_EQ(res.header("x-rrn-namespace"), "root");
  // rcan-py's NodeClient fallback path (api_base + /api/v1/robots/…).
  EXPECT_EQ(d.get("/api/v1/api/v1/robots/" + rrn).status, 200);
}

// --open-registration (off by default: RegisterGetListSearchUpdateDelete's anonymous POST is 401)
// takes a robot without credentials, as rcan.dev and rcan-ts's RegistryClient.register do: at the
// community tier, with its own robot key, under a tight per-address limit; public keys need the
// same proof of possession as with a key; a wrong key is still refused, never taken as anonymous.
TEST(RegistryApi, OpenRegistrationTakesAnonymousRobotsAtTheCommunityTier) {
  TempDir dir;
  RegistryDaemon d(dir.path(), {"--open-registration"});
  ASSERT_FALSE(d.url().empty());
  auto r = d.send("POST", "/api/v1/robots", robot("open-1"));
  ASSERT_EQ(r.status, 201) << r.body;
  const json::Value b = body_of(r);
  EXPECT_EQ(str(b, "verification_tier"), "community");
  const std::string rrn = str(b, "rrn"), robot_key = str(b, "api_key");
  ASSERT_FALSE(robot_key.empty());
  EXPECT_EQ(d.send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"mine"})", robot_key).status,
            200);
  // Names registered already are not an anonymous caller's to adopt.
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("open-1")).status, 409);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("open-2"), "not-a-key").status, 401);
  // Keys without a proof are refused; with one, the robot is registered as proven.
  auto k = keys::generate();
  ASSERT_TRUE(k.ok());
  auto unproven = d.send(
      "POST", "/api/v1/robots",
      robot("open-3", R"(,"ed25519_public_key":")" + base64url_encode(k->pub.ed25519_pk) + "\""));
  EXPECT_EQ(unproven.status, 400) << unproven.body;
  EXPECT_NE(unproven.body.find("proof_required"), std::string::npos) << unproven.body;
  auto proven = d.register_proven("", "acme", "arm", "v1", "open-4");
  ASSERT_EQ(proven.status, 201) << proven.body;
  EXPECT_TRUE(body_of(proven).get("identity_proven")->as_bool());
  // Five anonymous attempts an address (these were four), then one a minute; a key is not held
  // back by them.
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("open-5")).status, 201);
  auto limited = d.send("POST", "/api/v1/robots", robot("open-6"));
  EXPECT_EQ(limited.status, 429) << limited.body;
  EXPECT_NE(limited.body.find("open_registration"), std::string::npos) << limited.body;
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("open-6"), d.admin_key()).status, 201);
  std::string audit;
  for (const auto& e : std::filesystem::directory_iterator(dir.file("audit")))
    if (e.path().filename().string().rfind("seg-", 0) == 0) audit += read_file(e.path().string());
  EXPECT_NE(audit.find("\"principal\":\"anonymous:127.0.0.1\""), std::string::npos);
}

TEST(RegistryApi, PrefixNodeMintsPrefixedRrns) {
  TempDir dir;
  RegistryDaemon d(dir.path(), {"--prefix", "ACME", "--public-url", "https://reg.acme.example"});
  auto r = d.send("POST", "/api/v1/robots", robot("px-1"), d.admin_key());
  ASSERT_EQ(r.status, 201) << r.body;
  std::string rrn = str(body_of(r), "rrn");
  EXPECT_EQ(rrn.rfind("RRN-ACME-", 0), 0u) << rrn;
  EXPECT_EQ(str(body_of(r), "rcan_uri").rfind("rcan://reg.acme.example/", 0), 0u);
  auto man = body_of(d.get("/.well-known/rcan-node.json"));
  EXPECT_EQ(str(man, "node_type"), "authoritative");
  EXPECT_EQ(str(man, "namespace_prefix"), "ACME");
  EXPECT_EQ(str(man, "api_base"), "https://reg.acme.example/api/v1");
  auto res = d.get("/api/v1/resolve/" + rrn);
  EXPECT_EQ(res.status, 200);
  EXPECT_EQ(str(body_of(res), "namespace"), "ACME");
}

TEST(RegistryApi, RestartKeepsDataAndAuditsChanges) {
  TempDir dir;
  std::string rrn, robot_key;
  {
    RegistryDaemon d(dir.path());
    auto r = d.send("POST", "/api/v1/robots", robot("keep-1"), d.admin_key());
    rrn = str(body_of(r), "rrn");
    robot_key = str(body_of(r), "api_key");
    d.send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"kept"})", robot_key);
    d.send("POST", "/api/v1/nodes",
           R"({"prefix":"KP","operator":"o","node_url":"https://kp.example"})", d.admin_key());
    EXPECT_EQ(d.proc().stop(SIGTERM, 10000), 0);
  }
  std::string admin = read_file(dir.file("admin.key"));
  RegistryDaemon d(dir.path());
  EXPECT_EQ(d.admin_key(), admin);
  EXPECT_EQ(d.proc().err().find("a new admin API key"), std::string::npos);
  auto g = d.get("/api/v1/robots/" + rrn);
  ASSERT_EQ(g.status, 200);
  EXPECT_EQ(str(body_of(g), "description"), "kept");
  EXPECT_EQ(
      d.send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"again"})", robot_key).status,
      200);
  EXPECT_EQ(d.get("/api/v1/nodes/KP").status, 200);
  auto next = d.send("POST", "/api/v1/robots", robot("keep-2"), admin);
  EXPECT_EQ(str(body_of(next), "rrn"), "RRN-000000000002");

  std::string audit;
  for (const auto& e : std::filesystem::directory_iterator(dir.file("audit")))
    if (e.path().filename().string().rfind("seg-", 0) == 0) audit += read_file(e.path().string());
  for (const char* ev : {"REGISTRY_KEY_CREATED", "REGISTRY_ROBOT_REGISTERED",
                         "REGISTRY_ROBOT_UPDATED", "REGISTRY_PREFIX_DELEGATED"})
    EXPECT_NE(audit.find(ev), std::string::npos) << ev;
}

// The first admin key is made once per database: a start that finds no admin.key in its data
// directory (restored from a backup, or the key moved to a vault) but admin keys in the database
// mints none — it says so and the old key goes on working.
TEST(RegistryApi, MissingAdminKeyFileMintsNoNewAdminKey) {
  TempDir dir;
  std::string admin;
  {
    RegistryDaemon d(dir.path());
    admin = d.admin_key();
    ASSERT_FALSE(admin.empty());
    EXPECT_EQ(admin_keys(d, admin), 1);
    EXPECT_EQ(d.proc().stop(SIGTERM, 10000), 0);
  }
  ASSERT_TRUE(std::filesystem::remove(dir.file("admin.key")));
  RegistryDaemon d(dir.path());
  EXPECT_FALSE(std::filesystem::exists(dir.file("admin.key")));
  EXPECT_EQ(d.proc().err().find("a new admin API key"), std::string::npos);
  EXPECT_NE(d.proc().err().find("\"event\":\"admin_key_exists\""), std::string::npos)
      << d.proc().err();
  EXPECT_EQ(admin_keys(d, admin), 1);
  EXPECT_EQ(d.send("POST", "/api/v1/robots", robot("after-restore"), admin).status, 201);
}

// Instances on one PostgreSQL database share its one first admin key: only the first start
// writes admin.key; the others mint none.
TEST(RegistryApi, InstancesOnOnePostgresDatabaseMintOneAdminKey) {
  Postgres pg;
  TempDir a_dir, b_dir;
  RegistryDaemon a(a_dir.path(), {"--database", pg.url()});
  RegistryDaemon b(b_dir.path(), {"--database", pg.url()});
  ASSERT_FALSE(a.admin_key().empty());
  EXPECT_TRUE(b.admin_key().empty());
  EXPECT_EQ(admin_keys(b, a.admin_key()), 1);
}

// Two stateless instances on one PostgreSQL database (--database postgresql://…): what one
// registers, the other serves; keys made on one work on the other; concurrent registrations of
// one robot through both mint one RRN.
TEST(RegistryApi, TwoInstancesOnOnePostgresDatabase) {
  Postgres pg;
  TempDir a_dir, b_dir;
  RegistryDaemon a(a_dir.path(), {"--database", pg.url()});
  RegistryDaemon b(b_dir.path(), {"--database", pg.url()});
  EXPECT_EQ(str(body_of(a.get("/healthz")), "backend"), "postgresql");
  auto r = a.send("POST", "/api/v1/robots", robot("pg-1"), a.admin_key());
  ASSERT_EQ(r.status, 201) << r.body;
  std::string rrn = str(body_of(r), "rrn");
  EXPECT_EQ(b.get("/api/v1/robots/" + rrn).status, 200);
  EXPECT_EQ(b.send("PATCH", "/api/v1/robots/" + rrn, R"({"description":"via b"})",
                   str(body_of(r), "api_key"))
                .status,
            200);
  EXPECT_EQ(str(body_of(a.get("/api/v1/robots/" + rrn)), "description"), "via b");
  // a's admin key is valid on b (one key table).
  EXPECT_EQ(b.get("/api/v1/keys", a.admin_key()).status, 200);

  std::vector<std::thread> threads;
  std::vector<std::string> rrns(8);
  for (int i = 0; i < 8; ++i)
    threads.emplace_back([&, i] {
      const RegistryDaemon& d = i % 2 == 0 ? a : b;
      auto x = d.send("POST", "/api/v1/robots", robot("same"), a.admin_key());  // one database
      rrns[static_cast<size_t>(i)] = str(body_of(x), "rrn");
    });
  for (auto& t : threads) t.join();
  for (const auto& x : rrns) EXPECT_EQ(x, rrns[0]);
  EXPECT_EQ(num(body_of(b.get("/api/v1/robots")), "total"), 2);
}

TEST(RegistryApi, FlagsHelpAndTheDefaultDataDirectory) {
  auto help = run({RCAN_REGISTRY_PATH, "--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("--public-url"), std::string::npos);
  EXPECT_EQ(run({RCAN_REGISTRY_PATH, "--bogus"}).exit_code, 2);
  EXPECT_EQ(run({RCAN_REGISTRY_PATH, "--port", "70000"}).exit_code, 2);
  // No --data-dir: $HOME/.local/share/rcan-registry (as rcand's ~/.local/share/rcand).
  TempDir home;
  Process p;
  ASSERT_TRUE(p.start({RCAN_REGISTRY_PATH, "--port", "0"},
                      {"HOME=" + home.path(), "XDG_DATA_HOME=", "RCAN_REGISTRY_DATA_DIR="}));
  auto line = p.wait_for_line("\"event\":\"listening\"", 30000);
  ASSERT_TRUE(line) << p.err();
  std::string dir = home.path() + "/.local/share/rcan-registry";
  EXPECT_NE(line->find(dir), std::string::npos) << *line;
  EXPECT_EQ(mode_of(dir), 0700u);
  EXPECT_EQ(mode_of(dir + "/admin.key"), 0600u);
  EXPECT_EQ(p.stop(SIGTERM, 10000), 0);
}

TEST(RegistryApi, AConfigFileSetsTheFlagsAndTheCommandLineWins) {
  TempDir cfg;
  const std::string file = cfg.path() + "/registry.yaml";
  std::ofstream(file) << "port: 1\ndata-dir: state\nread-rate: 500\noperator: Acme robots\n"
                         "allow-http-node-urls: true\nsync-from: []\n";
  Process p;
  // --port on the command line wins over the file's port 1; data-dir is the file's, relative
  // to the file.
  ASSERT_TRUE(p.start({RCAN_REGISTRY_PATH, "--config", file, "--port", "0"}));
  auto line = p.wait_for_line("\"event\":\"listening\"", 30000);
  ASSERT_TRUE(line) << p.err();
  EXPECT_NE(line->find(cfg.path() + "/state"), std::string::npos) << *line;
  EXPECT_EQ(mode_of(cfg.path() + "/state/admin.key"), 0600u);
  EXPECT_EQ(p.stop(SIGTERM, 10000), 0);
  // Bad files are refused with the file and the key named (exit 2), never half-applied.
  const std::pair<std::string, std::string> bad[] = {
      {"bogus: 1\n", "unknown argument '--bogus'"},
      {"port: [1, 2]\n", "'port' must be a single value"},
      {"allow-http-node-urls: maybe\n", "must be true or false"},
      {"config: other.yaml\n", "'config' is not a setting"},
      {"port: 70000\n", "--port must be 0..65535"},
      {"- port\n", "must be a mapping"},
      {"port: [\n", "not valid YAML"},
  };
  for (const auto& [text, message] : bad) {
    std::ofstream(file, std::ios::trunc) << text;
    auto r = run({RCAN_REGISTRY_PATH, "--config", file});
    EXPECT_EQ(r.exit_code, 2) << text;
    EXPECT_NE(r.err.find(message), std::string::npos) << text << " -> " << r.err;
  }
  auto missing = run({RCAN_REGISTRY_PATH, "--config", cfg.path() + "/none.yaml"});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("cannot be read"), std::string::npos) << missing.err;
}

// rcan-registry started with `args`: its exit status when it refuses to start, -1 when it
// serves (then it is stopped); `err` receives its stderr.
int refused_start(const std::vector<std::string>& args, std::string& err) {
  std::vector<std::string> argv{RCAN_REGISTRY_PATH};
  argv.insert(argv.end(), args.begin(), args.end());
  Process p;
  EXPECT_TRUE(p.start(argv));
  const bool served = p.wait_for_line("\"event\":\"listening\"", 30000).has_value();
  const int status = p.stop(SIGTERM, 10000);
  err = p.err();
  return served ? -1 : status;
}

// F12: a database password on the command line is in every local user's `ps`. rcan-registry
// refuses one in --database (naming where it goes instead) and in a config file others can read;
// PostgreSQL's own PGPASSFILE carries it. Before: the password URL was taken as given.
TEST(RegistryApi, ADatabasePasswordComesFromPgpassfileNeverFromTheCommandLine) {
  Postgres pg;
  // A role that must give a password: password authentication for it, ahead of the trust lines.
  ASSERT_EQ(pg.sql("CREATE ROLE registry LOGIN PASSWORD 'pg-secret-7f3a'").exit_code, 0);
  ASSERT_EQ(pg.sql("CREATE DATABASE reg OWNER registry").exit_code, 0);
  auto hba = pg.sql("SHOW hba_file");
  ASSERT_EQ(hba.exit_code, 0) << hba.err;
  const std::string hba_file = hba.out.substr(0, hba.out.find('\n'));
  const std::string rules = read_file(hba_file);
  std::ofstream(hba_file, std::ios::trunc) << "host all registry 127.0.0.1/32 scram-sha-256\n"
                                           << rules;
  ASSERT_EQ(pg.sql("SELECT pg_reload_conf()").exit_code, 0);
  const std::string port = std::to_string(pg.port());
  const std::string plain = "postgresql://registry@127.0.0.1:" + port + "/reg";
  TempDir dir;

  // In the URL, either form: refused before anything is opened (exit 2), the way out named.
  for (const std::string& with_password :
       {"postgresql://registry:pg-secret-7f3a@127.0.0.1:" + port + "/reg",
        plain + "?sslmode=disable&password=pg-secret-7f3a"}) {
    std::string err;
    EXPECT_EQ(refused_start(
                  {"--data-dir", dir.file("a"), "--port", "0", "--database", with_password}, err),
              2)
        << with_password << ": " << err;
    EXPECT_NE(err.find("--database must not carry a password"), std::string::npos) << err;
    EXPECT_NE(err.find("PGPASSFILE"), std::string::npos) << err;
  }
  // In a config file others can read: refused too.
  const std::string cfg = dir.file("registry.yaml");
  std::ofstream(cfg) << "database: postgresql://registry:pg-secret-7f3a@127.0.0.1:" << port
                     << "/reg\n";
  ::chmod(cfg.c_str(), 0644);
  std::string readable;
  EXPECT_EQ(refused_start({"--config", cfg, "--data-dir", dir.file("b"), "--port", "0"}, readable),
            2)
      << readable;
  EXPECT_NE(readable.find("mode 0600"), std::string::npos) << readable;

  // The password must come from somewhere: without it the server refuses the registry.
  auto none =
      run({RCAN_REGISTRY_PATH, "--data-dir", dir.file("c"), "--port", "0", "--database", plain}, {},
          {"PGPASSFILE=" + dir.file("no-such-file")});
  EXPECT_NE(none.exit_code, 0);
  EXPECT_NE(none.err.find("password"), std::string::npos) << none.err;
  // PGPASSFILE (0600): the registry runs on that database.
  const std::string pgpass = dir.file("pgpass");
  std::ofstream(pgpass) << "127.0.0.1:" << port << ":reg:registry:pg-secret-7f3a\n";
  ::chmod(pgpass.c_str(), 0600);
  {
    Process p;
    ASSERT_TRUE(p.start(
        {RCAN_REGISTRY_PATH, "--data-dir", dir.file("d"), "--port", "0", "--database", plain},
        {"PGPASSFILE=" + pgpass}));
    auto line = p.wait_for_line("\"event\":\"listening\"", 30000);
    ASSERT_TRUE(line) << p.err();
    EXPECT_NE(line->find("\"backend\":\"postgresql\""), std::string::npos) << *line;
    EXPECT_EQ(p.stop(SIGTERM, 10000), 0);
  }
  // A config file only its owner reads may hold the URL with the password.
  ::chmod(cfg.c_str(), 0600);
  Process q;
  ASSERT_TRUE(
      q.start({RCAN_REGISTRY_PATH, "--config", cfg, "--data-dir", dir.file("e"), "--port", "0"},
              {"PGPASSFILE=" + dir.file("no-such-file")}));
  auto line = q.wait_for_line("\"event\":\"listening\"", 30000);
  ASSERT_TRUE(line) << q.err();
  EXPECT_NE(line->find("\"backend\":\"postgresql\""), std::string::npos) << *line;
  EXPECT_EQ(q.stop(SIGTERM, 10000), 0);
}

}  // namespace
}  // namespace rcan::test
