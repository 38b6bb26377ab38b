// The registry's token authority as the node reads it (node/admission/registry_feed.h) and the
// Authenticator following an issuer's published keys (set_followed_issuer_keys).
#include "node/admission/registry_feed.h"

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <map>
#include <thread>

#include "node/admission/authenticator.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/encoding.h"
#include "rcan/registry.h"
#include "registry_token_fixture.h"

using namespace rcan;
using namespace rcan::node;

namespace {

using namespace registry_fixture;
constexpr int64_t kNow = kNowS;

std::vector<jwt::VerificationKey> parsed_keys(const std::string& jwks) {
  auto set = parse_registry_jwks(jwks);
  EXPECT_TRUE(set.ok()) << set.error().message;
  return set.ok() ? std::move(set->keys) : std::vector<jwt::VerificationKey>{};
}

}  // namespace

TEST(RegistryFeed, JwksKeepsOnlySignatureKeysWithAKid) {
  auto set = parse_registry_jwks(
      R"({"keys":[)" + jwk(1, "k1") + "," + jwk(2, "") +
      R"(,{"kty":"oct","k":"c2VjcmV0c2VjcmV0c2VjcmV0c2VjcmV0c2VjcmV0","kid":"h"},)" +
      R"({"kty":"RSA","kid":"r"}]})");
  ASSERT_TRUE(set.ok()) << set.error().message;
  ASSERT_EQ(set->keys.size(), 1u);
  EXPECT_EQ(set->keys[0].kid(), "k1");
  EXPECT_EQ(set->skipped, 3u);
  for (const char* bad : {"", "[]", "{}", R"({"keys":{}})", R"({"keys":[]})",
                          R"({"keys":[{"kty":"OKP","crv":"Ed25519","kid":"k"}]})", "not json"}) {
    auto r = parse_registry_jwks(bad);
    EXPECT_FALSE(r.ok()) << bad;
    if (!r.ok()) {
      EXPECT_FALSE(r.error().message.empty());
    }
  }
}

TEST(RegistryFeed, RevocationPage) {
  auto p = parse_revocation_page(
      R"({"revocations":[{"seq":12,"jti":"a","sub":null,"exp":1900000000,"revoked_at":"2026-11-27T05:35:00Z"},)"
      R"({"seq":13,"jti":null,"sub":"alice","exp":null,"revoked_at":"2026-11-27T06:35:00.5+01:00"}],"next_since":13})",
      11);
  ASSERT_TRUE(p.ok()) << p.error().message;
  ASSERT_EQ(p->entries.size(), 2u);
  EXPECT_EQ(p->entries[0].jti, "a");
  EXPECT_EQ(*p->entries[0].exp, 1'900'000'000);
  EXPECT_EQ(p->entries[1].sub, "alice");
  EXPECT_FALSE(p->entries[1].exp.has_value());
  EXPECT_EQ(*p->entries[0].revoked_at_ms, 1'795'757'700'000);
  EXPECT_EQ(*p->entries[1].revoked_at_ms, 1'795'757'700'500);
  EXPECT_EQ(p->next_since, 13);
  for (const char* bad :
       {R"({"revocations":[{"seq":11,"jti":"a"}],"next_since":11})",  // not above since
        R"({"revocations":[{"seq":12,"jti":null,"sub":null}],"next_since":12})",
        R"({"revocations":[{"seq":12,"jti":5}],"next_since":12})",
        R"({"revocations":[{"seq":13,"jti":"a"},{"seq":12,"jti":"b"}],"next_since":13})",
        R"({"revocations":[],"next_since":3})",  // goes back
        R"({"revocations":[{"seq":12,"jti":"a"}],"next_since":11})", R"({"next_since":11})",
        "[]"}) {
    auto r = parse_revocation_page(bad, 11);
    EXPECT_FALSE(r.ok()) << bad;
  }
  EXPECT_FALSE(parse_iso8601_ms("2026-13-01T00:00:00Z").has_value());
  EXPECT_FALSE(parse_iso8601_ms("2026-01-01T00:00:00").has_value());
  EXPECT_EQ(*parse_iso8601_ms("1970-01-01T00:00:00Z"), 0);
}

TEST(FollowedIssuer, KeysAreSwappedInAndOutAndUnknownKidsReported) {
  Authenticator auth = make_auth();
  std::vector<std::string> asked;
  auth.on_unknown_followed_key(
      kIss, [&](const std::string& kid, std::string_view) { asked.push_back(kid); });
  const std::string t1 = token(1, "k1");
  EXPECT_FALSE(auth.authenticate_token(t1, kNow).ok());  // no keys yet: untrusted issuer
  ASSERT_EQ(asked.size(), 1u);
  EXPECT_EQ(asked[0], "k1");
  auth.set_followed_issuer_keys(kIss, parsed_keys(R"({"keys":[)" + jwk(1, "k1") + "]}"));
  auto p = auth.authenticate_token(t1, kNow);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->issuer, kIss);
  EXPECT_EQ(p->role, Role::kOwner);
  // A token of another issuer is not the registry's concern; a forged key under k1 is refused
  // without asking for keys.
  EXPECT_FALSE(auth.authenticate_token(token(1, "k1", "elsewhere"), kNow).ok());
  EXPECT_FALSE(auth.authenticate_token(token(3, "k1"), kNow).ok());
  EXPECT_EQ(asked.size(), 1u);
  // Rotation: k2 is unknown, then known; once k1 leaves the JWKS its (cached) token is refused.
  const std::string t2 = token(2, "k2");
  EXPECT_FALSE(auth.authenticate_token(t2, kNow).ok());
  EXPECT_EQ(asked.back(), "k2");
  auth.set_followed_issuer_keys(kIss, parsed_keys(R"({"keys":[)" + jwk(2, "k2") + "]}"));
  EXPECT_TRUE(auth.authenticate_token(t2, kNow).ok());
  EXPECT_FALSE(auth.authenticate_token(t1, kNow).ok());
  // The configured issuers are untouched by the swaps.
  auto local = jwt::SigningKey::ed25519_seed(seed(9));
  json::Object c{{"iss", "local"}, {"sub", "me"}, {"aud", kAud},
                 {"role", "user"}, {"iat", kNow}, {"exp", kNow + 60}};
  EXPECT_TRUE(auth.authenticate_token(*jwt::issue(c, *local), kNow).ok());
}

// Many threads verify while the keys are swapped (run under ThreadSanitizer in the tsan tree).
TEST(FollowedIssuer, SwapWhileVerifying) {
  Authenticator auth = make_auth();
  const auto set = R"({"keys":[)" + jwk(1, "k1") + "]}";
  auth.set_followed_issuer_keys(kIss, parsed_keys(set));
  const std::string t1 = token(1, "k1");
  std::atomic<bool> stop{false};
  std::atomic<int> refused{0};
  std::vector<std::thread> threads;
  for (int i = 0; i < 4; ++i)
    threads.emplace_back([&] {
      while (!stop.load())
        if (!auth.authenticate_token(t1, kNow).ok()) ++refused;
    });
  for (int i = 0; i < 200; ++i) auth.set_followed_issuer_keys(kIss, parsed_keys(set));
  stop = true;
  for (auto& t : threads) t.join();
  EXPECT_EQ(refused.load(), 0);
}

// The registry's introspection answer stands in for a signature the node cannot check, never
// for the checks of the claims: exp, aud, role and issuer are this node's to check.
TEST(FollowedIssuer, IntrospectedClaimsAreCheckedLikeAVerifiedTokens) {
  Authenticator auth = make_auth();
  std::map<std::string, json::Object> answers;
  int asked = 0;
  auth.on_unknown_followed_key(
      kIss, [&](const std::string&, std::string_view) { ++asked; },
      [&](std::string_view t) -> std::optional<json::Object> {
        auto it = answers.find(std::string(t));
        if (it == answers.end()) return std::nullopt;
        return it->second;
      });
  const std::string t = token(7, "kx");  // signed "owner" by a key the node never had
  EXPECT_FALSE(auth.authenticate_token(t, kNow).ok());
  EXPECT_EQ(asked, 1);
  const json::Object answer{{"iss", kIss}, {"sub", "carol"},   {"aud", kAud},
                            {"rrn", kRrn}, {"role", "user"},   {"scope", "status control"},
                            {"iat", kNow}, {"exp", kNow + 100}};
  answers[t] = answer;
  auto p = auth.authenticate_token(t, kNow);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->sub, "carol");
  EXPECT_EQ(p->role, Role::kUser);  // the answer's role, not the token's
  EXPECT_TRUE(p->has_scope("control"));
  EXPECT_EQ(p->issuer, kIss);
  EXPECT_EQ(asked, 1);  // answered: nothing more to ask
  // Another robot's audience, an expired answer, another issuer: refused.
  answers[t] = answer;
  answers[t].set("aud", "rcan://local.rcan/acme/rover/ffffffff");
  EXPECT_FALSE(auth.authenticate_token(t, kNow).ok());
  answers[t] = answer;
  answers[t].set("exp", kNow - 3600);
  EXPECT_FALSE(auth.authenticate_token(t, kNow).ok());
  answers[t] = answer;
  answers[t].set("iss", "elsewhere");
  EXPECT_FALSE(auth.authenticate_token(t, kNow).ok());
  answers[t] = answer;
  answers[t].set("role", "emperor");
  EXPECT_FALSE(auth.authenticate_token(t, kNow).ok());
  // The registry's word names this robot exactly (docs/SECURITY.md R20): its RRN, no wildcard.
  answers[t] = answer;
  answers[t].set("rrn", "RRN-000000000777");
  EXPECT_EQ(auth.authenticate_token(t, kNow).error().reason, "rrn_mismatch");
  answers[t] = answer;
  answers[t].set("aud", "rcan://*/*/*/*");
  EXPECT_EQ(auth.authenticate_token(t, kNow).error().reason, "aud_not_exact");
}

// What rcand reads back when it introspects a token (RFC 7662) and registers itself.
TEST(RegistryAnswers, IntrospectionAnswers) {
  const int64_t now = kNow * 1000, active = 60'000, inactive = 30'000;
  auto a = parse_introspection_answer(
      R"({"active":true,"iss":"https://registry.example","sub":"carol","exp":)" +
          std::to_string(kNow + 10) + "}",
      now, active, inactive);
  ASSERT_TRUE(a.ok()) << a.error().message;
  ASSERT_TRUE(a->claims.has_value());
  EXPECT_EQ(a->claims->find("active"), nullptr);
  EXPECT_EQ(json::string_field(json::Value(*a->claims), "sub"), "carol");
  EXPECT_EQ(a->until_ms, (kNow + 10) * 1000);  // before now + 60 s: the token's own end
  a = parse_introspection_answer(R"({"active":true,"exp":)" + std::to_string(kNow + 3600) + "}",
                                 now, active, inactive);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->until_ms, now + active);
  // An exp so large that exp × 1000 overflows is capped, not wrapped into the past; one far in
  // the past ends the answer at once.
  for (const char* exp : {"9223372036854775807", "9223372036854776"}) {
    a = parse_introspection_answer(std::string(R"({"active":true,"exp":)") + exp + "}", now, active,
                                   inactive);
    ASSERT_TRUE(a.ok()) << exp;
    EXPECT_EQ(a->until_ms, now + active) << exp;
  }
  a = parse_introspection_answer(R"({"active":true,"exp":-9223372036854775807})", now, active,
                                 inactive);
  ASSERT_TRUE(a.ok());
  EXPECT_LT(a->until_ms, now);
  // Inactive, or active without an integer exp: no claims, remembered as inactive.
  for (const char* body : {R"({"active":false})", R"({"active":true})",
                           R"({"active":true,"exp":"soon"})", R"({"active":true,"exp":1.5})"}) {
    a = parse_introspection_answer(body, now, active, inactive);
    ASSERT_TRUE(a.ok()) << body;
    EXPECT_FALSE(a->claims.has_value()) << body;
    EXPECT_EQ(a->until_ms, now + inactive) << body;
  }
  for (const char* body : {"", "[]", "{}", R"({"active":"true"})", "not json", R"({"active":1})"})
    EXPECT_FALSE(parse_introspection_answer(body, now, active, inactive).ok()) << body;
  std::string huge =
      R"({"active":true,"pad":")" + std::string(kMaxRegistryAnswerBytes, 'x') + "\"}";
  EXPECT_FALSE(parse_introspection_answer(huge, now, active, inactive).ok());
}

TEST(RegistryAnswers, ChallengeRegistrationAndRefusal) {
  auto c = parse_registry_challenge(R"({"challenge_id":"c1","nonce":"n1","expires_in":60})");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->id, "c1");
  EXPECT_EQ(c->nonce, "n1");
  for (const char* body : {R"({"challenge_id":"c1"})", R"({"challenge_id":"","nonce":"n"})",
                           R"({"challenge_id":7,"nonce":"n"})", "[]", "nope"})
    EXPECT_FALSE(parse_registry_challenge(body).ok()) << body;
  EXPECT_FALSE(
      parse_registry_challenge(R"({"challenge_id":")" + std::string(513, 'c') + R"(","nonce":"n"})")
          .ok());

  auto r = parse_registration_answer(R"({"rrn":"RRN-000000000042","api_key":"rk_1"})");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->rrn, *registry::normalize_rrn("RRN-000000000042"));
  EXPECT_EQ(r->robot_key, "rk_1");
  r = parse_registration_answer(R"({"rrn":"RRN-000000000042"})");
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->robot_key.empty());
  for (const char* body : {R"({"rrn":"not-an-rrn"})", R"({"rrn":42})", "{}", "", "[1]"})
    EXPECT_FALSE(parse_registration_answer(body).ok()) << body;

  EXPECT_EQ(registry_refusal(409, R"({"message":"already registered"})"),
            "the registry answered 409: already registered");
  EXPECT_EQ(registry_refusal(403, R"({"error":"forbidden"})"),
            "the registry answered 403: forbidden");
  EXPECT_EQ(registry_refusal(500, "<html>"), "the registry answered 500");
  // A long message is cut at a character boundary (it goes into logs and audit records).
  std::string msg(511, 'a');
  msg += "\xC3\xA9\xC3\xA9";  // é é: the cut falls inside the first
  const std::string line = registry_refusal(400, R"({"message":")" + msg + "\"}");
  EXPECT_EQ(line, "the registry answered 400: " + std::string(511, 'a'));
}
