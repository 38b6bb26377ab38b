// JWT verification and issuing: fixtures made independently by tests/data/jwt/make_fixtures.py
// (pyca/cryptography), plus tokens built here to pin every rejection rule.
#include "rcan/crypto/jwt.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>

#include "test_support.h"

namespace rcan::jwt {
namespace {

const std::string kData = std::string(RCAN_TESTDATA_DIR) + "/jwt/";
constexpr int64_t kNow = 1767225600;
const std::string kIss = "https://auth.example.org";
const std::string kRobot = "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6";
const std::string kAud = "rcan://continuon.cloud/continuon/companion-v1/*";

std::string data(const std::string& name) { return test::read_file(kData + name); }

// Copies a fixture into a temp dir with mode 0600 (git does not keep 0600).
std::string private_copy(const test::TempDir& dir, const std::string& name, unsigned mode = 0600) {
  std::string path = dir.file(name);
  std::ofstream(path, std::ios::binary) << data(name);
  chmod(path.c_str(), mode);
  return path;
}

VerificationKey vkey_pem(const std::string& name) {
  auto k = VerificationKey::from_pem(data(name));
  EXPECT_TRUE(k.ok()) << name << ": " << (k.ok() ? "" : k.error().message);
  return std::move(k).value();
}

SigningKey skey_pem(const std::string& name) {
  auto k = SigningKey::from_pem(data(name));
  EXPECT_TRUE(k.ok()) << name << ": " << (k.ok() ? "" : k.error().message);
  return std::move(k).value();
}

Bytes secret_bytes() {
  std::string s = data("hs256.secret");
  return Bytes(s.begin(), s.end());
}

TrustStore full_store() {
  TrustStore ts;
  ts.add(kIss, vkey_pem("ed25519_pub.pem"), "ed-1");
  ts.add(kIss, vkey_pem("p256_pub.pem"), "ec-1");
  ts.add(kIss, vkey_pem("rsa2048_pub.pem"), "rsa-1");
  auto hs = VerificationKey::hs256_secret(secret_bytes());
  EXPECT_TRUE(hs.ok());
  ts.add(kIss, std::move(hs).value());
  return ts;
}

VerifyOptions robot_opts() {
  VerifyOptions o;
  o.audience = kRobot;
  o.fleet_ids = {"d3a4b5c6"};
  return o;
}

json::Object base_claims() {
  json::Object c;
  c.set("iss", kIss);
  c.set("sub", "user-1");
  c.set("aud", kAud);
  c.set("role", "owner");
  c.set("scope", json::Array{"control", "config"});
  c.set("iat", int64_t{kNow - 10});
  c.set("exp", int64_t{kNow + 3600});
  return c;
}

std::string b64(std::string_view s) {
  return base64url_encode(reinterpret_cast<const uint8_t*>(s.data()), s.size(), false);
}

// A token with an arbitrary header and claims text, signed by `key`.
std::string raw_token(const std::string& header_json, const std::string& claims_json,
                      const SigningKey& key) {
  std::string input = b64(header_json) + "." + b64(claims_json);
  auto sig = key.sign(input);
  EXPECT_TRUE(sig.ok());
  return input + "." + base64url_encode(*sig, false);
}

std::string ed_token(const json::Object& claims) {
  auto key = skey_pem("ed25519_priv.pem");
  auto t = issue(claims, key, "ed-1");
  EXPECT_TRUE(t.ok());
  return *t;
}

Result<Claims> check(const std::string& token, VerifyOptions opts = robot_opts()) {
  JwtVerifier v(full_store(), std::move(opts));
  return v.verify(token, kNow);
}

void expect_rejected(const Result<Claims>& r, const std::string& reason,
                     ErrorCode code = ErrorCode::kAuthInvalid) {
  ASSERT_FALSE(r.ok()) << "expected rejection (" << reason << ")";
  EXPECT_EQ(r.error().code, code) << r.error().message;
  if (!reason.empty()) {
    EXPECT_EQ(r.error().reason, reason) << r.error().message;
  }
  EXPECT_FALSE(r.error().message.empty());
}

// ---------------------------------------------------------------------------------------

TEST(Jwt, PythonMadeFixturesVerifyOrFailAsExpected) {
  auto doc = json::parse(data("tokens.json"));
  ASSERT_TRUE(doc.ok());
  const auto& cases = doc->get("cases")->as_array();
  ASSERT_EQ(cases.size(), 14u);
  for (const auto& c : cases) {
    SCOPED_TRACE(c.get("name")->as_string());
    auto r = check(c.get("token")->as_string());
    if (c.get("valid")->as_bool()) {
      ASSERT_TRUE(r.ok()) << r.error().message;
      EXPECT_EQ(r->iss, kIss);
      EXPECT_EQ(r->sub, "user-7f3c");
      if (const auto* role = c.get("role")) {
        EXPECT_EQ(r->role, role->as_string());
      }
      if (const auto* sc = c.get("scopes")) {
        std::vector<std::string> want;
        for (const auto& s : sc->as_array()) want.push_back(s.as_string());
        EXPECT_EQ(r->scopes, want);
      }
    } else {
      expect_rejected(r, c.get("reason")->as_string());
    }
  }
}

TEST(Jwt, EachAlgorithmVerifiesWithPemJwkAndJwks) {
  auto doc = json::parse(data("tokens.json"));
  ASSERT_TRUE(doc.ok());
  auto jwks = parse_jwk_set(data("jwks.json"));
  ASSERT_TRUE(jwks.ok()) << jwks.error().message;
  ASSERT_EQ(jwks->size(), 3u);
  TrustStore from_jwks;
  for (auto& k : *jwks) from_jwks.add(kIss, k);
  for (const char* alg : {"EdDSA", "ES256", "RS256"}) {
    SCOPED_TRACE(alg);
    std::string tok;
    for (const auto& c : doc->get("cases")->as_array())
      if (c.get("name")->as_string() == std::string("valid_") + alg)
        tok = c.get("token")->as_string();
    JwtVerifier v(from_jwks, robot_opts());
    auto r = v.verify(tok, kNow);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->role, "owner");
    EXPECT_EQ(r->role_level, 4);
    EXPECT_EQ(r->scopes, (std::vector<std::string>{"control", "config", "training"}));
    ASSERT_TRUE(r->fleet.has_value());
  }
  // Single JWK files too.
  for (const char* f : {"ed25519_pub.jwk", "p256_pub.jwk", "rsa2048_pub.jwk"}) {
    auto ks = parse_jwk_set(data(f));
    ASSERT_TRUE(ks.ok()) << f;
    EXPECT_FALSE((*ks)[0].kid().empty());
  }
}

TEST(Jwt, IssueThenVerifyRoundTripsForEveryAlgorithm) {
  for (const char* pem : {"ed25519_priv.pem", "p256_priv.pem", "rsa2048_priv.pem"}) {
    SCOPED_TRACE(pem);
    auto key = skey_pem(pem);
    auto tok = issue(base_claims(), key);
    ASSERT_TRUE(tok.ok());
    auto r = check(*tok);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->role, "owner");
  }
  auto hs = SigningKey::hs256_secret(secret_bytes());
  ASSERT_TRUE(hs.ok());
  auto tok = issue(base_claims(), *hs);
  ASSERT_TRUE(tok.ok());
  EXPECT_TRUE(check(*tok).ok());
}

TEST(Jwt, SigningKeyFromFileRefusesWorldReadableKeysAndAcceptsRawSeed) {
  test::TempDir dir;
  EXPECT_TRUE(SigningKey::from_file(private_copy(dir, "p256_priv.pem")).ok());
  auto loose = SigningKey::from_file(private_copy(dir, "rsa2048_priv.pem", 0644));
  ASSERT_FALSE(loose.ok());
  EXPECT_NE(loose.error().message.find("group/world"), std::string::npos);
  // A raw 32-byte ed25519.seed: same key as ed25519_priv.pem (seed 00..1f).
  std::string seed_path = dir.file("ed25519.seed");
  std::string seed;
  for (int i = 0; i < 32; ++i) seed.push_back(static_cast<char>(i));
  std::ofstream(seed_path, std::ios::binary) << seed;
  chmod(seed_path.c_str(), 0600);
  auto k = SigningKey::from_file(seed_path);
  ASSERT_TRUE(k.ok()) << k.error().message;
  EXPECT_EQ(k->alg(), Alg::kEdDSA);
  auto tok = issue(base_claims(), *k, "ed-1");
  ASSERT_TRUE(tok.ok());
  EXPECT_TRUE(check(*tok).ok());
}

TEST(Jwt, AlgNoneIsRejectedInEverySpelling) {
  for (const char* alg : {"none", "None", "NONE", "nOnE"}) {
    std::string t = b64(std::string("{\"alg\":\"") + alg + "\"}") + "." +
                    b64(json::dump(json::Value(base_claims()))) + ".";
    expect_rejected(check(t), "alg_none");
  }
}

TEST(Jwt, UnsupportedAlgorithmsAreRejected) {
  auto key = skey_pem("ed25519_priv.pem");
  std::string claims = json::dump(json::Value(base_claims()));
  for (const char* alg : {"HS512", "RS512", "PS256", "ES384", "eddsa", "", "Ed25519"}) {
    expect_rejected(check(raw_token(std::string("{\"alg\":\"") + alg + "\"}", claims, key)),
                    "bad_alg");
  }
  expect_rejected(check(raw_token("{\"alg\":7}", claims, key)), "malformed");
  expect_rejected(check(raw_token("{\"typ\":\"JWT\"}", claims, key)), "malformed");
}

TEST(Jwt, AlgorithmConfusionIsRefused) {
  // HS256 token whose HMAC key is the RSA public key PEM: the issuer's RS256 key never
  // verifies an HMAC.
  std::string pem = data("rsa2048_pub.pem");
  auto hs_pem = SigningKey::hs256_secret(Bytes(pem.begin(), pem.end()));
  ASSERT_TRUE(hs_pem.ok());
  TrustStore rsa_only;
  rsa_only.add(kIss, vkey_pem("rsa2048_pub.pem"));
  JwtVerifier v(rsa_only, robot_opts());
  auto tok = issue(base_claims(), *hs_pem);
  ASSERT_TRUE(tok.ok());
  expect_rejected(v.verify(*tok, kNow), "alg_mismatch");
  // And an EdDSA token against an issuer that only has an HS256 secret.
  TrustStore hs_only;
  hs_only.add(kIss, *VerificationKey::hs256_secret(secret_bytes()));
  JwtVerifier v2(hs_only, robot_opts());
  expect_rejected(v2.verify(ed_token(base_claims()), kNow), "alg_mismatch");
  // ES256 token relabelled as EdDSA (same key bytes cannot cross algorithms).
  auto es = issue(base_claims(), skey_pem("p256_priv.pem"));
  ASSERT_TRUE(es.ok());
  std::string body = es->substr(es->find('.'));
  expect_rejected(check(b64("{\"alg\":\"EdDSA\"}") + body), "bad_signature");
}

TEST(Jwt, HmacSecretsMustBeConfiguredExplicitlyAndLongEnough) {
  EXPECT_FALSE(VerificationKey::hs256_secret(Bytes(31, 'k')).ok());
  EXPECT_TRUE(VerificationKey::hs256_secret(Bytes(32, 'k')).ok());
  EXPECT_FALSE(SigningKey::hs256_secret(Bytes(16, 'k')).ok());
  // An oct JWK is refused unless the caller asks for a secret.
  auto oct = json::parse(R"({"kty":"oct","k":")" + base64url_encode(Bytes(32, 'k')) + R"("})");
  ASSERT_TRUE(oct.ok());
  auto refused = VerificationKey::from_jwk(*oct);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("shared secret"), std::string::npos);
  EXPECT_TRUE(VerificationKey::from_jwk(*oct, true).ok());
  // Secret files: mode 0600 required; one trailing newline is not part of the secret.
  test::TempDir dir;
  std::string p = dir.file("s");
  std::ofstream(p) << data("hs256.secret") << "\n";
  chmod(p.c_str(), 0640);
  EXPECT_FALSE(load_verification_keys(p, true).ok());
  chmod(p.c_str(), 0600);
  auto ks = load_verification_keys(p, true);
  ASSERT_TRUE(ks.ok()) << ks.error().message;
  auto hs = SigningKey::hs256_secret(secret_bytes());
  auto tok = issue(base_claims(), *hs);
  ASSERT_TRUE((*ks)[0].verify(tok->substr(0, tok->rfind('.')),
                              *base64url_decode(tok->substr(tok->rfind('.') + 1))));
}

TEST(Jwt, MalformedTokensAreRejectedNotCrashed) {
  std::string good = ed_token(base_claims());
  size_t d1 = good.find('.'), d2 = good.rfind('.');
  std::string h = good.substr(0, d1), p = good.substr(d1 + 1, d2 - d1 - 1), s = good.substr(d2 + 1);
  struct Case {
    std::string token;
    std::string reason;
  };
  std::vector<Case> cases = {
      {h + "." + p, "malformed"},
      {h + "." + p + "." + s + ".x", "malformed"},
      {"." + p + "." + s, "malformed"},
      {h + ".." + s, "malformed"},
      {h + "=." + p + "." + s, "malformed"},
      {h + "." + p + "." + s + "=", "malformed"},
      {h + "." + p + "+" + "." + s, "malformed"},
      {h + "." + p + "." + s.substr(0, s.size() - 1) + "+", "malformed"},
      {h + " ." + p + "." + s, "malformed"},
      {b64("[1,2]") + "." + p + "." + s, "malformed"},
      {b64("{\"alg\":\"EdDSA\"") + "." + p + "." + s, "malformed"},
      {h + "." + b64("\"str\"") + "." + s, "malformed"},
      {h + "." + b64("{\"a\":1,\"a\":2}") + "." + s, "malformed"},
      {h + "." + b64("{\"bad\":\"\xff\"}") + "." + s, "malformed"},
      {h + "." + p + "." + "A", "malformed"},
      {"abc", "malformed"},
      {std::string(9000, 'a'), "oversize"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.token.substr(0, 80));
    expect_rejected(check(c.token), c.reason);
  }
  expect_rejected(check(""), "", ErrorCode::kAuthRequired);
  // A flipped signature bit.
  std::string bad_sig = good;
  bad_sig[bad_sig.size() - 5] = bad_sig[bad_sig.size() - 5] == 'A' ? 'B' : 'A';
  expect_rejected(check(bad_sig), "bad_signature");
  // Signatures of the wrong length for the algorithm.
  expect_rejected(check(h + "." + p + "." + base64url_encode(Bytes(63, 1))), "bad_signature");
  expect_rejected(check(h + "." + p), "malformed");
}

TEST(Jwt, Es256RejectsOutOfRangeAndDerSignatures) {
  auto key = skey_pem("p256_priv.pem");
  auto tok = issue(base_claims(), key, "ec-1");
  ASSERT_TRUE(tok.ok());
  std::string input = tok->substr(0, tok->rfind('.'));
  auto raw = *base64url_decode(tok->substr(tok->rfind('.') + 1));
  ASSERT_EQ(raw.size(), 64u);
  EXPECT_TRUE(check(*tok).ok());
  Bytes zero(64, 0);
  expect_rejected(check(input + "." + base64url_encode(zero)), "bad_signature");
  Bytes ff(64, 0xff);  // r, s ≥ n
  expect_rejected(check(input + "." + base64url_encode(ff)), "bad_signature");
  Bytes longer = raw;
  longer.push_back(0);
  expect_rejected(check(input + "." + base64url_encode(longer)), "bad_signature");
}

TEST(Jwt, CritHeaderIsRefused) {
  auto key = skey_pem("ed25519_priv.pem");
  expect_rejected(check(raw_token(R"({"alg":"EdDSA","crit":["b64"],"b64":false})",
                                  json::dump(json::Value(base_claims())), key)),
                  "crit");
}

TEST(Jwt, TimeClaimsHonourLeeway) {
  auto at = [&](const char* name, int64_t v, VerifyOptions o = robot_opts()) {
    auto c = base_claims();
    c.set(name, v);
    return check(ed_token(c), o);
  };
  EXPECT_TRUE(at("exp", kNow + 1).ok());
  EXPECT_TRUE(at("exp", kNow - 59).ok());  // within the 60 s leeway
  expect_rejected(at("exp", kNow - 60), "expired");
  VerifyOptions strict = robot_opts();
  strict.leeway_s = 0;
  expect_rejected(at("exp", kNow, strict), "expired");
  EXPECT_TRUE(at("nbf", kNow + 60).ok());
  expect_rejected(at("nbf", kNow + 61), "not_yet_valid");
  expect_rejected(at("iat", kNow + 61), "iat_in_future");
  EXPECT_TRUE(at("iat", kNow + 30).ok());

  auto c = base_claims();
  c.erase("exp");
  expect_rejected(check(ed_token(c)), "missing_claim");
  c = base_claims();
  c.set("exp", "4102444800");
  expect_rejected(check(ed_token(c)), "malformed");
  c = base_claims();
  c.set("exp", 1e300);
  expect_rejected(check(ed_token(c)), "malformed");
  c = base_claims();
  c.set("exp", static_cast<double>(kNow) + 100.5);  // fractional NumericDate is fine
  EXPECT_TRUE(check(ed_token(c)).ok());
  c = base_claims();
  c.erase("iat");
  EXPECT_TRUE(check(ed_token(c)).ok());
  VerifyOptions need_iat = robot_opts();
  need_iat.require_iat = true;
  expect_rejected(check(ed_token(c), need_iat), "missing_claim");
}

TEST(Jwt, AudienceMustMatchTheRobotRuri) {
  auto with_aud = [&](json::Value aud) {
    auto c = base_claims();
    c.set("aud", std::move(aud));
    return check(ed_token(c));
  };
  EXPECT_TRUE(with_aud(kRobot).ok());
  EXPECT_TRUE(with_aud("rcan://continuon.cloud/*/*/d3a4b5c6").ok());
  EXPECT_TRUE(with_aud(json::Array{"rcan://x.example/a/b/*", kAud}).ok());
  expect_rejected(with_aud("rcan://continuon.cloud/continuon/companion-v1/00000000"),
                  "aud_mismatch");
  expect_rejected(with_aud("rcan://continuon.cloud/continuon/*"), "aud_mismatch");
  expect_rejected(with_aud("*"), "aud_mismatch");
  expect_rejected(with_aud(json::Array{}), "malformed");
  expect_rejected(with_aud(json::Array{kAud, 5}), "malformed");
  expect_rejected(with_aud(json::Value(7)), "malformed");
  auto c = base_claims();
  c.erase("aud");
  expect_rejected(check(ed_token(c)), "missing_claim");
  VerifyOptions no_aud = robot_opts();
  no_aud.audience.clear();
  expect_rejected(check(ed_token(base_claims()), no_aud), "aud_mismatch");
}

TEST(Jwt, RolesFromRoleOrRcanRole) {
  auto role = [&](const char* claim, json::Value v) {
    auto c = base_claims();
    c.erase("role");
    c.set(claim, std::move(v));
    return check(ed_token(c));
  };
  struct Named {
    const char* name;
    int level;
  };
  for (auto [name, level] : {Named{"creator", 5}, Named{"owner", 4}, Named{"leasee", 3},
                             Named{"user", 2}, Named{"guest", 1}}) {
    auto r = role("role", name);
    ASSERT_TRUE(r.ok()) << name;
    EXPECT_EQ(r->role_level, level);
    EXPECT_EQ(r->role, name);
  }
  expect_rejected(role("role", "admin"), "bad_role");
  expect_rejected(role("role", "superuser"), "bad_role");
  expect_rejected(role("role", json::Value(4)), "bad_role");
  struct Num {
    json::Value v;
    int level;
  };
  for (const auto& [v, level] : std::vector<Num>{{json::Value(1), 1},
                                                 {json::Value(2), 2},
                                                 {json::Value(2.5), 2},
                                                 {json::Value(2.0), 2},
                                                 {json::Value(3), 4},
                                                 {json::Value(5), 5}}) {
    auto r = role("rcan_role", v);
    ASSERT_TRUE(r.ok()) << json::dump(v);
    EXPECT_EQ(r->role_level, level) << json::dump(v);
  }
  for (const auto& v : {json::Value(0), json::Value(4), json::Value(6), json::Value(2.4),
                        json::Value("m2m_trusted"), json::Value("3"), json::Value(true)})
    expect_rejected(role("rcan_role", v), "bad_role");
  // Both present: must agree.
  auto c = base_claims();
  c.set("rcan_role", 3);
  EXPECT_TRUE(check(ed_token(c)).ok());
  c.set("rcan_role", 5);
  expect_rejected(check(ed_token(c)), "bad_role");
  // Absent: rejected unless the verifier allows a GUEST default.
  c = base_claims();
  c.erase("role");
  expect_rejected(check(ed_token(c)), "missing_claim");
  VerifyOptions lax = robot_opts();
  lax.require_role = false;
  auto g = check(ed_token(c), lax);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->role, "guest");
}

TEST(Jwt, ScopesFromEveryClaimForm) {
  auto c = base_claims();
  c.set("scope", "status  chat");
  c.set("scopes", json::Array{"control", "status"});
  c.set("rcan_scopes", json::Array{"config"});
  auto r = check(ed_token(c));
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->scopes, (std::vector<std::string>{"status", "chat", "control", "config"}));
  c.set("scopes", json::Array{"control", json::Value(1)});
  expect_rejected(check(ed_token(c)), "malformed");
  c = base_claims();
  c.set("scope", json::Object{{"a", 1}});
  expect_rejected(check(ed_token(c)), "malformed");
}

TEST(Jwt, RequiredScopeNeedsScopeAndRole) {
  VerifyOptions o = robot_opts();
  o.required_scope = "config";
  EXPECT_TRUE(check(ed_token(base_claims()), o).ok());
  auto c = base_claims();
  c.set("role", "user");
  auto r = check(ed_token(c), o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kInsufficientPrivileges);
  o.required_scope = "admin";
  r = check(ed_token(base_claims()), o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kInsufficientPrivileges);
}

TEST(Jwt, FleetMustContainThisDevice) {
  auto c = base_claims();
  c.set("fleet", json::Array{"robot-001", "d3a4b5c6"});
  EXPECT_TRUE(check(ed_token(c)).ok());
  c.set("fleet", json::Array{"robot-001"});
  expect_rejected(check(ed_token(c)), "fleet_mismatch");
  c.set("fleet", json::Array{});
  expect_rejected(check(ed_token(c)), "fleet_mismatch");
  c.set("fleet", "d3a4b5c6");
  expect_rejected(check(ed_token(c)), "malformed");
  c.set("fleet", json::Array{"d3a4b5c6"});
  VerifyOptions no_ids = robot_opts();
  no_ids.fleet_ids.clear();
  expect_rejected(check(ed_token(c), no_ids), "fleet_mismatch");
}

TEST(Jwt, SenderTypeRulesOfSection8_5) {
  auto c = base_claims();
  c.set("sender_type", "cloud_function");
  auto r = check(ed_token(c));
  expect_rejected(r, "missing_cloud_provider");
  c.set("cloud_provider", "");
  expect_rejected(check(ed_token(c)), "missing_cloud_provider");
  c.set("cloud_provider", "firebase");
  c.set("function_name", "castor-bridge-v2");
  r = check(ed_token(c));
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->sender_type, "cloud_function");
  EXPECT_EQ(r->cloud_provider, "firebase");
  EXPECT_EQ(r->function_name, "castor-bridge-v2");
  c.set("sender_type", "service");
  expect_rejected(check(ed_token(c)), "bad_sender_type");
  c.set("sender_type", json::Value(1));
  expect_rejected(check(ed_token(c)), "malformed");
  for (const char* st : {"human", "robot", "system"}) {
    auto c2 = base_claims();
    c2.set("sender_type", st);
    EXPECT_TRUE(check(ed_token(c2)).ok()) << st;
  }
}

TEST(Jwt, IssuerAndKidSelectTheKey) {
  auto c = base_claims();
  c.erase("iss");
  expect_rejected(check(ed_token(c)), "missing_claim");
  c.set("iss", "someone-else");
  expect_rejected(check(ed_token(c)), "untrusted_issuer");
  c.set("iss", json::Value(5));
  expect_rejected(check(ed_token(c)), "missing_claim");
  // Two Ed25519 keys under one issuer: the kid picks one.
  auto other = SigningKey::ed25519_seed(Bytes(32, 9));
  ASSERT_TRUE(other.ok());
  TrustStore ts;
  ts.add(kIss, vkey_pem("ed25519_pub.pem"), "ed-1");
  ts.add(kIss, *other->verification_key(), "ed-2");
  JwtVerifier v(ts, robot_opts());
  auto t2 = issue(base_claims(), *other, "ed-2");
  EXPECT_TRUE(v.verify(*t2, kNow).ok());
  auto t2_wrong_kid = issue(base_claims(), *other, "ed-1");
  expect_rejected(v.verify(*t2_wrong_kid, kNow), "bad_signature");
  auto t_unknown = issue(base_claims(), *other, "ed-9");
  expect_rejected(v.verify(*t_unknown, kNow), "unknown_kid");
  auto t_nokid = issue(base_claims(), *other);
  EXPECT_TRUE(v.verify(*t_nokid, kNow).ok());
}

TEST(Jwt, KeyLoadingRefusesWeakWrongOrPrivateKeys) {
  auto small = VerificationKey::from_pem(data("rsa1024_pub.pem"));
  ASSERT_FALSE(small.ok());
  EXPECT_NE(small.error().message.find("2048"), std::string::npos);
  auto p384 = VerificationKey::from_pem(data("p384_pub.pem"));
  ASSERT_FALSE(p384.ok());
  EXPECT_NE(p384.error().message.find("P-256"), std::string::npos);
  EXPECT_FALSE(VerificationKey::from_pem(data("rsa2048_priv.pem")).ok());
  EXPECT_FALSE(
      VerificationKey::from_pem("-----BEGIN PUBLIC KEY-----\nAAAA\n-----END PUBLIC KEY-----\n")
          .ok());
  EXPECT_FALSE(VerificationKey::from_pem("").ok());
  test::TempDir dir;
  EXPECT_FALSE(load_verification_keys(private_copy(dir, "p256_priv.pem")).ok());
  // JWKs with problems.
  for (
      const char* bad : {
          R"({"kty":"OKP","crv":"Ed25519"})",
          R"({"kty":"OKP","crv":"Ed448","x":"AAAA"})",
          R"({"kty":"OKP","crv":"Ed25519","x":"AAAA"})",
          R"({"kty":"EC","crv":"P-256","x":"AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA","y":"AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA"})",
          R"({"kty":"EC","crv":"P-384","x":"AA","y":"AA"})",
          R"({"kty":"RSA","n":"AQAB","e":"AQAB"})",
          R"({"kty":"XYZ"})",
          R"({"kty":5})",
          R"([])",
          R"({"keys":[]})",
          R"({"keys":"x"})",
          R"(not json)",
      }) {
    SCOPED_TRACE(bad);
    auto r = parse_jwk_set(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_FALSE(r.error().message.empty());
  }
  // alg/use disagreement and private members.
  auto jwk = json::parse(data("ed25519_pub.jwk"));
  ASSERT_TRUE(jwk.ok());
  json::Value k = *jwk;
  k.as_object().set("alg", "ES256");
  EXPECT_FALSE(VerificationKey::from_jwk(k).ok());
  k = *jwk;
  k.as_object().set("use", "enc");
  EXPECT_FALSE(VerificationKey::from_jwk(k).ok());
  k = *jwk;
  k.as_object().set("d", "AAAA");
  EXPECT_FALSE(VerificationKey::from_jwk(k).ok());
}

TEST(Jwt, TrustStoreFromConfig) {
  test::TempDir dir;
  std::vector<TrustStore::IssuerConfig> cfg = {
      {kIss, kData + "jwks.json", "auto", ""},
      {kIss, private_copy(dir, "hs256.secret"), "hs256_secret", ""},
  };
  auto ts = TrustStore::from_config(cfg);
  ASSERT_TRUE(ts.ok()) << ts.error().message;
  auto doc = json::parse(data("tokens.json"));
  JwtVerifier v(*ts, robot_opts());
  for (const auto& c : doc->get("cases")->as_array()) {
    if (c.get("name")->as_string().rfind("valid_", 0) == 0) {
      EXPECT_TRUE(v.verify(c.get("token")->as_string(), kNow).ok()) << c.get("name")->as_string();
    }
  }
  cfg[1].kind = "password";
  EXPECT_FALSE(TrustStore::from_config(cfg).ok());
  cfg = {{kIss, kData + "missing.pem", "auto", ""}};
  EXPECT_FALSE(TrustStore::from_config(cfg).ok());
  cfg = {{"", kData + "jwks.json", "auto", ""}};
  EXPECT_FALSE(TrustStore::from_config(cfg).ok());
  // HS256 only when named: the same secret file loaded as "auto" is not a key.
  cfg = {{kIss, private_copy(dir, "hs256.secret"), "auto", ""}};
  EXPECT_FALSE(TrustStore::from_config(cfg).ok());
}

TEST(Jwt, ParseDuration) {
  EXPECT_EQ(parse_duration("1h"), 3600);
  EXPECT_EQ(parse_duration("90"), 90);
  EXPECT_EQ(parse_duration("15m"), 900);
  EXPECT_EQ(parse_duration("7d"), 7 * 86400);
  EXPECT_EQ(parse_duration("30s"), 30);
  for (const char* bad : {"", "h", "0", "-5m", "1.5h", "1w", "99999999999999d", " 1h"})
    EXPECT_FALSE(parse_duration(bad)) << bad;
}

TEST(Jwt, DecodeExposesHeaderAndClaims) {
  auto tok = ed_token(base_claims());
  auto d = decode(tok);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->header.alg, "EdDSA");
  EXPECT_EQ(d->header.kid, "ed-1");
  EXPECT_EQ(d->header.typ, "JWT");
  EXPECT_EQ(d->claims.find("sub")->as_string(), "user-1");
  EXPECT_EQ(d->signature.size(), 64u);
}

// ---------------------------------------------------------------------------------------
// CLI

TEST(JwtCli, IssueAndInspectRoundTrip) {
  test::TempDir dir;
  std::string key = private_copy(dir, "p256_priv.pem");
  auto issued =
      test::run_cli({"token", "issue", "--key", key, "--sub", "alice", "--role", "owner", "--scope",
                     "control,config", "--aud", kAud, "--ttl", "1h", "--iss", kIss});
  ASSERT_EQ(issued.exit_code, 0) << issued.err;
  std::string tok = issued.out;
  while (!tok.empty() && (tok.back() == '\n' || tok.back() == '\r')) tok.pop_back();
  auto d = decode(tok);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->header.alg, "ES256");
  EXPECT_EQ(d->claims.find("role")->as_string(), "owner");

  auto ok = test::run_cli(
      {"token", "inspect", "--key", kData + "p256_pub.pem", "--iss", kIss, "--aud", kRobot}, tok);
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  EXPECT_NE(ok.out.find("\"valid\":true"), std::string::npos) << ok.out;
  auto wrong_key =
      test::run_cli({"token", "inspect", "--key", kData + "ed25519_pub.pem", "--aud", kRobot, tok});
  EXPECT_EQ(wrong_key.exit_code, 1) << wrong_key.out << wrong_key.err;
  auto wrong_aud = test::run_cli({"token", "inspect", "--key", kData + "p256_pub.pem", "--aud",
                                  "rcan://a.example/b/c/00000000", tok});
  EXPECT_EQ(wrong_aud.exit_code, 1);
  auto decode_only = test::run_cli({"token", "inspect", tok});
  EXPECT_EQ(decode_only.exit_code, 0);
  EXPECT_NE(decode_only.out.find("\"alice\""), std::string::npos);
  auto garbage = test::run_cli({"token", "inspect"}, "not-a-token\n");
  EXPECT_EQ(garbage.exit_code, 2);
}

TEST(JwtCli, IssueRefusesWithoutKeyAndWithBadArguments) {
  EXPECT_EQ(test::run_cli(
                {"token", "issue", "--sub", "a", "--role", "owner", "--aud", kAud, "--ttl", "1h"})
                .exit_code,
            2);
  test::TempDir dir;
  std::string key = private_copy(dir, "ed25519_priv.pem");
  EXPECT_EQ(test::run_cli({"token", "issue", "--key", key, "--sub", "a", "--role", "root", "--aud",
                           kAud, "--ttl", "1h"})
                .exit_code,
            2);
  EXPECT_EQ(test::run_cli({"token", "issue", "--key", key, "--sub", "a", "--role", "owner", "--aud",
                           kAud, "--ttl", "x"})
                .exit_code,
            2);
  EXPECT_EQ(test::run_cli({"token", "issue", "--key", key, "--sub", "a", "--role", "owner", "--aud",
                           kAud, "--ttl", "1h", "--alg", "RS256"})
                .exit_code,
            2);
  std::string loose = private_copy(dir, "rsa2048_priv.pem", 0644);
  auto r = test::run_cli({"token", "issue", "--key", loose, "--sub", "a", "--role", "owner",
                          "--aud", kAud, "--ttl", "1h"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("group/world"), std::string::npos) << r.err;
}

TEST(JwtCli, Hs256IssueNeedsExplicitAlgAndVerifiesWithSecret) {
  test::TempDir dir;
  std::string secret = private_copy(dir, "hs256.secret");
  auto issued =
      test::run_cli({"token", "issue", "--key", secret, "--alg", "HS256", "--sub", "svc", "--role",
                     "user", "--scope", "status", "--aud", kAud, "--ttl", "10m", "--iss", kIss});
  ASSERT_EQ(issued.exit_code, 0) << issued.err;
  auto ok = test::run_cli({"token", "inspect", "--secret", secret, "--iss", kIss, "--aud", kRobot},
                          issued.out);
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  auto confused = test::run_cli(
      {"token", "inspect", "--key", kData + "rsa2048_pub.pem", "--aud", kRobot}, issued.out);
  EXPECT_EQ(confused.exit_code, 1);
}

}  // namespace
}  // namespace rcan::jwt
