// The action table: every accepted name, synonyms folded, one capability each; unknown names
// are not defaulted (rcan/actions.h).
#include "rcan/actions.h"

#include <gtest/gtest.h>

#include <set>
#include <string>

namespace rcan {
namespace {

TEST(Actions, SynonymsFoldIntoOneCanonicalActionWithOneCapability) {
  struct Case {
    const char* sent;
    const char* canonical;
    Capability cap;
    ActionKind kind;
  };
  const Case cases[] = {
      {"set_joints", "arm_move", Capability::kArm, ActionKind::kArm},
      {"SET_JOINTS", "arm_move", Capability::kArm, ActionKind::kArm},
      {"joint_move", "arm_move", Capability::kArm, ActionKind::kArm},
      {"arm", "arm_move", Capability::kArm, ActionKind::kArm},
      {"arm_move", "arm_move", Capability::kArm, ActionKind::kArm},
      {"arm_home", "arm_home", Capability::kArm, ActionKind::kArm},
      {"grip", "gripper_close", Capability::kArm, ActionKind::kGripper},
      {"release_grip", "gripper_open", Capability::kArm, ActionKind::kGripper},
      {"open_gripper", "gripper_open", Capability::kArm, ActionKind::kGripper},
      {"drive", "move", Capability::kNavigation, ActionKind::kDrive},
      {"move_forward", "move_forward", Capability::kNavigation, ActionKind::kDrive},
      {"teleop", "teleop", Capability::kTeleop, ActionKind::kDrive},
      {"turn", "rotate", Capability::kTeleop, ActionKind::kDrive},
      {"status", "status", Capability::kViewStatus, ActionKind::kInformational},
      {"get_status", "status", Capability::kViewStatus, ActionKind::kInformational},
      {"ask", "chat", Capability::kChat, ActionKind::kInformational},
      {"pick_object", "pick_object", Capability::kArm, ActionKind::kSkill},
      {"arm_extend", "arm_extend", Capability::kArm, ActionKind::kSkill},
      {"navigate_to_waypoint", "navigate_to_waypoint", Capability::kNavigation, ActionKind::kSkill},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.sent);
    const ActionSpec* a = find_action(c.sent);
    ASSERT_NE(a, nullptr);
    EXPECT_EQ(a->name, c.canonical);
    EXPECT_EQ(a->capability, c.cap);
    EXPECT_EQ(a->kind, c.kind);
  }
}

TEST(Actions, UnknownNamesAreNotDefaultedToAnyCapability) {
  // The old prefix map sent these to teleop (or guessed from a prefix); now they name nothing.
  for (const char* n : {"wave", "arm_wrestle", "joint_venture", "nav_to", "fly_to_the_moon",
                        "deploy_model", "update_firmware", "", " move", "move ", "mov"}) {
    EXPECT_EQ(find_action(n), nullptr) << n;
  }
  EXPECT_EQ(find_action(std::string(4096, 'a')), nullptr);
}

TEST(Actions, EveryNameNamesExactlyOneActionAndEveryMotionNeedsControl) {
  std::set<std::string> seen;
  for (const auto& a : ActionTable::builtin().entries()) {
    EXPECT_TRUE(seen.insert(a.name).second) << a.name;
    for (const auto& s : a.synonyms) EXPECT_TRUE(seen.insert(s).second) << s;
    if (a.kind != ActionKind::kInformational) {
      EXPECT_EQ(capability_scope(a.capability), "control") << a.name;
      EXPECT_EQ(a.guest_class, "control") << a.name;
    }
    // Whatever moves the arm or its gripper is the arm capability (user_arm governs it).
    if (a.kind == ActionKind::kArm || a.kind == ActionKind::kGripper) {
      EXPECT_EQ(a.capability, Capability::kArm) << a.name;
    }
  }
}

TEST(Actions, ADriversSkillCannotTakeANameAlreadyTaken) {
  ActionTable t = ActionTable::builtin();
  EXPECT_FALSE(t.add({"wave", Capability::kTeleop, ActionKind::kSkill, "control", {"grip"}}).ok());
  EXPECT_FALSE(t.add({"SET_JOINTS", Capability::kTeleop, ActionKind::kSkill, "control", {}}).ok());
  EXPECT_FALSE(t.add({"", Capability::kTeleop, ActionKind::kSkill, "control", {}}).ok());
  ASSERT_TRUE(t.add({"Wave", Capability::kTeleop, ActionKind::kSkill, "control", {"hello"}}).ok());
  ASSERT_NE(t.find("HELLO"), nullptr);
  EXPECT_EQ(t.find("hello")->name, "wave");
  EXPECT_EQ(find_action("wave"), nullptr);  // the built-in table is unchanged
}

}  // namespace
}  // namespace rcan
