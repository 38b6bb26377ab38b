// Roles, scopes, the seed §2.2 matrix with the profile's resolutions, limits and TTLs.
#include "rcan/roles.h"

#include <gtest/gtest.h>

namespace rcan {
namespace {

TEST(Roles, NamesLevelsAndClaimForms) {
  EXPECT_EQ(role_level(Role::kCreator), 5);
  EXPECT_EQ(role_level(Role::kGuest), 1);
  EXPECT_EQ(role_from_name("owner"), Role::kOwner);
  EXPECT_EQ(role_from_name("LEASEE"), Role::kLeasee);
  EXPECT_EQ(role_from_name("admin"), std::nullopt);
  EXPECT_EQ(role_from_name("operator"), std::nullopt);
  EXPECT_EQ(role_from_rcan_level(1), Role::kGuest);
  EXPECT_EQ(role_from_rcan_level(2), Role::kUser);
  EXPECT_EQ(role_from_rcan_level(2.5), Role::kUser);
  EXPECT_EQ(role_from_rcan_level(3), Role::kOwner);
  EXPECT_EQ(role_from_rcan_level(5), Role::kCreator);
  EXPECT_EQ(role_from_rcan_level(4), std::nullopt);
  EXPECT_EQ(role_from_rcan_level(6), std::nullopt);
  EXPECT_EQ(role_from_rcan_level(0), std::nullopt);
}

TEST(CapabilityMatrix, SeedCellsExactly) {
  using C = Capability;
  using A = Access;
  // Spot-check every row against seed §2.2 (columns Creator, Owner, Leasee, User, Guest).
  struct Row {
    C cap;
    A creator, owner, leasee, user, guest;
  };
  const Row rows[] = {
      {C::kViewStatus, A::kFull, A::kFull, A::kFull, A::kFull, A::kFull},
      {C::kChat, A::kFull, A::kFull, A::kFull, A::kFull, A::kFull},
      {C::kTeleop, A::kFull, A::kFull, A::kFull, A::kFull, A::kNone},
      {C::kArm, A::kFull, A::kFull, A::kFull, A::kConditional, A::kNone},
      {C::kNavigation, A::kFull, A::kFull, A::kFull, A::kFull, A::kNone},
      {C::kRecordEpisodes, A::kFull, A::kFull, A::kFull, A::kConditional, A::kNone},
      {C::kTrainingContribute, A::kFull, A::kFull, A::kConditional, A::kNone, A::kNone},
      {C::kInstallSkills, A::kFull, A::kFull, A::kNone, A::kNone, A::kNone},
      {C::kOtaUpdates, A::kFull, A::kFull, A::kNone, A::kNone, A::kNone},
      {C::kSafetyConfig, A::kFull, A::kConditional, A::kNone, A::kNone, A::kNone},
      {C::kUserManagement, A::kFull, A::kFull, A::kConditional, A::kNone, A::kNone},
      {C::kModelDeployment, A::kFull, A::kNone, A::kNone, A::kNone, A::kNone},
      {C::kHardwareDiagnostics, A::kFull, A::kFull, A::kConditional, A::kNone, A::kNone},
  };
  for (const auto& r : rows) {
    SCOPED_TRACE(std::string(capability_name(r.cap)));
    EXPECT_EQ(matrix_cell(Role::kCreator, r.cap), r.creator);
    EXPECT_EQ(matrix_cell(Role::kOwner, r.cap), r.owner);
    EXPECT_EQ(matrix_cell(Role::kLeasee, r.cap), r.leasee);
    EXPECT_EQ(matrix_cell(Role::kUser, r.cap), r.user);
    EXPECT_EQ(matrix_cell(Role::kGuest, r.cap), r.guest);
  }
}

TEST(CapabilityMatrix, ConditionalCellsResolveByPolicy) {
  RolePolicy none;
  EXPECT_FALSE(role_allows(Role::kUser, Capability::kArm, none));
  EXPECT_FALSE(role_allows(Role::kUser, Capability::kRecordEpisodes, none));
  EXPECT_TRUE(role_allows(Role::kUser, Capability::kTeleop, none));
  EXPECT_TRUE(role_allows(Role::kUser, Capability::kNavigation, none));
  EXPECT_TRUE(role_allows(Role::kLeasee, Capability::kArm, none));
  EXPECT_FALSE(role_allows(Role::kLeasee, Capability::kTrainingContribute, none));
  EXPECT_FALSE(role_allows(Role::kLeasee, Capability::kHardwareDiagnostics, none));
  EXPECT_TRUE(role_allows(Role::kLeasee, Capability::kUserManagement, none));
  EXPECT_FALSE(role_allows(Role::kOwner, Capability::kSafetyConfig, none));
  RolePolicy granted{true, true, true, true, true};
  EXPECT_TRUE(role_allows(Role::kUser, Capability::kArm, granted));
  EXPECT_TRUE(role_allows(Role::kUser, Capability::kRecordEpisodes, granted));
  EXPECT_TRUE(role_allows(Role::kLeasee, Capability::kTrainingContribute, granted));
  EXPECT_TRUE(role_allows(Role::kLeasee, Capability::kHardwareDiagnostics, granted));
  EXPECT_TRUE(role_allows(Role::kOwner, Capability::kSafetyConfig, granted));
  // A grant never reaches a role the seed marks ❌.
  EXPECT_FALSE(role_allows(Role::kGuest, Capability::kArm, granted));
  EXPECT_FALSE(role_allows(Role::kOwner, Capability::kModelDeployment, granted));
}

TEST(Scopes, MinimumRoles) {
  EXPECT_EQ(scope_min_role("status"), Role::kGuest);
  EXPECT_EQ(scope_min_role("chat"), Role::kGuest);
  EXPECT_EQ(scope_min_role("control"), Role::kUser);
  EXPECT_EQ(scope_min_role("config"), Role::kOwner);
  EXPECT_EQ(scope_min_role("training"), Role::kOwner);
  EXPECT_EQ(scope_min_role("admin"), Role::kCreator);
  EXPECT_EQ(scope_min_role("safety"), Role::kCreator);
  EXPECT_EQ(scope_min_role("bogus"), std::nullopt);
}

TEST(Authorize, GuestControlIsInsufficientPrivileges) {
  Status s = authorize(Role::kGuest, {"control"}, Capability::kNavigation);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::kInsufficientPrivileges);
  EXPECT_NE(s.error().message.find("GUEST may not use scope control"), std::string::npos);
}

TEST(Authorize, ScopeRoleAndMatrixAllApply) {
  EXPECT_TRUE(authorize(Role::kUser, {"control"}, Capability::kNavigation).ok());
  EXPECT_FALSE(authorize(Role::kUser, {"status"}, Capability::kNavigation).ok());  // scope missing
  EXPECT_FALSE(authorize(Role::kUser, {"control"}, Capability::kArm).ok());  // matrix ⚙ not granted
  EXPECT_TRUE(authorize(Role::kUser, {"control"}, Capability::kArm, RolePolicy{true}).ok());
  EXPECT_TRUE(authorize(Role::kGuest, {}, Capability::kViewStatus).ok());  // status is implied
  EXPECT_FALSE(authorize(Role::kOwner, {"config"}, Capability::kModelDeployment).ok());
  EXPECT_TRUE(authorize(Role::kCreator, {"deploy"}, Capability::kModelDeployment).ok());
  EXPECT_FALSE(authorize(Role::kLeasee, {"config"}, Capability::kInstallSkills).ok());
}

TEST(Limits, RatesAndTtls) {
  EXPECT_EQ(rate_limit_per_minute(Role::kGuest), 10u);
  EXPECT_EQ(rate_limit_per_minute(Role::kUser), 100u);
  EXPECT_EQ(rate_limit_per_minute(Role::kLeasee), 500u);
  EXPECT_EQ(rate_limit_per_minute(Role::kOwner), 1000u);
  EXPECT_EQ(rate_limit_per_minute(Role::kCreator), 0u);
  EXPECT_EQ(session_ttl_seconds(Role::kGuest), 900u);
  EXPECT_EQ(session_ttl_seconds(Role::kUser), 3600u);
  EXPECT_EQ(session_ttl_seconds(Role::kLeasee), 7200u);
  EXPECT_EQ(session_ttl_seconds(Role::kOwner), 28800u);
  EXPECT_EQ(session_ttl_seconds(Role::kCreator), 0u);
  GuestLimits g;
  EXPECT_EQ(g.chat_per_minute, 10u);
  EXPECT_EQ(g.query_per_minute, 30u);
  EXPECT_EQ(g.concurrent_sessions, 3u);
}

}  // namespace
}  // namespace rcan
