// Key-bound tokens (rcan/crypto/cnf.h, RFC 7800) through the Authenticator: a token with a `cnf`
// claim is accepted only on messages signed by its key, and a channel that requires bound
// tokens (MQTT) refuses a plain bearer token. docs/SECURITY.md R8.
#include <gtest/gtest.h>

#include <array>

#include "node/admission/authenticator.h"
#include "rcan/crypto/cnf.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/message.h"

using namespace rcan;
using namespace rcan::node;

namespace {

constexpr int64_t kNow = 1'800'000'000;
const std::string kAud = "rcan://local.rcan/acme/rover/abcdef12";

std::array<uint8_t, 32> seed_of(uint8_t fill) {
  std::array<uint8_t, 32> s{};
  s.fill(fill);
  return s;
}

// A holder's key pair, from fixed seeds.
keys::RobotKeys holder(uint8_t fill) {
  auto ms = seed_of(fill), es = seed_of(static_cast<uint8_t>(fill + 100));
  return std::move(keys::derive(ms, es)).value();
}

struct Fixture {
  jwt::SigningKey issuer = std::move(jwt::SigningKey::ed25519_seed(seed_of(7))).value();
  Authenticator auth = make();

  Authenticator make() {
    AuthOptions o;
    o.trust.add("test-issuer", *issuer.verification_key());
    o.verify.audience = kAud;
    return Authenticator(std::move(o));
  }
  std::string token(std::optional<json::Value> cnf) {
    json::Object c{{"iss", "test-issuer"},
                   {"sub", "fleet-op"},
                   {"aud", kAud},
                   {"role", "owner"},
                   {"scope", json::Array{"control"}},
                   {"iat", kNow - 5},
                   {"exp", kNow + 3600}};
    if (cnf) c.set("cnf", std::move(*cnf));
    return *jwt::issue(c, issuer);
  }
};

json::Object command(const std::string& tok,
                     const std::string& id = "00000000-0000-4000-8000-000000000001") {
  return json::Object{
      {"version", "1.0.0"}, {"message_id", id},
      {"type", "COMMAND"},  {"timestamp_ms", kNow * 1000},
      {"auth_token", tok},  {"payload", json::Object{{"action", "move_forward"}, {"speed", 0.2}}}};
}

Message decoded(const json::Object& wire) {
  auto m = decode_message(json::Value(wire));
  EXPECT_TRUE(m.ok()) << m.error().message;
  return std::move(m).value();
}

}  // namespace

TEST(BoundTokens, CnfClaimsOfBothAlgorithmsParseAndOthersAreRefused) {
  auto k = holder(1);
  auto ed = cnf::make(msgsig::Alg::kEd25519, k.pub.ed25519_pk);
  ASSERT_TRUE(ed.ok());
  auto p = cnf::parse(*ed);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->public_key, k.pub.ed25519_pk);
  EXPECT_EQ(p->kid, *keys::ed25519_kid(k.pub.ed25519_pk));
  auto ml = cnf::make(msgsig::Alg::kMlDsa65, k.pub.mldsa65_pk);
  ASSERT_TRUE(ml.ok());
  auto q = cnf::parse(*ml);
  ASSERT_TRUE(q.ok()) << q.error().message;
  EXPECT_EQ(q->alg, msgsig::Alg::kMlDsa65);
  EXPECT_EQ(q->public_key, k.pub.mldsa65_pk);

  for (const char* bad : {R"("x")", R"({})", R"({"jkt":"abc"})",
                          R"({"jwk":{"kty":"EC","crv":"P-256","x":"AA","y":"AA"}})",
                          R"({"jwk":{"kty":"OKP","crv":"Ed25519","x":"AAAA"}})",
                          R"({"jwk":{"kty":"OKP","crv":"X25519","x":"AAAA"}})",
                          R"({"jwk":{"kty":"OKP","crv":"Ed25519"},"kid":"k1"})"}) {
    auto v = json::parse(bad);
    ASSERT_TRUE(v.ok()) << bad;
    auto r = cnf::parse(*v);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.error().code, ErrorCode::kAuthInvalid) << bad;
  }
}

TEST(BoundTokens, AMalformedCnfMakesTheTokenInvalid) {
  Fixture f;
  auto r = f.auth.authenticate_token(f.token(*json::parse(R"({"jkt":"abc"})")), kNow);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kAuthInvalid);
}

TEST(BoundTokens, ABoundTokenNeedsItsKeysSignatureOnEveryTransport) {
  Fixture f;
  auto k = holder(2);
  std::string tok = f.token(*cnf::make(msgsig::Alg::kEd25519, k.pub.ed25519_pk));
  auto p = f.auth.authenticate_token(tok, kNow);
  ASSERT_TRUE(p.ok()) << p.error().message;
  ASSERT_TRUE(p->bound_key);

  // Unsigned: refused, whether or not the channel asks for bound tokens.
  for (bool need : {false, true}) {
    auto r = f.auth.check_signature(decoded(command(tok)), *p, need);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kAuthRequired);
  }
  // Signed by the bound key: accepted, and marked as such.
  json::Object good = command(tok);
  ASSERT_TRUE(msgsig::sign_ed25519(good, k.ed25519_seed.span()).ok());
  auto ok = f.auth.check_signature(decoded(good), *p, true);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_TRUE(ok->verified);
  EXPECT_TRUE(ok->bound_key);
  EXPECT_EQ(ok->alg, "ed25519");

  // Signed by another key (a topic reader's own): refused.
  auto other = holder(3);
  json::Object theirs = command(tok, "00000000-0000-4000-8000-000000000002");
  ASSERT_TRUE(msgsig::sign_ed25519(theirs, other.ed25519_seed.span()).ok());
  auto r = f.auth.check_signature(decoded(theirs), *p, true);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kSignatureInvalid);

  // The holder's signature lifted onto a message of the reader's making: refused.
  json::Object lifted = command(tok, "00000000-0000-4000-8000-000000000003");
  lifted.set("payload", json::Object{{"action", "move_backward"}, {"speed", 1.0}});
  lifted.set("sig", *good.find("sig"));
  auto l = f.auth.check_signature(decoded(lifted), *p, true);
  ASSERT_FALSE(l.ok());
  EXPECT_EQ(l.error().code, ErrorCode::kSignatureInvalid);
}

TEST(BoundTokens, AnMlDsaBoundTokenWorksTheSameWay) {
  Fixture f;
  auto k = holder(4);
  std::string tok = f.token(*cnf::make(msgsig::Alg::kMlDsa65, k.pub.mldsa65_pk));
  auto p = f.auth.authenticate_token(tok, kNow);
  ASSERT_TRUE(p.ok()) << p.error().message;
  json::Object m = command(tok);
  // An Ed25519 signature by the same holder is not the bound key.
  ASSERT_TRUE(msgsig::sign_ed25519(m, k.ed25519_seed.span()).ok());
  EXPECT_FALSE(f.auth.check_signature(decoded(m), *p, true).ok());
  ASSERT_TRUE(msgsig::sign_mldsa65(m, k.mldsa65_sk.span(), k.pub.mldsa65_pk).ok());
  auto r = f.auth.check_signature(decoded(m), *p, true);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->alg, "ml-dsa-65");
}

TEST(BoundTokens, AChannelThatNeedsBoundTokensRefusesABearerToken) {
  Fixture f;
  std::string tok = f.token(std::nullopt);
  auto p = f.auth.authenticate_token(tok, kNow);
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(p->bound_key);
  auto r = f.auth.check_signature(decoded(command(tok)), *p, true);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kAuthInvalid);
  EXPECT_EQ(r.error().field, "cnf");
  // Elsewhere (HTTP, WebSocket) a bearer token stays a bearer token.
  EXPECT_TRUE(f.auth.check_signature(decoded(command(tok)), *p, false).ok());
}
