#include "rcan/roles.h"

#include <algorithm>
#include <array>
#include <cctype>

#include "base/strings.h"

namespace rcan {
namespace {

constexpr std::array<std::string_view, kCapabilityCount> kCapNames{
    "view_status", "chat",          "teleop",          "arm",
    "navigation",  "record",        "training",        "install_skills",
    "ota",         "safety_config", "user_management", "model_deployment",
    "diagnostics"};

using A = Access;
// Rows: capability; columns: GUEST, USER, LEASEE, OWNER, CREATOR (seed §2.2, right to left).
constexpr std::array<std::array<A, 5>, kCapabilityCount> kMatrix{{
    {A::kFull, A::kFull, A::kFull, A::kFull, A::kFull},         // view status
    {A::kFull, A::kFull, A::kFull, A::kFull, A::kFull},         // chat (guest rate-limited)
    {A::kNone, A::kFull, A::kFull, A::kFull, A::kFull},         // teleop
    {A::kNone, A::kConditional, A::kFull, A::kFull, A::kFull},  // arm
    {A::kNone, A::kFull, A::kFull, A::kFull, A::kFull},         // navigation
    {A::kNone, A::kConditional, A::kFull, A::kFull, A::kFull},  // record episodes
    {A::kNone, A::kNone, A::kConditional, A::kFull, A::kFull},  // training contribute
    {A::kNone, A::kNone, A::kNone, A::kFull, A::kFull},         // install skills
    {A::kNone, A::kNone, A::kNone, A::kFull, A::kFull},         // OTA updates
    {A::kNone, A::kNone, A::kNone, A::kConditional, A::kFull},  // safety config
    {A::kNone, A::kNone, A::kConditional, A::kFull, A::kFull},  // user management
    {A::kNone, A::kNone, A::kNone, A::kNone, A::kFull},         // model deployment
    {A::kNone, A::kNone, A::kConditional, A::kFull, A::kFull},  // hardware diagnostics
}};

}  // namespace

std::string_view role_name(Role r) {
  switch (r) {
    case Role::kGuest:
      return "GUEST";
    case Role::kUser:
      return "USER";
    case Role::kLeasee:
      return "LEASEE";
    case Role::kOwner:
      return "OWNER";
    case Role::kCreator:
      return "CREATOR";
  }
  return "GUEST";
}

std::string_view role_claim_name(Role r) {
  switch (r) {
    case Role::kGuest:
      return "guest";
    case Role::kUser:
      return "user";
    case Role::kLeasee:
      return "leasee";
    case Role::kOwner:
      return "owner";
    case Role::kCreator:
      return "creator";
  }
  return "guest";
}

std::optional<Role> role_from_name(std::string_view name) {
  std::string n = ascii_lower(name);
  if (n == "guest") return Role::kGuest;
  if (n == "user") return Role::kUser;
  if (n == "leasee") return Role::kLeasee;
  if (n == "owner") return Role::kOwner;
  if (n == "creator") return Role::kCreator;
  return std::nullopt;
}

std::optional<Role> role_from_rcan_level(double level) {
  if (level == 1.0) return Role::kGuest;
  if (level == 2.0 || level == 2.5) return Role::kUser;
  if (level == 3.0) return Role::kOwner;
  if (level == 5.0) return Role::kCreator;
  return std::nullopt;
}

std::string_view capability_name(Capability c) { return kCapNames[static_cast<size_t>(c)]; }

std::optional<Capability> capability_from_name(std::string_view name) {
  for (size_t i = 0; i < kCapNames.size(); ++i)
    if (kCapNames[i] == name) return static_cast<Capability>(i);
  return std::nullopt;
}

Access matrix_cell(Role r, Capability c) {
  return kMatrix[static_cast<size_t>(c)][static_cast<size_t>(role_level(r) - 1)];
}

bool role_allows(Role r, Capability c, const RolePolicy& policy) {
  Access a = matrix_cell(r, c);
  if (a == Access::kFull) return true;
  if (a == Access::kNone) return false;
  switch (c) {
    case Capability::kArm:
      return r == Role::kUser && policy.user_arm;
    case Capability::kRecordEpisodes:
      return r == Role::kUser && policy.user_record;
    case Capability::kTrainingContribute:
      return r == Role::kLeasee && policy.leasee_training;
    case Capability::kHardwareDiagnostics:
      return r == Role::kLeasee && policy.leasee_diagnostics;
    case Capability::kUserManagement:
      return r == Role::kLeasee;  // within the lease's sessions
    case Capability::kSafetyConfig:
      return r == Role::kOwner && policy.owner_safety_config;
    default:
      return false;
  }
}

std::optional<Role> scope_min_role(std::string_view scope) {
  if (scope == "status" || scope == "chat" || scope == "discover") return Role::kGuest;
  if (scope == "control") return Role::kUser;
  if (scope == "config" || scope == "training") return Role::kOwner;
  if (scope == "safety" || scope == "admin" || scope == "deploy") return Role::kCreator;
  return std::nullopt;
}

std::string_view capability_scope(Capability c) {
  switch (c) {
    case Capability::kViewStatus:
      return "status";
    case Capability::kChat:
      return "chat";
    case Capability::kTeleop:
    case Capability::kArm:
    case Capability::kNavigation:
    case Capability::kRecordEpisodes:
      return "control";
    case Capability::kTrainingContribute:
      return "training";
    case Capability::kInstallSkills:
    case Capability::kOtaUpdates:
    case Capability::kUserManagement:
    case Capability::kHardwareDiagnostics:
      return "config";
    case Capability::kSafetyConfig:
      return "safety";
    case Capability::kModelDeployment:
      return "deploy";
  }
  return "control";
}

uint32_t rate_limit_per_minute(Role r) {
  switch (r) {
    case Role::kGuest:
      return 10;
    case Role::kUser:
      return 100;
    case Role::kLeasee:
      return 500;
    case Role::kOwner:
      return 1000;
    case Role::kCreator:
      return 0;
  }
  return 10;
}

uint32_t session_ttl_seconds(Role r) {
  switch (r) {
    case Role::kGuest:
      return 15 * 60;
    case Role::kUser:
      return 3600;
    case Role::kLeasee:
      return 2 * 3600;
    case Role::kOwner:
      return 8 * 3600;
    case Role::kCreator:
      return 0;
  }
  return 15 * 60;
}

Status authorize(Role role, const std::vector<std::string>& scopes, Capability capability,
                 const RolePolicy& policy) {
  std::string_view needed = capability_scope(capability);
  auto min_role = scope_min_role(needed);
  // status is implied for every authenticated principal (role-implied scope).
  bool has_scope =
      needed == "status" || std::find(scopes.begin(), scopes.end(), needed) != scopes.end();
  if (!has_scope) {
    return Error(ErrorCode::kInsufficientPrivileges,
                 std::string(role_name(role)) + " token lacks scope " + std::string(needed) +
                     " needed for " + std::string(capability_name(capability)),
                 "scope");
  }
  if (min_role && role_level(role) < role_level(*min_role)) {
    return Error(ErrorCode::kInsufficientPrivileges,
                 std::string(role_name(role)) + " may not use scope " + std::string(needed),
                 "scope");
  }
  if (!role_allows(role, capability, policy)) {
    return Error(
        ErrorCode::kInsufficientPrivileges,
        std::string(role_name(role)) + " may not use " + std::string(capability_name(capability)),
        "role");
  }
  return Status::Ok();
}

}  // namespace rcan
