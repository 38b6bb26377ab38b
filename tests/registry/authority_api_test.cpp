// rcan-registry's token authority (docs/REGISTRY.md "Token authority") over real sockets:
// clients and grants, the OAuth 2.0 token endpoint (client_secret_basic, client_secret_post,
// private_key_jwt), tokens verified by the project's own JWT verifier with the daemon's JWKS,
// introspection, revocations, key rotation, the device authorization grant and two instances
// on one PostgreSQL database.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include "postgres.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
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

HttpReply form(const RegistryDaemon& d, const std::string& path, const std::string& body,
               const std::vector<std::pair<std::string, std::string>>& extra = {}) {
  std::vector<std::pair<std::string, std::string>> h{
      {"Content-Type", "application/x-www-form-urlencoded"}};
  h.insert(h.end(), extra.begin(), extra.end());
  return http(d.port(), "POST", path, body, h);
}

bool write_file(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  return static_cast<bool>(f);
}

// The registry's audit records (one JSON object a line in audit/seg-*), in no particular order.
std::vector<json::Value> audit_records(const TempDir& dir) {
  std::vector<json::Value> out;
  for (const auto& e : std::filesystem::directory_iterator(dir.file("audit"))) {
    if (e.path().filename().string().rfind("seg-", 0) != 0) continue;
    std::string text = read_file(e.path().string());
    size_t at = 0;
    while (at < text.size()) {
      size_t nl = text.find('\n', at);
      if (nl == std::string::npos) nl = text.size();
      auto v = json::parse(text.substr(at, nl - at));
      if (v.ok()) out.push_back(std::move(*v));
      at = nl + 1;
    }
  }
  return out;
}

// The value of an unlabelled counter in the /metrics text (-1 when absent).
double metric(const RegistryDaemon& d, const std::string& name) {
  auto m = d.get("/metrics");
  size_t at = m.body.find("\n" + name + " ");
  if (at == std::string::npos) return -1;
  return std::stod(m.body.substr(at + name.size() + 2));
}

std::string oauth_error_of(const HttpReply& r) { return str(body_of(r), "error"); }

// A registrant's key and a robot it registered (metadata.ruri as rcand sends it).
struct Fixture {
  std::string registrant, registrant_id, rrn_a, rrn_b, robot_key_a;
  std::string ruri_a = "rcan://rcan.local/acme/arm/a1b2c3d4";
  std::string ruri_b = "rcan://rcan.local/acme/arm/b1b2c3d4";
};

Fixture setup(const RegistryDaemon& d) {
  Fixture s;
  auto k =
      d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"owner"})", d.admin_key());
  EXPECT_EQ(k.status, 201) << k.body;
  s.registrant = str(body_of(k), "key");
  s.registrant_id = str(body_of(k), "id");
  auto reg = [&](const std::string& dev, const std::string& ruri, std::string& key) {
    auto r =
        d.register_proven(s.registrant, "acme", "arm", "v1", dev, R"({"ruri":")" + ruri + R"("})");
    EXPECT_EQ(r.status, 201) << r.body;
    key = str(body_of(r), "api_key");
    return str(body_of(r), "rrn");
  };
  std::string unused;
  s.rrn_a = reg("a1b2c3d4", s.ruri_a, s.robot_key_a);
  s.rrn_b = reg("b1b2c3d4", s.ruri_b, unused);
  return s;
}

// A client with a secret and a grant on robot A (role user, scopes status + teleop).
std::pair<std::string, std::string> secret_client(const RegistryDaemon& d, const Fixture& s) {
  auto c =
      d.send("POST", "/api/v1/clients", R"({"name":"ops","auth":"client_secret"})", s.registrant);
  EXPECT_EQ(c.status, 201) << c.body;
  std::string id = str(body_of(c), "client_id"), secret = str(body_of(c), "client_secret");
  auto g = d.send("POST", "/api/v1/grants",
                  R"({"principal":")" + id + R"(","robot":")" + s.rrn_a +
                      R"(","role":"user","scope":["status","teleop"],"max_ttl_s":600})",
                  s.registrant);
  EXPECT_EQ(g.status, 201) << g.body;
  return {id, secret};
}

std::string token_of(const RegistryDaemon& d, const std::string& id, const std::string& secret,
                     const std::string& rrn) {
  auto r = form(d, "/oauth/token",
                "grant_type=client_credentials&client_id=" + id + "&client_secret=" + secret +
                    "&resource=" + rrn);
  EXPECT_EQ(r.status, 200) << r.body;
  return str(body_of(r), "access_token");
}

Result<jwt::Claims> verify(const RegistryDaemon& d, const std::string& token,
                           const std::string& audience) {
  auto jwks = d.get("/.well-known/jwks.json");
  EXPECT_EQ(jwks.status, 200);
  auto keys = jwt::parse_jwk_set(jwks.body);
  EXPECT_TRUE(keys.ok()) << jwks.body;
  jwt::TrustStore ts;
  if (keys.ok())
    for (auto& k : *keys) ts.add(d.url(), k);
  jwt::VerifyOptions vo;
  vo.audience = audience;
  return jwt::JwtVerifier(std::move(ts), vo).verify(token);
}

std::string basic(const std::string& id, const std::string& secret) {
  std::string raw = id + ":" + secret;
  return "Basic " + base64_encode(reinterpret_cast<const uint8_t*>(raw.data()), raw.size());
}

TEST(RegistryAuthority, ClientCredentialsWithSecretVerifiedWithTheJwks) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  Fixture s = setup(d);
  auto [id, secret] = secret_client(d, s);

  // client_secret_basic
  auto r = form(d, "/oauth/token", "grant_type=client_credentials&resource=" + s.rrn_a,
                {{"Authorization", basic(id, secret)}});
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.header("cache-control"), "no-store");
  EXPECT_EQ(str(body_of(r), "token_type"), "Bearer");
  EXPECT_EQ(num(body_of(r), "expires_in"), 600);
  std::string tok = str(body_of(r), "access_token");
  auto c = verify(d, tok, s.ruri_a);
  ASSERT_TRUE(c.ok()) << c.error().message << " " << json::dump(jwt::decode(tok)->claims);
  EXPECT_EQ(c->iss, d.url());
  EXPECT_EQ(c->sub, id);
  EXPECT_EQ(c->role, "user");
  EXPECT_TRUE(c->has_scope("teleop"));
  EXPECT_FALSE(c->jti.empty());
  EXPECT_FALSE(c->kid.empty());
  EXPECT_FALSE(verify(d, tok, s.ruri_b).ok());  // another robot's RURI

  // client_secret_post with a narrower scope, by RURI
  r = form(d, "/oauth/token",
           "grant_type=client_credentials&client_id=" + id + "&client_secret=" + secret +
               "&resource=" + s.ruri_a + "&scope=status");
  ASSERT_EQ(r.status, 200) << r.body;
  c = verify(d, str(body_of(r), "access_token"), s.ruri_a);
  ASSERT_TRUE(c.ok());
  EXPECT_TRUE(c->has_scope("status"));
  EXPECT_FALSE(c->has_scope("teleop"));

  // Beyond the grant
  auto post = [&](const std::string& extra) {
    return form(
        d, "/oauth/token",
        "grant_type=client_credentials&client_id=" + id + "&client_secret=" + secret + extra);
  };
  EXPECT_EQ(oauth_error_of(post("&resource=" + s.rrn_a + "&scope=admin")), "invalid_scope");
  EXPECT_EQ(oauth_error_of(post("&resource=" + s.rrn_a + "&role=owner")), "invalid_scope");
  EXPECT_EQ(oauth_error_of(post("&resource=" + s.rrn_a + "&role=creator")), "invalid_scope");
  EXPECT_EQ(oauth_error_of(post("&resource=" + s.rrn_b)), "unauthorized_client");
  EXPECT_EQ(post("&resource=" + s.rrn_b).status, 400);
  // Wrong secret, unknown client, SQL metacharacters
  auto bad = form(d, "/oauth/token", "grant_type=client_credentials&resource=" + s.rrn_a,
                  {{"Authorization", basic(id, "nope")}});
  EXPECT_EQ(bad.status, 401);
  EXPECT_EQ(oauth_error_of(bad), "invalid_client");
  EXPECT_FALSE(bad.header("www-authenticate").empty());
  bad = form(d, "/oauth/token",
             "grant_type=client_credentials&client_id=x%27%20OR%201%3D1--&client_secret=y"
             "&resource=" +
                 s.rrn_a);
  EXPECT_EQ(oauth_error_of(bad), "invalid_client");
  // Hostile forms
  EXPECT_EQ(oauth_error_of(post("&resource=" + s.rrn_a + "&grant_type=password")),
            "invalid_request");  // repeated parameter
  EXPECT_EQ(oauth_error_of(form(d, "/oauth/token", "grant_type=password&username=a&password=b")),
            "unsupported_grant_type");
  EXPECT_EQ(oauth_error_of(form(d, "/oauth/token", "grant_type=client_credentials&x=%zz")),
            "invalid_request");
  EXPECT_EQ(oauth_error_of(form(d, "/oauth/token", "resource=x")), "invalid_request");
  EXPECT_EQ(
      oauth_error_of(d.send("POST", "/oauth/token", R"({"grant_type":"client_credentials"})")),
      "invalid_request");
  EXPECT_EQ(oauth_error_of(post("")), "invalid_request");  // no resource
  std::string huge = "grant_type=client_credentials&pad=" + std::string(20000, 'a');
  EXPECT_EQ(oauth_error_of(form(d, "/oauth/token", huge)), "invalid_request");
  auto giant = form(d, "/oauth/token", std::string(3 << 20, 'a'));
  EXPECT_TRUE(giant.status == 413 || giant.status == 400 || giant.status == 0) << giant.status;
  EXPECT_EQ(d.get("/oauth/token").status, 405);

  // A grant deleted stops new tokens.
  auto grants = body_of(d.get("/api/v1/grants", s.registrant));
  ASSERT_EQ(grants.get("grants")->as_array().size(), 1u);
  int64_t gid = num(grants.get("grants")->as_array()[0], "id");
  EXPECT_EQ(d.send("DELETE", "/api/v1/grants/" + std::to_string(gid), "", s.registrant).status,
            200);
  EXPECT_EQ(oauth_error_of(post("&resource=" + s.rrn_a)), "unauthorized_client");
  // Only the robot's owner or an admin grants on it.
  auto other =
      d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"x"})", d.admin_key());
  std::string other_key = str(body_of(other), "key");
  EXPECT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":")" + id + R"(","robot":")" + s.rrn_a + R"(","role":"owner"})",
                   other_key)
                .status,
            403);
  EXPECT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":")" + id + R"(","robot":")" + s.rrn_a + R"(","role":"creator"})",
                   d.admin_key())
                .status,
            400);
}

std::string assertion(const Bytes& seed, const std::string& id, const std::string& aud,
                      int64_t exp_in, const std::string& jti) {
  auto key = jwt::SigningKey::ed25519_seed(seed);
  EXPECT_TRUE(key.ok());
  int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                    std::chrono::system_clock::now().time_since_epoch())
                    .count();
  json::Object c{{"iss", id},  {"sub", id},           {"aud", aud},
                 {"iat", now}, {"exp", now + exp_in}, {"jti", jti}};
  auto t = jwt::issue(c, *key);
  EXPECT_TRUE(t.ok());
  return t.ok() ? *t : "";
}

TEST(RegistryAuthority, PrivateKeyJwtClient) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  Fixture s = setup(d);
  Bytes seed = ed25519::random_seed();
  auto pub = ed25519::public_key_from_seed(seed);
  ASSERT_TRUE(pub.ok());
  auto c = d.send(
      "POST", "/api/v1/clients",
      R"({"name":"fleet-ops","auth":"private_key_jwt","jwk":{"kty":"OKP","crv":"Ed25519","x":")" +
          base64url_encode(*pub) + R"("}})",
      s.registrant);
  ASSERT_EQ(c.status, 201) << c.body;
  std::string id = str(body_of(c), "client_id");
  EXPECT_EQ(body_of(c).get("client_secret"), nullptr);
  ASSERT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":")" + id + R"(","robot":")" + s.rrn_a +
                       R"(","role":"leasee","scope":["status"]})",
                   s.registrant)
                .status,
            201);
  std::string endpoint = d.url() + "/oauth/token";
  auto ask = [&](const std::string& a) {
    return form(d, "/oauth/token",
                "grant_type=client_credentials&client_assertion_type=urn%3Aietf%3Aparams%3Aoauth%"
                "3Aclient-assertion-type%3Ajwt-bearer&client_assertion=" +
                    a + "&resource=" + s.rrn_a);
  };
  std::string good = assertion(seed, id, endpoint, 120, "j-1");
  auto r = ask(good);
  ASSERT_EQ(r.status, 200) << r.body;
  auto claims = verify(d, str(body_of(r), "access_token"), s.ruri_a);
  ASSERT_TRUE(claims.ok()) << claims.error().message;
  EXPECT_EQ(claims->role, "leasee");
  EXPECT_EQ(oauth_error_of(ask(good)), "invalid_client");  // replayed
  EXPECT_EQ(oauth_error_of(ask(assertion(seed, id, d.url() + "/other", 120, "j-2"))),
            "invalid_client");
  EXPECT_EQ(oauth_error_of(ask(assertion(seed, id, endpoint, -10, "j-3"))), "invalid_client");
  EXPECT_EQ(oauth_error_of(ask(assertion(seed, id, endpoint, 3600, "j-4"))), "invalid_client");
  EXPECT_EQ(oauth_error_of(ask(assertion(ed25519::random_seed(), id, endpoint, 120, "j-5"))),
            "invalid_client");
  EXPECT_EQ(ask(assertion(seed, id, endpoint, 120, "j-6")).status, 200);
}

TEST(RegistryAuthority, IntrospectionAndRevocationsFeed) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  Fixture s = setup(d);
  auto [id, secret] = secret_client(d, s);
  std::string tok = token_of(d, id, secret, s.rrn_a);
  auto introspect = [&](const std::string& t, const std::string& key) {
    return form(d, "/oauth/introspect", "token=" + t, {{"Authorization", "Bearer " + key}});
  };
  auto r = introspect(tok, s.robot_key_a);
  ASSERT_EQ(r.status, 200) << r.body;
  auto b = body_of(r);
  EXPECT_EQ(b.get("active")->as_bool(), true);
  EXPECT_EQ(str(b, "sub"), id);
  EXPECT_EQ(str(b, "aud"), s.ruri_a);
  EXPECT_EQ(str(b, "role"), "user");
  EXPECT_EQ(str(b, "iss"), d.url());
  std::string jti = str(b, "jti");
  EXPECT_FALSE(jti.empty());
  // client credentials authenticate too; no credentials do not
  auto by_client =
      form(d, "/oauth/introspect", "token=" + tok, {{"Authorization", basic(id, secret)}});
  EXPECT_EQ(body_of(by_client).get("active")->as_bool(), true);
  EXPECT_EQ(form(d, "/oauth/introspect", "token=" + tok).status, 401);
  EXPECT_EQ(introspect(tok, s.registrant).status, 403);
  EXPECT_EQ(body_of(introspect("garbage", d.admin_key())).get("active")->as_bool(), false);
  std::string tampered =
      tok.substr(0, tok.size() - 4) + (tok.substr(tok.size() - 4) == "AAAA" ? "BBBB" : "AAAA");
  EXPECT_EQ(body_of(introspect(tampered, d.admin_key())).get("active")->as_bool(), false);

  // Revoked by the robot's owner, who presents the token.
  auto rv = d.send("POST", "/api/v1/revocations",
                   R"({"token":")" + tok + R"(","reason":"lost laptop"})", s.registrant);
  ASSERT_EQ(rv.status, 201) << rv.body;
  int64_t seq1 = num(body_of(rv), "seq");
  EXPECT_EQ(body_of(introspect(tok, s.robot_key_a)).get("active")->as_bool(), false);
  // by jti and sub (admin); not by a stranger
  EXPECT_EQ(d.send("POST", "/api/v1/revocations", R"({"jti":"x"})", s.registrant).status, 403);
  std::vector<int64_t> seqs{seq1};
  for (int i = 0; i < 3; ++i) {
    auto x = d.send("POST", "/api/v1/revocations",
                    R"({"jti":"j')" + std::to_string(i) + R"(; DROP TABLE x;--"})", d.admin_key());
    ASSERT_EQ(x.status, 201) << x.body;
    seqs.push_back(num(body_of(x), "seq"));
  }
  auto x = d.send("POST", "/api/v1/revocations", R"({"sub":")" + id + R"("})", d.admin_key());
  ASSERT_EQ(x.status, 201);
  seqs.push_back(num(body_of(x), "seq"));
  for (size_t i = 1; i < seqs.size(); ++i) EXPECT_GT(seqs[i], seqs[i - 1]);
  auto feed = body_of(d.get("/api/v1/revocations?since=0"));
  const auto& list = feed.get("revocations")->as_array();
  ASSERT_EQ(list.size(), 5u);
  EXPECT_EQ(str(list[0], "jti"), jti);
  EXPECT_TRUE(list[0].get("exp")->is_int());
  EXPECT_TRUE(list[4].get("jti")->is_null());
  EXPECT_EQ(str(list[4], "sub"), id);
  EXPECT_EQ(num(feed, "next_since"), seqs.back());
  auto page = body_of(d.get("/api/v1/revocations?since=" + std::to_string(seqs[2])));
  EXPECT_EQ(page.get("revocations")->as_array().size(), 2u);
  auto empty = body_of(d.get("/api/v1/revocations?since=" + std::to_string(seqs.back())));
  EXPECT_EQ(empty.get("revocations")->as_array().size(), 0u);
  EXPECT_EQ(num(empty, "next_since"), seqs.back());
  EXPECT_EQ(d.get("/api/v1/revocations?since=abc").status, 400);
  // The sub revocation covers tokens issued before it, not after.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  std::string later = token_of(d, id, secret, s.rrn_a);
  EXPECT_EQ(body_of(introspect(later, s.robot_key_a)).get("active")->as_bool(), true);
}

// Every revocation leaves a REGISTRY_TOKEN_REVOKED record naming it (its feed seq, jti, sub);
// none of the appends fails.
TEST(RegistryAuthority, RevocationsAreAudited) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  auto by_jti =
      d.send("POST", "/api/v1/revocations", R"({"jti":"j-1","reason":"lost"})", d.admin_key());
  ASSERT_EQ(by_jti.status, 201) << by_jti.body;
  auto by_sub = d.send("POST", "/api/v1/revocations", R"({"sub":"client-9"})", d.admin_key());
  ASSERT_EQ(by_sub.status, 201) << by_sub.body;
  const int64_t seq_jti = num(body_of(by_jti), "seq"), seq_sub = num(body_of(by_sub), "seq");
  std::vector<json::Value> revoked;
  for (auto& r : audit_records(dir))
    if (str(r, "event") == "REGISTRY_TOKEN_REVOKED") revoked.push_back(r);
  ASSERT_EQ(revoked.size(), 2u);
  bool saw_jti = false, saw_sub = false;
  for (const auto& r : revoked) {
    const json::Value* detail = r.get("detail");
    ASSERT_NE(detail, nullptr);
    if (str(*detail, "jti") == "j-1") {
      saw_jti = true;
      EXPECT_EQ(num(*detail, "revocation_seq"), seq_jti);
      EXPECT_EQ(str(*detail, "reason"), "lost");
    } else if (str(*detail, "sub") == "client-9") {
      saw_sub = true;
      EXPECT_EQ(num(*detail, "revocation_seq"), seq_sub);
    }
  }
  EXPECT_TRUE(saw_jti && saw_sub);
  EXPECT_EQ(metric(d, "rcan_registry_audit_failures_total"), 0);
}

TEST(RegistryAuthority, KeyRotationOverlap) {
  TempDir dir;
  RegistryDaemon d(dir.path(), {"--key-overlap", "2"});
  Fixture s = setup(d);
  auto [id, secret] = secret_client(d, s);
  std::string t1 = token_of(d, id, secret, s.rrn_a);
  auto jwks = d.get("/.well-known/jwks.json");
  EXPECT_NE(jwks.header("cache-control").find("max-age="), std::string::npos);
  auto keys1 = body_of(jwks).get("keys")->as_array();
  ASSERT_EQ(keys1.size(), 1u);
  EXPECT_EQ(str(keys1[0], "kty"), "OKP");
  EXPECT_EQ(str(keys1[0], "crv"), "Ed25519");
  EXPECT_EQ(str(keys1[0], "alg"), "EdDSA");
  EXPECT_EQ(str(keys1[0], "use"), "sig");
  std::string kid1 = str(keys1[0], "kid");
  EXPECT_EQ(d.send("POST", "/api/v1/authority/keys/rotate", "", s.registrant).status, 403);
  auto rot = d.send("POST", "/api/v1/authority/keys/rotate", "", d.admin_key());
  ASSERT_EQ(rot.status, 201) << rot.body;
  std::string kid2 = str(body_of(rot), "kid");
  auto keys2 = body_of(d.get("/.well-known/jwks.json")).get("keys")->as_array();
  ASSERT_EQ(keys2.size(), 2u);
  // Published but not yet signing.
  auto c2 = verify(d, token_of(d, id, secret, s.rrn_a), s.ruri_a);
  ASSERT_TRUE(c2.ok());
  EXPECT_EQ(c2->kid, kid1);
  std::this_thread::sleep_for(std::chrono::milliseconds(3200));
  auto c3 = verify(d, token_of(d, id, secret, s.rrn_a), s.ruri_a);
  ASSERT_TRUE(c3.ok());
  EXPECT_EQ(c3->kid, kid2);
  auto c1 = verify(d, t1, s.ruri_a);  // the old key stays published
  ASSERT_TRUE(c1.ok()) << c1.error().message;
  EXPECT_EQ(c1->kid, kid1);
  EXPECT_EQ(body_of(form(d, "/oauth/introspect", "token=" + t1,
                         {{"Authorization", "Bearer " + d.admin_key()}}))
                .get("active")
                ->as_bool(),
            true);
}

TEST(RegistryAuthority, DeviceAuthorizationGrant) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  Fixture s = setup(d);
  auto c = d.send("POST", "/api/v1/clients", R"({"name":"rcan-cli","auth":"none"})", d.admin_key());
  std::string client = str(body_of(c), "client_id");
  // A confidential client's id alone starts nothing (docs/THREATS.md T7).
  auto conf = d.send("POST", "/api/v1/clients", R"({"name":"ops"})", d.admin_key());
  auto unauth = form(d, "/oauth/device_authorization",
                     "client_id=" + str(body_of(conf), "client_id") + "&resource=" + s.rrn_a);
  EXPECT_EQ(unauth.status, 401) << unauth.body;
  EXPECT_EQ(oauth_error_of(unauth), "invalid_client");
  // A public client gets no token by client credentials.
  EXPECT_EQ(oauth_error_of(
                form(d, "/oauth/token",
                     "grant_type=client_credentials&client_id=" + client + "&resource=" + s.rrn_a)),
            "invalid_client");
  ASSERT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":"user:)" + s.registrant_id + R"(","robot":")" + s.rrn_a +
                       R"(","role":"owner","scope":["status","config"]})",
                   s.registrant)
                .status,
            201);
  auto start = [&] {
    auto r = form(d, "/oauth/device_authorization",
                  "client_id=" + client + "&resource=" + s.rrn_a + "&scope=status");
    EXPECT_EQ(r.status, 200) << r.body;
    return body_of(r);
  };
  auto da = start();
  std::string code = str(da, "device_code"), user = str(da, "user_code");
  ASSERT_EQ(user.size(), 9u);
  EXPECT_EQ(user[4], '-');
  EXPECT_EQ(num(da, "expires_in"), 600);
  EXPECT_EQ(num(da, "interval"), 5);
  EXPECT_EQ(str(da, "verification_uri"), d.url() + "/device");
  EXPECT_NE(str(da, "verification_uri_complete").find(user), std::string::npos);
  auto poll = [&](const std::string& dc) {
    return form(d, "/oauth/token",
                "grant_type=urn%3Aietf%3Aparams%3Aoauth%3Agrant-type%3Adevice_code&client_id=" +
                    client + "&device_code=" + dc);
  };
  EXPECT_EQ(oauth_error_of(poll(code)), "authorization_pending");
  EXPECT_EQ(oauth_error_of(poll(code)), "slow_down");
  EXPECT_EQ(oauth_error_of(poll("nope")), "invalid_grant");
  // A key without a grant cannot approve.
  auto other =
      d.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"x"})", d.admin_key());
  EXPECT_EQ(
      d.send("POST", "/api/v1/device/approve",
             R"({"user_code":")" + user + R"(","decision":"approve"})", str(body_of(other), "key"))
          .status,
      403);
  std::string lower = user;
  for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  auto ap = d.send("POST", "/api/v1/device/approve",
                   R"({"user_code":")" + lower + R"(","decision":"approve"})", s.registrant);
  ASSERT_EQ(ap.status, 200) << ap.body;
  auto t = poll(code);
  ASSERT_EQ(t.status, 200) << t.body;
  auto claims = verify(d, str(body_of(t), "access_token"), s.ruri_a);
  ASSERT_TRUE(claims.ok()) << claims.error().message;
  EXPECT_EQ(claims->sub, "user:" + s.registrant_id);
  EXPECT_EQ(claims->role, "owner");
  EXPECT_TRUE(claims->has_scope("status"));
  EXPECT_FALSE(claims->has_scope("config"));
  EXPECT_EQ(oauth_error_of(poll(code)), "invalid_grant");  // used once

  auto da2 = start();
  ASSERT_EQ(
      d.send("POST", "/api/v1/device/approve",
             R"({"user_code":")" + str(da2, "user_code") + R"(","decision":"deny"})", s.registrant)
          .status,
      200);
  EXPECT_EQ(oauth_error_of(poll(str(da2, "device_code"))), "access_denied");
  EXPECT_EQ(d.send("POST", "/api/v1/device/approve",
                   R"({"user_code":"AAAA-0000","decision":"approve"})", s.registrant)
                .status,
            400);
}

TEST(RegistryAuthority, TwoInstancesOnOnePostgresDatabase) {
  Postgres pg;
  TempDir a_dir, b_dir;
  RegistryDaemon a(a_dir.path(), {"--database", pg.url(), "--public-url", "https://reg.example"});
  RegistryDaemon b(b_dir.path(), {"--database", pg.url(), "--public-url", "https://reg.example"});
  Fixture s = setup(a);
  auto [id, secret] = secret_client(a, s);
  std::string tok = token_of(a, id, secret, s.rrn_a);
  auto at_b =
      form(b, "/oauth/introspect", "token=" + tok, {{"Authorization", "Bearer " + s.robot_key_a}});
  ASSERT_EQ(at_b.status, 200) << at_b.body;
  EXPECT_EQ(body_of(at_b).get("active")->as_bool(), true);
  EXPECT_EQ(str(body_of(at_b), "iss"), "https://reg.example");
  EXPECT_EQ(a.get("/.well-known/jwks.json").body, b.get("/.well-known/jwks.json").body);
  auto rv = b.send("POST", "/api/v1/revocations", R"({"token":")" + tok + R"("})", a.admin_key());
  ASSERT_EQ(rv.status, 201) << rv.body;
  auto feed = body_of(a.get("/api/v1/revocations?since=0"));
  ASSERT_EQ(feed.get("revocations")->as_array().size(), 1u);
  EXPECT_EQ(body_of(form(a, "/oauth/introspect", "token=" + tok,
                         {{"Authorization", "Bearer " + a.admin_key()}}))
                .get("active")
                ->as_bool(),
            false);
  // A key rotated at B is published by A.
  ASSERT_EQ(b.send("POST", "/api/v1/authority/keys/rotate", "", a.admin_key()).status, 201);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  EXPECT_EQ(body_of(a.get("/.well-known/jwks.json")).get("keys")->as_array().size(), 2u);
}

TEST(RegistryAuthority, DeviceCodeExpires) {
  TempDir dir;
  RegistryDaemon d(dir.path(), {"--device-code-ttl", "1"});
  Fixture s = setup(d);
  auto c = d.send("POST", "/api/v1/clients", R"({"name":"cli","auth":"none"})", d.admin_key());
  std::string client = str(body_of(c), "client_id");
  auto r = form(d, "/oauth/device_authorization", "client_id=" + client + "&resource=" + s.rrn_a);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(num(body_of(r), "expires_in"), 1);
  std::string code = str(body_of(r), "device_code"), user = str(body_of(r), "user_code");
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));
  EXPECT_EQ(d.send("POST", "/api/v1/device/approve",
                   R"({"user_code":")" + user + R"(","decision":"approve"})", s.registrant)
                .status,
            404);
  auto p =
      form(d, "/oauth/token",
           "grant_type=urn%3Aietf%3Aparams%3Aoauth%3Agrant-type%3Adevice_code&client_id=" + client +
               "&device_code=" + code);
  EXPECT_EQ(oauth_error_of(p), "expired_token");
  EXPECT_EQ(
      oauth_error_of(form(d, "/oauth/device_authorization", "client_id=nope&resource=" + s.rrn_a)),
      "invalid_client");
}

TEST(RegistryAuthority, FleetGrantGivesTheFleetForm) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  Fixture s = setup(d);
  auto c = d.send("POST", "/api/v1/clients", R"({"name":"yard-ops"})", s.registrant);
  std::string id = str(body_of(c), "client_id"), secret = str(body_of(c), "client_secret");
  auto g = d.send("POST", "/api/v1/grants",
                  R"({"principal":")" + id + R"(","fleet":"yard","robots":[")" + s.rrn_a +
                      R"(",")" + s.rrn_b + R"("],"role":"user","scope":["status"]})",
                  s.registrant);
  ASSERT_EQ(g.status, 201) << g.body;
  EXPECT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":")" + id + R"(","fleet":"yard","role":"user"})", s.registrant)
                .status,
            400);  // a fleet grant lists its robots
  auto r = form(d, "/oauth/token",
                "grant_type=client_credentials&client_id=" + id + "&client_secret=" + secret +
                    "&resource=fleet%3Ayard");
  ASSERT_EQ(r.status, 200) << r.body;
  std::string tok = str(body_of(r), "access_token");
  auto jwks = jwt::parse_jwk_set(d.get("/.well-known/jwks.json").body);
  ASSERT_TRUE(jwks.ok());
  auto check = [&](const std::string& fleet_id) {
    jwt::TrustStore ts;
    for (auto& k : *jwks) ts.add(d.url(), k);
    jwt::VerifyOptions vo;
    vo.audience = s.ruri_a;
    vo.fleet_ids = {fleet_id};
    vo.fleet_audiences = {"rcan://fleet/yard"};
    return jwt::JwtVerifier(std::move(ts), vo).verify(tok);
  };
  auto ok = check(s.rrn_a);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  ASSERT_TRUE(ok->fleet.has_value());
  EXPECT_EQ(ok->fleet->size(), 2u);
  EXPECT_FALSE(check("RRN-000000009999").ok());  // not a member
  EXPECT_FALSE(verify(d, tok, s.ruri_a).ok());   // a robot not in fleet "yard"
  EXPECT_EQ(oauth_error_of(form(d, "/oauth/token",
                                "grant_type=client_credentials&client_id=" + id +
                                    "&client_secret=" + secret + "&resource=fleet%3Aother")),
            "unauthorized_client");
}

TEST(RegistryAuthority, CliTokenGetAndLogin) {
  TempDir dir;
  RegistryDaemon d(dir.path());
  Fixture s = setup(d);
  auto [id, secret] = secret_client(d, s);
  std::string secret_file = dir.file("client.secret");
  ASSERT_TRUE(write_file(secret_file, secret + "\n"));
  auto r = run_cli({"token", "get", "--registry", d.url(), "--client-id", id,
                    "--client-secret-file", secret_file, "--robot", s.rrn_a, "--scope", "status"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::string tok = r.out.substr(0, r.out.find('\n'));
  auto c = verify(d, tok, s.ruri_a);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_TRUE(c->has_scope("status"));
  r = run_cli({"token", "get", "--registry", d.url(), "--client-id", id, "--client-secret-file",
               secret_file, "--robot", s.rrn_b});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("unauthorized_client"), std::string::npos) << r.err;

  // private_key_jwt with a key directory's seed
  Bytes seed = ed25519::random_seed();
  auto pub = ed25519::public_key_from_seed(seed);
  ASSERT_TRUE(pub.ok());
  std::string seed_file = dir.file("ed25519.seed");
  ASSERT_TRUE(write_file(seed_file, std::string(seed.begin(), seed.end())));
  ::chmod(seed_file.c_str(), 0600);
  auto cl =
      d.send("POST", "/api/v1/clients",
             R"({"name":"k","auth":"private_key_jwt","jwk":{"kty":"OKP","crv":"Ed25519","x":")" +
                 base64url_encode(*pub) + R"("}})",
             s.registrant);
  std::string kid_client = str(body_of(cl), "client_id");
  ASSERT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":")" + kid_client + R"(","robot":")" + s.rrn_a +
                       R"(","role":"guest","scope":["status"]})",
                   s.registrant)
                .status,
            201);
  std::string saved = dir.file("token.jwt");
  r = run_cli({"token", "get", "--registry", d.url(), "--client-id", kid_client, "--client-key",
               dir.path(), "--robot", s.ruri_a, "--save", saved});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  struct stat st {};
  ASSERT_EQ(::stat(saved.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);

  // rcan login: the device flow, approved by the registrant
  auto c2 = d.send("POST", "/api/v1/clients", R"({"name":"cli","auth":"none"})", d.admin_key());
  std::string cli_client = str(body_of(c2), "client_id");
  ASSERT_EQ(d.send("POST", "/api/v1/grants",
                   R"({"principal":"user:)" + s.registrant_id + R"(","robot":")" + s.rrn_a +
                       R"(","role":"user","scope":["status"]})",
                   s.registrant)
                .status,
            201);
  std::string login_file = dir.file("login.jwt");
  Process p;
  ASSERT_TRUE(p.start({RCAN_CLI_PATH, "login", "--registry", d.url(), "--client-id", cli_client,
                       "--resource", s.rrn_a, "--save", login_file}));
  auto line = p.wait_for_line("enter the code", 10000);
  ASSERT_TRUE(line.has_value()) << p.err();
  std::string code = line->substr(line->find("enter the code ") + 15, 9);
  // The verification page the person opens says how to decide, with the code; it reflects
  // nothing else and runs no script.
  auto page = d.send("GET", "/device?user_code=" + code, "", "");
  ASSERT_EQ(page.status, 200) << page.body;
  EXPECT_NE(page.body.find("rcan registry device approve " + code), std::string::npos) << page.body;
  auto hostile = d.send("GET", "/device?user_code=%3Cscript%3Ealert(1)%3C/script%3E", "", "");
  ASSERT_EQ(hostile.status, 200);
  EXPECT_EQ(hostile.body.find("<script"), std::string::npos) << hostile.body;
  EXPECT_EQ(hostile.body.find("alert"), std::string::npos) << hostile.body;
  // The registrant approves at a CLI of their own with their key.
  const std::string key_file = dir.file("registrant.key");
  ASSERT_TRUE(write_file(key_file, s.registrant + "\n"));
  ::chmod(key_file.c_str(), 0600);
  // They see what they approve: the client, who made it, the robot and what their grant gives.
  auto shown =
      run_cli({"registry", "device", "show", code, "--registry", d.url(), "--key-file", key_file});
  ASSERT_EQ(shown.exit_code, 0) << shown.out << shown.err;
  EXPECT_NE(shown.out.find(cli_client), std::string::npos) << shown.out;
  EXPECT_NE(shown.out.find(s.rrn_a), std::string::npos) << shown.out;
  EXPECT_NE(shown.out.find("\"role\":\"user\""), std::string::npos) << shown.out;
  auto ap = run_cli({"registry", "device", "approve", code, "--yes", "--registry", d.url(),
                     "--key-file", key_file});
  ASSERT_EQ(ap.exit_code, 0) << ap.out << ap.err;
  EXPECT_NE(ap.err.find("client      cli (" + cli_client), std::string::npos) << ap.err;
  // Decided once: a second decision on the same code is not found (exit 1).
  EXPECT_EQ(
      run_cli({"registry", "device", "deny", code, "--registry", d.url(), "--key-file", key_file})
          .exit_code,
      1);
  EXPECT_EQ(run_cli({"registry", "device", "maybe", code}).exit_code, 2);
  ASSERT_TRUE(p.wait_for_line("token saved", 20000).has_value()) << p.err();
  auto lt = read_file(login_file);
  auto lc = verify(d, lt.substr(0, lt.find('\n')), s.ruri_a);
  ASSERT_TRUE(lc.ok()) << lc.error().message;
  EXPECT_EQ(lc->sub, "user:" + s.registrant_id);
}

}  // namespace
}  // namespace rcan::test
