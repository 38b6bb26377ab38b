// The node's link to its registry's token authority in process (node/admission/registry_trust.h),
// on a ManualClock: a restart while the registry does not answer verifies with the cached keys
// (and says how fresh they are), a cache of another registry or issuer is not used, the
// revocation cursor of the last run is read back, and the introspection answers expire on the
// clock. The same behaviours against a real rcand and registry stand-in: e2e/registry_trust_test.
#include <gtest/gtest.h>

#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/clock.h"
#include "base/metrics.h"
#include "node/admission/authenticator.h"
#include "node/admission/registry_trust.h"
#include "node/admission/revocation.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "registry_token_fixture.h"
#include "runtime/state_file.h"
#include "test_support.h"

namespace rcan::node {
namespace {

using namespace registry_fixture;
// Nothing listens there: every call to the registry fails at once.
const std::string kDownRegistry = "http://127.0.0.1:1";

// A node's parts the link works with, and the records it wrote.
struct Node {
  ManualClock clock{kNowS * 1000};
  Authenticator auth = make_auth();
  RevocationList revocations;
  Metrics metrics;
  std::vector<TrustRecord> records;

  std::unique_ptr<RegistryTrust> trust(const std::string& data_dir,
                                       const std::string& registry_url = kDownRegistry) {
    RegistryTrustOptions o;
    o.registry_url = registry_url;
    o.issuer = kIss;
    o.data_dir = data_dir;
    o.rrn = kRrn;
    o.max_key_age_s = 3600;
    return std::make_unique<RegistryTrust>(o, clock, auth, revocations, metrics,
                                           [this](TrustRecord r) { records.push_back(r); });
  }
};

void write_jwks_cache(const std::string& data_dir, const std::string& registry_url,
                      const std::string& issuer, int64_t fetched_at_ms) {
  auto jwks = json::parse(R"({"keys":[)" + jwk(1, "k1") + "]}");
  ASSERT_TRUE(jwks.ok());
  ASSERT_TRUE(std::filesystem::create_directories(data_dir + "/registry"));
  ASSERT_TRUE(write_state_file(data_dir + "/registry/jwks.json",
                               json::Value(json::Object{{"registry_url", registry_url},
                                                        {"issuer", issuer},
                                                        {"fetched_at_ms", fetched_at_ms},
                                                        {"jwks", *jwks}}))
                  .ok());
}

TEST(RegistryKeys, ARestartWithTheRegistryDownVerifiesWithTheCachedKeys) {
  test::TempDir dir;
  Node node;
  const int64_t fetched_at = node.clock.wall_ms() - 60'000;  // the last run's fetch
  write_jwks_cache(dir.path(), kDownRegistry, kIss, fetched_at);
  auto trust = node.trust(dir.path());
  trust->prime(500);
  EXPECT_EQ(trust->keys_fetched_ms(), fetched_at);
  auto p = node.auth.authenticate_token(token(1, "k1"), kNowS);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->issuer, kIss);

  json::Value status = trust->status_json();
  const json::Value* jwks = status.get("jwks");
  ASSERT_NE(jwks, nullptr);
  EXPECT_EQ(jwks->get("source")->as_string(), "cache");
  EXPECT_EQ(jwks->get("key_count")->as_int(), 1);
  EXPECT_EQ(jwks->get("fetched_at_ms")->as_int(), fetched_at);
  EXPECT_EQ(jwks->get("fresh_until_ms")->as_int(), fetched_at + 3600 * 1000);
  // The failed fetch is the last error; the keys were installed from the cache and recorded.
  ASSERT_TRUE(status.get("last_error")->is_string());
  EXPECT_EQ(status.get("last_error")->as_string().rfind("registry keys: ", 0), 0u);
  ASSERT_EQ(node.records.size(), 1u);
  EXPECT_EQ(node.records[0].event, "REGISTRY_KEYS_UPDATED");
  EXPECT_EQ(node.records[0].detail.find("source")->as_string(), "cache");
}

TEST(RegistryKeys, ACacheOfAnotherRegistryOrIssuerIsNotUsed) {
  for (const auto& [url, iss] : {std::pair<std::string, std::string>{"http://other.example", kIss},
                                 {kDownRegistry, "https://other-issuer.example"}}) {
    test::TempDir dir;
    Node node;
    write_jwks_cache(dir.path(), url, iss, node.clock.wall_ms());
    auto trust = node.trust(dir.path());
    trust->prime(500);
    EXPECT_EQ(trust->keys_fetched_ms(), 0) << url << " " << iss;
    EXPECT_FALSE(node.auth.authenticate_token(token(1, "k1"), kNowS).ok());
    EXPECT_TRUE(trust->status_json().get("jwks")->get("fetched_at_ms")->is_null());
    EXPECT_TRUE(node.records.empty());
  }
}

TEST(RegistryRevocationFeed, TheCursorOfTheLastRunIsReadBackForTheSameRegistryOnly) {
  test::TempDir dir;
  ASSERT_TRUE(std::filesystem::create_directories(dir.path() + "/registry"));
  const std::string cursor = dir.path() + "/registry/revocations_cursor.json";
  ASSERT_TRUE(write_state_file(
                  cursor, json::Value(json::Object{{"registry_url", kDownRegistry}, {"since", 42}}))
                  .ok());
  {
    Node node;
    auto trust = node.trust(dir.path());
    trust->prime(500);
    EXPECT_EQ(trust->status_json().get("revocations")->get("since")->as_int(), 42);
  }
  {
    Node node;
    auto trust = node.trust(dir.path(), "http://127.0.0.1:2");  // another registry
    trust->prime(500);
    EXPECT_EQ(trust->status_json().get("revocations")->get("since")->as_int(), 0);
  }
}

TEST(IntrospectionAnswers, AnAnswerHoldsUntilItsTimeOnTheClock) {
  ManualClock clock(kNowS * 1000);
  IntrospectionAnswers answers(clock);
  answers.put("active", {json::Object{{"sub", "ops"}}, clock.wall_ms() + 60'000});
  answers.put("inactive", {std::nullopt, clock.wall_ms() + 30'000});
  EXPECT_TRUE(answers.answered("active"));
  EXPECT_TRUE(answers.answered("inactive"));
  EXPECT_FALSE(answers.answered("unknown"));
  ASSERT_TRUE(answers.claims("active").has_value());
  EXPECT_EQ(answers.claims("active")->find("sub")->as_string(), "ops");
  EXPECT_FALSE(answers.claims("inactive").has_value());

  clock.advance(30'000);  // the inactive answer is over: the token may be asked about again
  EXPECT_FALSE(answers.answered("inactive"));
  EXPECT_TRUE(answers.claims("active").has_value());
  clock.advance(30'000);
  EXPECT_FALSE(answers.answered("active"));
  EXPECT_FALSE(answers.claims("active").has_value());
}

TEST(IntrospectionAnswers, PastCapacityTheExpiredAnswersGoFirst) {
  ManualClock clock(kNowS * 1000);
  IntrospectionAnswers answers(clock, 3);
  answers.put("a", {std::nullopt, clock.wall_ms() + 1'000});
  answers.put("b", {std::nullopt, clock.wall_ms() + 1'000});
  answers.put("c", {std::nullopt, clock.wall_ms() + 60'000});
  clock.advance(1'000);
  answers.put("d", {std::nullopt, clock.wall_ms() + 60'000});
  EXPECT_EQ(answers.size(), 2u);  // a and b expired and went; c and d stay
  EXPECT_TRUE(answers.answered("c"));
  EXPECT_TRUE(answers.answered("d"));
}

}  // namespace
}  // namespace rcan::node
