// Hybrid Ed25519 + ML-DSA-65 signed bodies: the 14 cases of hybrid-sign-body.json in SDK and
// strict mode, byte-exact reproduction of the rcan-py body, and round trips.
#include "rcan/crypto/hybrid.h"

#include <gtest/gtest.h>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"
#include "test_support.h"

namespace rcan::hybrid {
namespace {

json::Object parse_obj(const std::string& text) {
  auto v = json::parse(text);
  EXPECT_TRUE(v.ok()) << (v.ok() ? "" : v.error().message);
  if (!v.ok() || !v->is_object()) return {};
  return v->as_object();
}

struct Keys {
  Bytes pk0, sk0, pk1;
};
const Keys& keys() {
  static Keys k = [] {
    auto kg = test::load_vector("mldsa65-keygen.json");
    const auto& cs = kg.get("cases")->as_array();
    return Keys{test::hex(cs[0].get("pk_hex")->as_string()),
                test::hex(cs[0].get("sk_hex")->as_string()),
                test::hex(cs[1].get("pk_hex")->as_string())};
  }();
  return k;
}
const Bytes kEdSeed(32, 7);

const Bytes& pk_for_kid(const std::string& kid) {
  EXPECT_TRUE(kid == "d666806e" || kid == "1bc4ede9") << kid;
  return kid == "d666806e" ? keys().pk0 : keys().pk1;
}

TEST(Hybrid, VectorCasesInSdkAndStrictMode) {
  auto v = test::load_vector("hybrid-sign-body.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 14u);
  EXPECT_EQ(to_hex(keys().pk1), v.get("keys")->get("ml_dsa_pk1_hex")->as_string());
  int strict_rejects = 0;
  for (const auto& c : cases) {
    const std::string name = c.get("name")->as_string();
    SCOPED_TRACE(name);
    json::Object body = parse_obj(c.get("signed_json")->as_string());
    EXPECT_EQ(preimage(body), c.get("canonical_preimage_utf8")->as_string());
    EXPECT_EQ(sha256_hex(preimage(body)), c.get("preimage_sha256")->as_string());
    const Bytes& pk = pk_for_kid(c.get("verify_with_pq_pub_kid")->as_string());
    bool sdk_expected = c.get("expected_rcan_sdk_result")->as_bool();
    const json::Value* se = c.get("strict_expected_result");
    bool strict_expected = se ? se->as_bool() : sdk_expected;

    VerifyOptions sdk;
    sdk.strict = false;
    Status s = verify_body(body, pk, sdk);
    EXPECT_EQ(s.ok(), sdk_expected) << (s.ok() ? "" : s.error().message);
    Status st = verify_body(body, pk);  // strict is the default
    EXPECT_EQ(st.ok(), strict_expected) << (st.ok() ? "" : st.error().message);
    if (!st.ok()) {
      ++strict_rejects;
      EXPECT_EQ(st.error().code, ErrorCode::kSignatureInvalid);
      EXPECT_FALSE(st.error().message.empty());
    }
    if (name == "embedded_pub_mismatch") {
      ASSERT_FALSE(st.ok());
      EXPECT_EQ(st.error().field, "pq_signing_pub");
    }
  }
  EXPECT_EQ(strict_rejects, 9);
}

TEST(Hybrid, SignBodyReproducesTheRcanPyBody) {
  auto v = test::load_vector("hybrid-sign-body.json");
  json::Object want;
  for (const auto& c : v.get("cases")->as_array())
    if (c.get("name")->as_string() == "signed_by_rcan_py")
      want = parse_obj(c.get("signed_json")->as_string());
  ASSERT_FALSE(want.empty());
  json::Object body{{"rrn", "RRN-000000000042"}, {"name", "bot"}, {"n", 50.0}};
  SignOptions o;
  o.deterministic = true;
  auto signed_body = sign_body(body, keys().sk0, keys().pk0, kEdSeed, o);
  ASSERT_TRUE(signed_body.ok()) << signed_body.error().message;
  EXPECT_EQ(*signed_body, want);
  EXPECT_EQ(json::dump(json::Value(*signed_body)).substr(0, 41),
            R"({"rrn":"RRN-000000000042","name":"bot","n)");
  EXPECT_TRUE(verify_body(*signed_body, keys().pk0).ok());
}

TEST(Hybrid, NewNestedBodyWithPlaceholderSigIsReproduced) {
  auto v = test::load_vector("hybrid-sign-body.json");
  json::Object want;
  for (const auto& c : v.get("cases")->as_array())
    if (c.get("name")->as_string() == "new_nested_body")
      want = parse_obj(c.get("signed_json")->as_string());
  ASSERT_FALSE(want.empty());
  json::Object input = want;
  input.erase("pq_signing_pub");
  input.erase("pq_kid");
  input.set("sig", json::Object{});  // placeholder dropped before signing
  SignOptions o;
  o.deterministic = true;
  auto out = sign_body(input, keys().sk0, keys().pk0, kEdSeed, o);
  ASSERT_TRUE(out.ok());
  EXPECT_EQ(*out->find("sig"), *want.find("sig"));
  EXPECT_EQ(preimage(*out), preimage(want));
}

TEST(Hybrid, ProducedBodiesVerifyAndRejectTampering) {
  json::Object body{
      {"rrn", "RRN-000000000007"}, {"caps", json::Array{"arm", "nav"}}, {"ratio", 0.25}};
  auto out = sign_body(body, keys().sk0, keys().pk0, kEdSeed);
  ASSERT_TRUE(out.ok());
  EXPECT_TRUE(verify_body(*out, keys().pk0).ok());
  EXPECT_FALSE(verify_body(*out, keys().pk1).ok());
  auto edpub = ed25519::public_key_from_seed(kEdSeed);
  VerifyOptions pin;
  pin.expected_ed25519_pub = *edpub;
  EXPECT_TRUE(verify_body(*out, keys().pk0, pin).ok());
  pin.expected_ed25519_pub = Bytes(32, 1);
  EXPECT_FALSE(verify_body(*out, keys().pk0, pin).ok());

  json::Object t = *out;
  t.set("ratio", 0.5);
  EXPECT_FALSE(verify_body(t, keys().pk0).ok());
  t = *out;
  t.set("extra", true);
  EXPECT_FALSE(verify_body(t, keys().pk0).ok());
  // Malformed sig members never crash and name the field.
  for (const char* member : {"ml_dsa", "ed25519", "ed25519_pub"}) {
    for (const json::Value& bad :
         {json::Value(1), json::Value("!!!"), json::Value("AAAA"), json::Value()}) {
      t = *out;
      json::Object sig = t.find("sig")->as_object();
      sig.set(member, bad);
      t.set("sig", json::Value(sig));
      Status s = verify_body(t, keys().pk0);
      ASSERT_FALSE(s.ok());
      EXPECT_EQ(s.error().field, std::string("sig.") + member);
    }
  }
  t = *out;
  t.set("sig", "x");
  EXPECT_FALSE(verify_body(t, keys().pk0).ok());
  EXPECT_FALSE(verify_body(*out, Bytes(10, 0)).ok());
  // Wrong key sizes for signing.
  EXPECT_FALSE(sign_body(body, Bytes(10, 0), keys().pk0, kEdSeed).ok());
  EXPECT_FALSE(sign_body(body, keys().sk0, keys().pk0, Bytes(31, 0)).ok());
}

}  // namespace
}  // namespace rcan::hybrid
