// Command actions: the one table that says what every accepted action name means
// (docs/PROTOCOL.md §Actions). A COMMAND's `action` (or `command`, `action_type`) is looked up
// here, case-insensitively, synonyms folded into one canonical action; that action decides the
// capability that RBAC checks, the HiTL and confidence gates that match, the guest-limit class,
// the name in the audit record, and what the driver is asked to do. A name not in the table is
// refused for every role — never defaulted to some capability. Pure tables: no I/O.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/roles.h"

namespace rcan {

// What the robot does with an action.
enum class ActionKind : uint8_t {
  kInformational,  // answered from the robot's state (status, query, chat); moves nothing
  kDrive,          // base velocity for a duration
  kArm,            // joint targets
  kGripper,        // open / close
  kSkill,          // a named behaviour (pick_object, nav_goal…) a driver may or may not offer
};
std::string_view action_kind_name(ActionKind k);  // "drive", "arm", …

struct ActionSpec {
  std::string name;  // canonical, lower case
  Capability capability;
  ActionKind kind;
  // Seed §6.3 guest-limit class: status_read, basic_info, chat_text, control.
  std::string guest_class;
  std::vector<std::string> synonyms;  // lower case; each names this action and no other
};

class ActionTable {
 public:
  // The actions every node knows: the simulated robot's drive, arm, gripper and informational
  // actions, and the skills the spec and the SDKs name (docs/PROTOCOL.md §Actions).
  static const ActionTable& builtin();

  // The entry `name` (any case, canonical or synonym) names; nullptr when none does.
  const ActionSpec* find(std::string_view name) const;
  // Adds an action (a driver's own skill). Errors: SCHEMA_VALIDATION_FAILED when its name or
  // a synonym is empty or already names an action.
  Status add(ActionSpec spec);
  std::span<const ActionSpec> entries() const { return entries_; }

 private:
  std::vector<ActionSpec> entries_;
};

// ActionTable::builtin().find(name).
const ActionSpec* find_action(std::string_view name);

}  // namespace rcan
