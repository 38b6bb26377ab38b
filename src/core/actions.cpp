// The action table (rcan/actions.h).
#include "rcan/actions.h"

#include <cctype>
#include <cstdlib>

#include "base/strings.h"
#include "rcan/errors.h"

namespace rcan {
namespace {

using K = ActionKind;
using C = Capability;

// Every action name a node accepts. Drive actions keep the capability the reference server's
// prefix map gave them (move/drive/goto → navigation; teleop, turns → teleop); an action that
// moves the arm or the gripper is `arm`, whatever it is called.
ActionTable make_builtin() {
  const std::vector<ActionSpec> rows = {
      // Informational: answered from the robot's state.
      {"status", C::kViewStatus, K::kInformational, "status_read", {"get_status"}},
      {"query", C::kViewStatus, K::kInformational, "basic_info", {"info", "basic_info"}},
      {"chat", C::kChat, K::kInformational, "chat_text", {"ask"}},
      // Base motion: velocity for a duration.
      {"move", C::kNavigation, K::kDrive, "control", {"drive", "goto", "navigate", "nav"}},
      {"move_forward", C::kNavigation, K::kDrive, "control", {"forward"}},
      {"move_backward", C::kNavigation, K::kDrive, "control", {"backward", "reverse"}},
      {"teleop", C::kTeleop, K::kDrive, "control", {}},
      {"turn_left", C::kTeleop, K::kDrive, "control", {}},
      {"turn_right", C::kTeleop, K::kDrive, "control", {}},
      {"rotate", C::kTeleop, K::kDrive, "control", {"turn"}},
      // The arm and its gripper.
      {"arm_move",
       C::kArm,
       K::kArm,
       "control",
       {"arm", "move_arm", "arm_joints", "set_joints", "joints", "joint_move", "move_joints"}},
      {"arm_home", C::kArm, K::kArm, "control", {"home_arm"}},
      {"gripper_open",
       C::kArm,
       K::kGripper,
       "control",
       {"open_gripper", "release_grip", "release"}},
      {"gripper_close", C::kArm, K::kGripper, "control", {"close_gripper", "grip", "grasp"}},
      // Skills named by the spec's conformance cases, robot profiles and the SDKs' examples. A
      // node knows what they address; the driver says whether it can do them.
      {"pick_object", C::kArm, K::kSkill, "control", {"pick"}},
      {"place_object", C::kArm, K::kSkill, "control", {"place"}},
      {"arm_extend", C::kArm, K::kSkill, "control", {}},
      {"arm_deploy", C::kArm, K::kSkill, "control", {}},
      {"program_run", C::kArm, K::kSkill, "control", {}},
      {"navigate_to_waypoint", C::kNavigation, K::kSkill, "control", {"go_to_waypoint"}},
      {"nav_goal", C::kNavigation, K::kSkill, "control", {}},
      {"waypoint_mission", C::kNavigation, K::kSkill, "control", {}},
      {"dock", C::kNavigation, K::kSkill, "control", {"return_to_dock"}},
      {"stair_climb", C::kNavigation, K::kSkill, "control", {}},
      {"outdoor_traverse", C::kNavigation, K::kSkill, "control", {}},
      {"scan_environment", C::kTeleop, K::kSkill, "control", {"scan"}},
  };
  ActionTable t;
  for (const auto& r : rows) {
    Status s = t.add(r);
    if (!s.ok()) std::abort();  // a duplicate in the table above: a build-time mistake
  }
  return t;
}

}  // namespace

std::string_view action_kind_name(ActionKind k) {
  switch (k) {
    case ActionKind::kInformational:
      return "informational";
    case ActionKind::kDrive:
      return "drive";
    case ActionKind::kArm:
      return "arm";
    case ActionKind::kGripper:
      return "gripper";
    case ActionKind::kSkill:
      return "skill";
  }
  return "skill";
}

const ActionTable& ActionTable::builtin() {
  static const ActionTable table = make_builtin();
  return table;
}

const ActionSpec* ActionTable::find(std::string_view name) const {
  if (name.empty() || name.size() > 128) return nullptr;
  std::string n = ascii_lower(name);
  for (const auto& e : entries_) {
    if (e.name == n) return &e;
    for (const auto& s : e.synonyms)
      if (s == n) return &e;
  }
  return nullptr;
}

Status ActionTable::add(ActionSpec spec) {
  spec.name = ascii_lower(spec.name);
  for (auto& s : spec.synonyms) s = ascii_lower(s);
  std::vector<std::string> names = spec.synonyms;
  names.push_back(spec.name);
  for (const auto& n : names) {
    if (n.empty())
      return Error(ErrorCode::kSchemaValidationFailed, "an action name is empty", "action");
    if (const ActionSpec* other = find(n))
      return Error(ErrorCode::kSchemaValidationFailed,
                   "action name '" + n + "' already names '" + other->name + "'", "action");
  }
  entries_.push_back(std::move(spec));
  return Status::Ok();
}

const ActionSpec* find_action(std::string_view name) { return ActionTable::builtin().find(name); }

}  // namespace rcan
