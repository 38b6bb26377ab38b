// Roles, scopes and the seed §2.2 capability matrix, with the profile's resolutions
// (docs/PROTOCOL.md §Roles). Pure tables: no I/O, no clocks.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/result.h"

namespace rcan {

// Seed §2.1 hierarchy. The numeric value is the level.
enum class Role : uint8_t { kGuest = 1, kUser = 2, kLeasee = 3, kOwner = 4, kCreator = 5 };

std::string_view role_name(Role r);        // "OWNER"
std::string_view role_claim_name(Role r);  // "owner" (JWT `role` claim)
// Seed names, either case ("owner", "OWNER"). nullopt for anything else.
std::optional<Role> role_from_name(std::string_view name);
// rcan-py numeric `rcan_role`: 1 GUEST, 2 and 2.5 USER, 3 OWNER, 5 CREATOR; others nullopt.
std::optional<Role> role_from_rcan_level(double level);
inline int role_level(Role r) { return static_cast<int>(r); }

// Seed §2.2 capabilities (rows of the matrix).
enum class Capability : uint8_t {
  kViewStatus,
  kChat,
  kTeleop,
  kArm,
  kNavigation,
  kRecordEpisodes,
  kTrainingContribute,
  kInstallSkills,
  kOtaUpdates,
  kSafetyConfig,
  kUserManagement,
  kModelDeployment,
  kHardwareDiagnostics,
};
inline constexpr int kCapabilityCount = 13;
std::string_view capability_name(Capability c);  // "arm", "navigation", …
std::optional<Capability> capability_from_name(std::string_view name);

// The matrix cell: ✅ full, ⚙ conditional, ❌ none.
enum class Access : uint8_t { kNone, kConditional, kFull };
Access matrix_cell(Role r, Capability c);

// How the ⚙ cells resolve. Defaults follow the profile: USER gets teleop and navigation,
// not arm or recording unless granted; LEASEE gets arm and recording, training and
// diagnostics only if granted; LEASEE user management is session-scoped (allowed);
// OWNER safety config only when granted (tightening limits is an OWNER config matter).
struct RolePolicy {
  bool user_arm = false;
  bool user_record = false;
  bool leasee_training = false;
  bool leasee_diagnostics = false;
  bool owner_safety_config = false;
};
bool role_allows(Role r, Capability c, const RolePolicy& policy = {});

// Scopes (PROFILE §5): status, chat → GUEST; control → USER; config, training → OWNER;
// safety, admin, deploy → CREATOR.
std::optional<Role> scope_min_role(std::string_view scope);
// The scope a capability needs.
std::string_view capability_scope(Capability c);
// The capability a command action addresses comes from the action table (rcan/actions.h).

// Per-principal limits per minute (0 = unlimited): GUEST 10, USER 100, LEASEE 500,
// OWNER 1000, CREATOR unlimited.
uint32_t rate_limit_per_minute(Role r);
// Session TTL in seconds (0 = none): GUEST 900 (seed §6.3 guest limit, 15 min), USER 3600,
// LEASEE 7200, OWNER 28800, CREATOR none.
uint32_t session_ttl_seconds(Role r);

// Seed §6.3 guest limits.
struct GuestLimits {
  uint32_t chat_per_minute = 10;
  uint32_t query_per_minute = 30;
  uint32_t session_seconds = 15 * 60;
  uint32_t concurrent_sessions = 3;
  std::vector<std::string> capabilities{"status_read", "chat_text", "basic_info"};
  std::vector<std::string> blocked{"control", "camera_access", "location_history"};
};

// Decision of the authorizer: may `role` holding `scopes` use `capability`?
// Error INSUFFICIENT_PRIVILEGES names the missing scope or the matrix cell.
Status authorize(Role role, const std::vector<std::string>& scopes, Capability capability,
                 const RolePolicy& policy = {});

}  // namespace rcan
