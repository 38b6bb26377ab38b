// The verified-token cache (node/token_cache.h) through the Authenticator: a cached token is
// never accepted where full verification would refuse it.
#include "node/admission/token_cache.h"

#include <gtest/gtest.h>

#include <array>

#include "node/admission/authenticator.h"
#include "rcan/crypto/jwt.h"

using namespace rcan;
using namespace rcan::node;

namespace {

constexpr int64_t kNow = 1'800'000'000;
const std::string kAud = "rcan://local.rcan/acme/rover/abcdef12";

jwt::SigningKey signing_key(uint8_t fill) {
  std::array<uint8_t, 32> seed{};
  seed.fill(fill);
  return std::move(jwt::SigningKey::ed25519_seed(seed)).value();
}

Authenticator make_auth(const jwt::SigningKey& key, size_t cache_entries = 4096) {
  AuthOptions o;
  o.trust.add("test-issuer", *key.verification_key());
  o.verify.audience = kAud;
  o.verify.leeway_s = 60;
  o.token_cache_entries = cache_entries;
  return Authenticator(std::move(o));
}

std::string token(const jwt::SigningKey& key, const std::string& sub, int64_t iat, int64_t exp,
                  std::optional<int64_t> nbf = std::nullopt) {
  json::Object c{{"iss", "test-issuer"},
                 {"sub", sub},
                 {"aud", kAud},
                 {"role", "user"},
                 {"scope", json::Array{"status", "control"}},
                 {"iat", iat},
                 {"exp", exp}};
  if (nbf) c.set("nbf", *nbf);
  return *jwt::issue(c, key);
}

}  // namespace

TEST(TokenCache, RepeatedTokenGivesTheSamePrincipal) {
  auto key = signing_key(1);
  Authenticator auth = make_auth(key);
  std::string t = token(key, "alice", kNow - 10, kNow + 3600);
  auto a = auth.authenticate_token(t, kNow);
  ASSERT_TRUE(a.ok()) << a.error().message;
  auto b = auth.authenticate_token(t, kNow + 1);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->sub, "alice");
  EXPECT_EQ(b->role, Role::kUser);
  EXPECT_EQ(b->scopes, a->scopes);
  EXPECT_EQ(b->key(), a->key());
}

TEST(TokenCache, ExpiryIsCheckedOnEveryUse) {
  auto key = signing_key(2);
  Authenticator auth = make_auth(key);
  std::string t = token(key, "bob", kNow - 10, kNow + 100);
  ASSERT_TRUE(auth.authenticate_token(t, kNow).ok());
  // Within exp + leeway: still accepted; at exp + leeway: refused like the verifier refuses it.
  EXPECT_TRUE(auth.authenticate_token(t, kNow + 159).ok());
  auto late = auth.authenticate_token(t, kNow + 160);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.error().code, ErrorCode::kAuthInvalid);
  EXPECT_NE(late.error().message.find("expired"), std::string::npos);
}

TEST(TokenCache, NotBeforeAndIssuedAtAreCheckedOnEveryUse) {
  auto key = signing_key(3);
  Authenticator auth = make_auth(key);
  // Valid from kNow + 40 (nbf kNow + 100, leeway 60).
  std::string t = token(key, "carol", kNow, kNow + 3600, kNow + 100);
  ASSERT_TRUE(auth.authenticate_token(t, kNow + 40).ok());
  auto early = auth.authenticate_token(t, kNow + 39);
  ASSERT_FALSE(early.ok());
  EXPECT_EQ(early.error().code, ErrorCode::kAuthInvalid);
  // iat in the future beyond the leeway.
  std::string f = token(key, "dave", kNow + 200, kNow + 3600);
  ASSERT_TRUE(auth.authenticate_token(f, kNow + 140).ok());
  EXPECT_FALSE(auth.authenticate_token(f, kNow + 139).ok());
}

TEST(TokenCache, OnlyTheExactBytesHit) {
  auto key = signing_key(4);
  auto other = signing_key(5);
  Authenticator auth = make_auth(key);
  std::string t = token(key, "erin", kNow, kNow + 3600);
  ASSERT_TRUE(auth.authenticate_token(t, kNow).ok());
  // A different signature over the same claims (a key the node does not trust) is refused.
  std::string forged = token(other, "erin", kNow, kNow + 3600);
  ASSERT_NE(forged, t);
  EXPECT_FALSE(auth.authenticate_token(forged, kNow).ok());
  // One byte changed in the signature of the cached token: refused.
  std::string tampered = t;
  tampered.back() = tampered.back() == 'A' ? 'B' : 'A';
  EXPECT_FALSE(auth.authenticate_token(tampered, kNow).ok());
  // A prefix or an extension of the cached token is not the cached token.
  EXPECT_FALSE(auth.authenticate_token(t + "A", kNow).ok());
  EXPECT_FALSE(auth.authenticate_token(t.substr(0, t.size() - 1), kNow).ok());
  EXPECT_TRUE(auth.authenticate_token(t, kNow).ok());
}

TEST(TokenCache, BoundedAndRefusalsAreNotRemembered) {
  TokenCache cache(2);
  Principal p;
  p.authenticated = true;
  p.sub = "x";
  cache.insert("t1", p, 0, 100);
  cache.insert("t2", p, 0, 100);
  cache.insert("t3", p, 0, 100);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_TRUE(cache.find("t3", 50).has_value());
  // Outside the window: a miss, and the entry is dropped.
  EXPECT_FALSE(cache.find("t3", 100).has_value());
  EXPECT_FALSE(cache.find("t3", 50).has_value());
  // A disabled cache remembers nothing.
  TokenCache off(0);
  off.insert("t", p, 0, 100);
  EXPECT_FALSE(off.find("t", 50).has_value());

  auto key = signing_key(6);
  Authenticator auth = make_auth(key);
  std::string expired = token(key, "frank", kNow - 7200, kNow - 3600);
  EXPECT_FALSE(auth.authenticate_token(expired, kNow).ok());
  EXPECT_FALSE(auth.authenticate_token(expired, kNow).ok());
}
