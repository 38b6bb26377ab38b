// Runs scripts/demo-ai.sh (the README's §16 demo) against the built binaries: the demo must
// actually work. The script fails on any unexpected answer; its output is checked for each act.
#include <gtest/gtest.h>

#include <string>

#include "test_support.h"

namespace rcan {
namespace {

TEST(DemoAi, TheReadmeDemoRunsEndToEnd) {
  std::string script = std::string(RCAN_VECTORS_DIR) + "/../../scripts/demo-ai.sh";
  std::string rcand = RCAND_PATH;
  std::string bin = rcand.substr(0, rcand.rfind('/'));
  auto r = test::run({"/bin/bash", script, bin});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  for (const char* want :
       {"CONFIDENCE_GATE_ESCALATED blocked", "COMMAND ok", "no_higher_layer", "approved ",
        "denied ", "HITL_TIMEOUT blocked", "HITL_AUTHORIZE_REFUSED", "\"valid\":true", "HTTP_404",
        "HTTP_400", "records verified", "demo complete"})
    EXPECT_NE(r.out.find(want), std::string::npos) << want << "\n" << r.out;
}

}  // namespace
}  // namespace rcan
