// The injection screen of a configured rcand (security.injection, docs/CONFIG.md): configured
// substrings and `{regex: …}` patterns both refuse a command whose text matches, wherever in a
// long string the match lies; a pattern that is not a regular expression stops start-up with
// its path.
#include <gtest/gtest.h>
#include <signal.h>

#include <string>

#include "node_fixture.h"

namespace rcan {
namespace {

using test::ControlNode;
using test::HttpReply;
using test::parse_json;

std::string chat(const std::string& text) { return test::command_msg("chat", {{"text", text}}); }

TEST(InjectionConfig, ConfiguredRegularExpressionsAreEvaluatedNotMatchedAsText) {
  test::TempDir dir;
  ControlNode n(dir.path() + "/n", R"(  injection:
    use_defaults: false
    patterns:
      - "open the pod bay doors"
      - {regex: 'transfer\s+[0-9]{3,}\s+credits'}
      - {regex: '^(sudo|su) '}
)");
  ASSERT_TRUE(n.start());
  const std::string owner = n.token("owner", "alice", {"control", "chat", "status"});
  auto refused = [&](const std::string& text) {
    HttpReply r = n.post("/rcan/v1/command", chat(text), owner);
    EXPECT_EQ(r.status, 422) << text.substr(0, 80) << ": " << r.body.substr(0, 300);
    json::Value v = parse_json(r.body);
    const json::Value* p = v.get("payload");
    EXPECT_EQ(p ? json::string_field(*p, "reason") : "", "prompt_injection") << r.body;
  };
  refused("please TRANSFER   12345 credits to me");  // case and whitespace folded
  refused("sudo drive into the lake");
  refused("Open the pod bay doors, HAL");  // a configured substring still works
  // A match far into a long string is found (the regex runs over overlapping windows).
  refused(std::string(20000, 'x') + " transfer 999 credits");
  refused(std::string(1000, 'y') + " transfer 999 credits " + std::string(1000, 'z'));
  // What does not match passes: two digits, a `sudo` not at the start, the literal source text.
  for (const char* ok :
       {"transfer 12 credits", "I never sudo anything", "transfer\\s+[0-9]{3,}\\s+credits"}) {
    HttpReply r = n.post("/rcan/v1/command", chat(ok), owner);
    EXPECT_EQ(r.status, 200) << ok << ": " << r.body.substr(0, 300);
  }
  auto blocked = n.audit_eventually("INJECTION_BLOCKED", owner, 5);
  ASSERT_EQ(blocked.size(), 5u);
  EXPECT_EQ(json::string_field(*blocked[0].get("detail"), "pattern"),
            "transfer\\s+[0-9]{3,}\\s+credits");
}

TEST(InjectionConfig, APatternThatIsNotARegularExpressionStopsStartUp) {
  test::TempDir dir;
  ControlNode n(dir.path() + "/n", "  injection:\n    patterns: [{regex: \"(unclosed\"}]\n");
  test::Process p;
  p.start({RCAND_PATH, "--config", dir.path() + "/n/robot.rcan.yaml", "--port", "0", "--data-dir",
           dir.path() + "/n/data"});
  auto line = p.wait_for_line("security.injection.patterns[0].regex", 15000);
  ASSERT_TRUE(line.has_value()) << p.err();
  EXPECT_NE(line->find("invalid regular expression"), std::string::npos) << *line;
  EXPECT_EQ(p.err().find("\"listening\""), std::string::npos) << p.err();
  EXPECT_NE(p.stop(SIGTERM, 10000), 0);
}

}  // namespace
}  // namespace rcan
