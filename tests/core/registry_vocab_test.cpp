// The registry's shared vocabulary (include/rcan/registry.h) and its proof of possession
// (include/rcan/crypto/registry_proof.h).
#include <gtest/gtest.h>

#include "rcan/crypto/registry_proof.h"
#include "rcan/encoding.h"
#include "rcan/registry.h"

namespace rcan::registry {
namespace {

TEST(RegistrySlug, FollowsTheReferenceRegistry) {
  EXPECT_EQ(slugify("Acme Robotics"), "acme-robotics");
  EXPECT_EQ(slugify("RobotArm_v2"), "robotarm-v2");
  EXPECT_EQ(slugify("a--b"), "a-b");
  EXPECT_EQ(slugify("'; DROP TABLE robots;--"), "-drop-table-robots-");
  EXPECT_EQ(slugify("\xc3\xa9t\xc3\xa9"), "-t-");  // each UTF-8 character becomes one '-'
  EXPECT_EQ(slugify(std::string(100, 'x')).size(), 64u);
  EXPECT_EQ(slugify(""), "");
}

TEST(RegistryRrn, AnyLetterCaseNormalisesToTheCanonicalRrn) {
  EXPECT_EQ(normalize_rrn("rrn-bd-000000000001").value_or(""), "RRN-BD-000000000001");
  EXPECT_EQ(normalize_rrn("RRN-00000042").value_or(""), "RRN-000000000042");
  EXPECT_FALSE(normalize_rrn("RRN-1").has_value());
  EXPECT_FALSE(normalize_rrn("RRN-B_-000000000001").has_value());
  EXPECT_FALSE(normalize_rrn("XRN-000000000042").has_value());
  EXPECT_FALSE(normalize_rrn("").has_value());
}

TEST(RegistryProof, BothSignaturesVerifyAndAnyChangeIsRefused) {
  auto k = keys::generate();
  ASSERT_TRUE(k.ok()) << k.error().message;
  const std::string ed = base64url_encode(k->pub.ed25519_pk);
  const std::string ml = base64url_encode(k->pub.mldsa65_pk);
  const std::string msg = proof_message("c1", "n1", "acme", "arm", "v2", "unit-1");
  EXPECT_EQ(msg, "rcan-registry-pop:c1:n1:acme/arm/v2/unit-1");
  auto p = sign_proof(*k, "c1", msg);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_TRUE(verify_proof(ed, ml, msg, *p).ok());

  // Either key alone is a proof of that key.
  EXPECT_TRUE(verify_proof(ed, "", msg, *p).ok());
  EXPECT_TRUE(verify_proof("", ml, msg, *p).ok());
  auto none = verify_proof("", "", msg, *p);
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.error().reason, "no_keys");

  // Another robot's message, another key, a tampered signature, garbage.
  const std::string other = proof_message("c1", "n1", "acme", "arm", "v2", "unit-2");
  auto s = verify_proof(ed, ml, other, *p);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "proof.ed25519_sig");
  auto k2 = keys::generate();
  ASSERT_TRUE(k2.ok());
  s = verify_proof(ed, base64url_encode(k2->pub.mldsa65_pk), msg, *p);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "proof.mldsa65_sig");
  Proof t = *p;
  t.mldsa65_sig[10] = t.mldsa65_sig[10] == 'A' ? 'B' : 'A';
  EXPECT_FALSE(verify_proof(ed, ml, msg, t).ok());
  t = *p;
  t.ed25519_sig = "not base64url!";
  EXPECT_FALSE(verify_proof(ed, ml, msg, t).ok());
  EXPECT_EQ(verify_proof("AAAA", ml, msg, *p).error().field, "ed25519_public_key");
  EXPECT_EQ(verify_proof(ed, "AAAA", msg, *p).error().reason, "bad_key");
  t = *p;
  t.mldsa65_sig.clear();
  EXPECT_EQ(verify_proof(ed, ml, msg, t).error().reason, "missing_signature");
}

}  // namespace
}  // namespace rcan::registry
