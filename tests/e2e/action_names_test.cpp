// Action names against a real rcand (docs/SECURITY.md R2): a lower role tries every name the
// action table knows — and names it does not — and nothing moves that the role may not move.
// The capability comes from the canonical action, never from how the name happens to begin.
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "rcan/actions.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

using test::HttpReply;
using Headers = std::vector<std::pair<std::string, std::string>>;

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

std::string owner_token(const test::RcandDaemon& d) {
  std::string t = test::read_file(d.owner_token_file());
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r')) t.pop_back();
  return t;
}

json::Value parse(const std::string& s) {
  auto v = json::parse(s);
  return v.ok() ? *v : json::Value();
}

// A COMMAND naming `action`, carrying parameters for every kind of action at once: joints for
// an arm, a short drive for a base.
std::string command(const std::string& id, const std::string& action) {
  json::Object payload{{"action", action},
                       {"joints", json::Array{0.4, 0.3, -0.2, 0.1, 0.2, 0.3}},
                       {"linear", 0.05},
                       {"duration_ms", 50}};
  return json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                             {"message_id", id},
                                             {"type", "COMMAND"},
                                             {"timestamp_ms", now_ms()},
                                             {"payload", payload}}));
}

std::string error_code(const HttpReply& r) {
  const json::Value v = parse(r.body);
  const json::Value* c = v.is_object() ? v.get("payload") : nullptr;
  c = c && c->is_object() ? c->get("error_code") : nullptr;
  return c && c->is_string() ? c->as_string() : "";
}

// The arm's joint targets and the gripper, as the robot reports them.
std::string arm_state(const test::RcandDaemon& d, const std::string& owner) {
  HttpReply st = test::http(d.port(), "GET", "/rcan/v1/status", "", bearer(owner));
  json::Value v = parse(st.body);
  if (!v.is_object()) return "no robot state in " + st.body;
  const json::Value* robot = v.get("robot");
  robot = robot ? robot->get("robot") : nullptr;
  if (!robot) return "no robot state in " + st.body;
  return json::dump(*robot->get("arm")->get("targets_rad")) + json::dump(*robot->get("gripper"));
}

// Every name the table accepts: canonical names and synonyms, in the case a client might send.
std::vector<std::pair<std::string, const ActionSpec*>> every_name() {
  std::vector<std::pair<std::string, const ActionSpec*>> out;
  for (const auto& a : ActionTable::builtin().entries()) {
    out.emplace_back(a.name, &a);
    for (const auto& s : a.synonyms) out.emplace_back(s, &a);
  }
  out.emplace_back("SET_JOINTS", find_action("set_joints"));
  out.emplace_back("Grip", find_action("grip"));
  return out;
}

// The reproduction: USER (rbac.grants.user_arm off, the default) sends set_joints and used to
// get 200 ACK with the arm moving, while "arm" got 403.
TEST(ActionNames, AUserCannotMoveTheArmByAnyName) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string owner = owner_token(d);
  const std::string user = d.token("user", {"status", "control"}, "user-1");
  const std::string before = arm_state(d, owner);
  ASSERT_EQ(before.find("no robot"), std::string::npos) << before;

  HttpReply r = test::http(d.port(), "POST", "/rcan/v1/command",
                           command(new_uuid_v4(), "set_joints"), bearer(user));
  EXPECT_EQ(r.status, 403) << r.body;
  EXPECT_EQ(error_code(r), "INSUFFICIENT_PRIVILEGES") << r.body;

  for (const auto& [name, spec] : every_name()) {
    if (spec->capability != Capability::kArm) continue;
    HttpReply a = test::http(d.port(), "POST", "/rcan/v1/command", command(new_uuid_v4(), name),
                             bearer(user));
    EXPECT_EQ(a.status, 403) << name << ": " << a.body;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // a few control ticks
  EXPECT_EQ(arm_state(d, owner), before) << "the arm or gripper moved for a USER";
}

// A GUEST tries every name: every one that acts is refused; names the table does not hold are
// refused as unknown for every role, OWNER included — never defaulted to a capability.
TEST(ActionNames, EveryNameIsCheckedAgainstItsOwnCapabilityAndUnknownNamesAreRefused) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string owner = owner_token(d);
  const std::string guest = d.token("guest", {"status", "chat"}, "guest-1");
  const std::string leasee = d.token("leasee", {"status", "control"}, "leasee-1");
  const std::string before = arm_state(d, owner);
  for (const auto& [name, spec] : every_name()) {
    if (spec->kind == ActionKind::kInformational) continue;
    HttpReply g = test::http(d.port(), "POST", "/rcan/v1/command", command(new_uuid_v4(), name),
                             bearer(guest));
    EXPECT_EQ(g.status, 403) << name << ": " << g.body;
  }
  EXPECT_EQ(arm_state(d, owner), before);
  for (const char* name :
       {"wave", "arm_wrestle", "joint_venture", "set_joints2", "fly_to_the_moon", "deploy_model"}) {
    for (const std::string* tok : {&guest, &leasee, &owner}) {
      HttpReply u = test::http(d.port(), "POST", "/rcan/v1/command", command(new_uuid_v4(), name),
                               bearer(*tok));
      EXPECT_EQ(u.status, 422) << name << ": " << u.body;
      EXPECT_EQ(error_code(u), "COMMAND_REJECTED") << u.body;
      EXPECT_NE(u.body.find("unknown_action"), std::string::npos) << u.body;
    }
  }
  EXPECT_EQ(arm_state(d, owner), before);
  // A LEASEE may move the arm, by any of its names; the record names the canonical action and
  // what was sent.
  const std::string id = new_uuid_v4();
  HttpReply ok =
      test::http(d.port(), "POST", "/rcan/v1/command", command(id, "set_joints"), bearer(leasee));
  ASSERT_EQ(ok.status, 200) << ok.body;
  bool moved = false;  // the probe sees an arm that moves
  for (int i = 0; i < 50 && !moved; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    moved = arm_state(d, owner) != before;
  }
  EXPECT_TRUE(moved);
  HttpReply audit = test::http(d.port(), "GET", "/api/audit?limit=1000", "", bearer(owner));
  ASSERT_EQ(audit.status, 200) << audit.body;
  bool found = false;
  const json::Value listing = parse(audit.body);
  ASSERT_TRUE(listing.is_object() && listing.get("entries")) << audit.body;
  for (const auto& e : listing.get("entries")->as_array()) {
    if (e.get("message_id") && e.get("message_id")->as_string() == id &&
        e.get("event")->as_string() == "COMMAND") {
      found = true;
      EXPECT_EQ(e.get("action")->as_string(), "arm_move") << json::dump(e);
      ASSERT_TRUE(e.get("detail")) << json::dump(e);
      EXPECT_EQ(e.get("detail")->get("action_sent")->as_string(), "set_joints");
    }
  }
  EXPECT_TRUE(found);
}

}  // namespace
}  // namespace rcan
