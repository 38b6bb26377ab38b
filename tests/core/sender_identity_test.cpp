// §8.5 sender identity rules.
#include "rcan/sender_identity.h"

#include <gtest/gtest.h>

namespace rcan {
namespace {

Message msg(SenderType st = SenderType::kHuman, bool explicit_type = false) {
  Message m;
  m.sender_type = st;
  m.sender_type_explicit = explicit_type;
  return m;
}

TEST(SenderIdentity, HumanByDefaultWithTheTokenSubject) {
  TokenIdentity t{"user-1", {}, {}, {}};
  auto id = resolve_sender(msg(), t, false);
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(id->sender_type, SenderType::kHuman);
  EXPECT_EQ(id->sub, "user-1");
}

TEST(SenderIdentity, TokenClaimingCloudFunctionWithoutProviderIsAuthInvalid) {
  TokenIdentity t{"firebase-cloud-functions", "cloud_function", {}, {}};
  Status s = check_token_sender_claims(t);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::kAuthInvalid);
  auto id = resolve_sender(msg(), t, false);
  ASSERT_FALSE(id.ok());
  EXPECT_EQ(id.error().code, ErrorCode::kAuthInvalid);
}

TEST(SenderIdentity, SilentEnvelopeTakesTheTokensCloudIdentity) {
  TokenIdentity t{"firebase-cloud-functions", "cloud_function", "firebase", "castor-bridge-v2"};
  auto id = resolve_sender(msg(), t, false);
  ASSERT_TRUE(id.ok()) << id.error().message;
  EXPECT_EQ(id->sender_type, SenderType::kCloudFunction);
  EXPECT_EQ(id->cloud_provider, "firebase");
  EXPECT_EQ(id->function_name, "castor-bridge-v2");
}

TEST(SenderIdentity, EnvelopeContradictingTheTokenIsRefused) {
  TokenIdentity t{"svc", "cloud_function", "firebase", "f"};
  auto id = resolve_sender(msg(SenderType::kHuman, true), t, false);
  ASSERT_FALSE(id.ok());
  EXPECT_EQ(id.error().code, ErrorCode::kInsufficientPrivileges);
  Message m = msg(SenderType::kCloudFunction, true);
  m.cloud_provider = "aws_lambda";
  m.function_name = "f";
  id = resolve_sender(m, t, false);
  ASSERT_FALSE(id.ok());
  EXPECT_EQ(id.error().field, "cloud_provider");
}

TEST(SenderIdentity, CloudFunctionWithoutFunctionNameAnywhereIsRefused) {
  TokenIdentity t{"svc", "cloud_function", "firebase", {}};
  auto id = resolve_sender(msg(), t, false);
  ASSERT_FALSE(id.ok());
  EXPECT_EQ(id.error().field, "function_name");
}

TEST(SenderIdentity, RobotKeyMeansRobotAndRobotNeedsKeyAndChain) {
  TokenIdentity t{"peer", {}, {}, {}};
  auto id = resolve_sender(msg(SenderType::kHuman, true), t, true);
  ASSERT_FALSE(id.ok());  // signed by a robot key but claims human
  Message r = msg(SenderType::kRobot, true);
  id = resolve_sender(r, t, false);
  ASSERT_FALSE(id.ok());  // robot without a robot signature
  EXPECT_EQ(id.error().code, ErrorCode::kAuthInvalid);
  id = resolve_sender(r, t, true);
  ASSERT_FALSE(id.ok());  // robot without a delegation chain
  EXPECT_EQ(id.error().code, ErrorCode::kMissingDelegationChain);
  r.delegation_chain =
      json::Array{json::Object{{"issuer_ruri", "rcan://local.rcan/a1/b1/12345678"}}};
  id = resolve_sender(r, t, true);
  ASSERT_TRUE(id.ok()) << id.error().message;
  EXPECT_EQ(id->sender_type, SenderType::kRobot);
}

TEST(SenderIdentity, SystemIsReservedForTheNodeItself) {
  TokenIdentity t{"x", {}, {}, {}};
  EXPECT_FALSE(resolve_sender(msg(SenderType::kSystem, true), t, false, true).ok());
  EXPECT_TRUE(resolve_sender(msg(SenderType::kSystem, true), t, false, false).ok());
}

TEST(SenderIdentity, UnknownTokenSenderTypeIsAuthInvalid) {
  TokenIdentity t{"x", "service", {}, {}};
  EXPECT_EQ(check_token_sender_claims(t).error().code, ErrorCode::kAuthInvalid);
}

}  // namespace
}  // namespace rcan
