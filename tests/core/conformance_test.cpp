// The format, rbac and schema cases of the RCAN conformance suite v1.3
// (tests/vectors/rcan-conformance-v1.3.json), run against the library.
// The discovery, audit, safety, gate and HiTL cases need the node and run in its tests.
#include <gtest/gtest.h>

#include "rcan/actions.h"
#include "rcan/errors.h"
#include "rcan/message.h"
#include "rcan/roles.h"
#include "rcan/ruri.h"
#include "test_support.h"

namespace rcan {
namespace {

TEST(ConformanceV13, FormatRbacAndSchemaCases) {
  json::Value suite = test::load_vector("rcan-conformance-v1.3.json");
  int ran = 0;
  for (const auto& level : suite.get("levels")->as_object()) {
    for (const auto& t : level.second.as_array()) {
      const std::string& id = t.get("id")->as_string();
      const std::string& type = t.get("test_type")->as_string();
      const json::Value& in = *t.get("input");
      const json::Value& expect = *t.get("expect");
      SCOPED_TRACE(id);
      if (type == "format") {
        auto r = parse_ruri(in.get("ruri")->as_string());
        EXPECT_EQ(r.ok(), expect.get("valid")->as_bool());
        if (!r.ok()) {
          EXPECT_EQ(error_name(r.error().code), expect.get("error_code")->as_string());
          EXPECT_EQ(r.error().message, expect.get("reason")->as_string());
        }
        ++ran;
      } else if (type == "rbac") {
        auto role = role_from_name(in.get("principal_role")->as_string());
        ASSERT_TRUE(role.has_value());
        std::vector<std::string> scopes{in.get("scope")->as_string()};
        const ActionSpec* action = find_action(in.get("payload")->get("action")->as_string());
        ASSERT_NE(action, nullptr);
        Status s = authorize(*role, scopes, action->capability);
        EXPECT_EQ(s.ok(), expect.get("allowed")->as_bool());
        ASSERT_FALSE(s.ok());
        EXPECT_EQ(http_status(s.error().code), expect.get("http_status")->as_int());
        EXPECT_EQ(error_name(s.error().code), expect.get("error_code")->as_string());
        ++ran;
      } else if (type == "schema") {
        Status s = check_shape(*in.get("message"));
        EXPECT_EQ(s.ok(), expect.get("valid")->as_bool());
        ASSERT_FALSE(s.ok());
        EXPECT_EQ(error_name(s.error().code), expect.get("error_code")->as_string());
        json::Value body = error_body(s.error(), "", 0);
        EXPECT_EQ(body.get("payload")->get("detail")->get("missing_field")->as_string(),
                  expect.get("missing_field")->as_string());
        // The full decoder agrees.
        auto m = decode_message(*in.get("message"));
        ASSERT_FALSE(m.ok());
        EXPECT_EQ(m.error().field, "payload");
        ++ran;
      }
    }
  }
  EXPECT_EQ(ran, 5);  // RURI-001/002/003, RBAC-001, SCHEMA-001
}

}  // namespace
}  // namespace rcan
