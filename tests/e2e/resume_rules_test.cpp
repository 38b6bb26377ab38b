// Who may clear an ESTOP, against a real rcand (docs/SECURITY.md R12): RESUME re-enables
// motion, so it needs the control scope and a role at least that of whoever latched it (OWNER
// clears any). Before, any LEASEE token — even one holding only `status` — cleared an OWNER's
// ESTOP.
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <vector>

#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

using test::HttpReply;
using Headers = std::vector<std::pair<std::string, std::string>>;

Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

std::string resume_message() {
  const int64_t now = std::chrono::duration_cast<std::chrono::milliseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  return json::dump(
      json::Value(json::Object{{"version", "1.0.0"},
                               {"message_id", new_uuid_v4()},
                               {"type", "SAFETY"},
                               {"timestamp_ms", now},
                               {"payload", json::Object{{"safety_event", "RESUME"}}}}));
}

bool latched(const test::RcandDaemon& d, const std::string& token) {
  HttpReply st = test::http(d.port(), "GET", "/rcan/v1/status", "", bearer(token));
  return st.body.find("\"estop_active\":true") != std::string::npos;
}

TEST(ResumeRules, ClearingAnEstopNeedsControlAndTheRoleThatLatchedIt) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string owner = d.token("owner", {"status", "control", "config"}, "owner-1");
  const std::string leasee_status = d.token("leasee", {"status"}, "leasee-1");
  const std::string leasee = d.token("leasee", {"status", "control"}, "leasee-2");
  const std::string user = d.token("user", {"status", "control"}, "user-1");
  auto resume = [&](const std::string& tok) {
    return test::http(d.port(), "POST", "/rcan/v1/command", resume_message(), bearer(tok));
  };

  ASSERT_EQ(test::http(d.port(), "POST", "/api/stop", "{}", bearer(owner)).status, 200);
  ASSERT_TRUE(latched(d, owner));
  // A LEASEE token with only `status`: no control scope, no RESUME.
  HttpReply r1 = resume(leasee_status);
  EXPECT_EQ(r1.status, 403) << r1.body;
  EXPECT_TRUE(latched(d, owner));
  // A LEASEE with control may not clear what an OWNER latched.
  HttpReply r2 = resume(leasee);
  EXPECT_EQ(r2.status, 403) << r2.body;
  EXPECT_NE(r2.body.find("INSUFFICIENT_PRIVILEGES"), std::string::npos) << r2.body;
  EXPECT_TRUE(latched(d, owner));
  HttpReply r3 = resume(owner);
  EXPECT_EQ(r3.status, 200) << r3.body;
  EXPECT_FALSE(latched(d, owner));

  // A USER's ESTOP: a LEASEE with control clears it; the USER itself may not (LEASEE or above).
  ASSERT_EQ(test::http(d.port(), "POST", "/api/stop", "{}", bearer(user)).status, 200);
  EXPECT_EQ(resume(user).status, 403);
  EXPECT_TRUE(latched(d, owner));
  HttpReply r4 = resume(leasee);
  EXPECT_EQ(r4.status, 200) << r4.body;
  EXPECT_FALSE(latched(d, owner));
}

}  // namespace
}  // namespace rcan
