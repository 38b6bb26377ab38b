// The rcan CLI's first verbs, run as a real process: ruri parse, json canonical, message check.
#include <gtest/gtest.h>

#include <sstream>

#include "rcan/json.h"
#include "test_support.h"

namespace rcan {
namespace {

json::Value parse_out(const std::string& s) {
  auto v = json::parse(s);
  EXPECT_TRUE(v.ok()) << s;
  return v.ok() ? *v : json::Value();
}

TEST(CliRuri, ValidPrintsComponentsAndExitsZero) {
  auto r = test::run_cli({"ruri", "parse", "rcan://local.rcan/unitree/go2/a1b2c3d4:9000/teleop"});
  EXPECT_EQ(r.exit_code, 0);
  json::Value v = parse_out(r.out);
  EXPECT_EQ(v.get("valid")->as_bool(), true);
  EXPECT_EQ(v.get("canonical")->as_string(), "rcan://local.rcan/unitree/go2/a1b2c3d4:9000/teleop");
  EXPECT_EQ(v.get("registry")->as_string(), "local.rcan");
  EXPECT_EQ(v.get("manufacturer")->as_string(), "unitree");
  EXPECT_EQ(v.get("model")->as_string(), "go2");
  EXPECT_EQ(v.get("device_id")->as_string(), "a1b2c3d4");
  EXPECT_EQ(v.get("port")->as_int(), 9000);
  EXPECT_EQ(v.get("capability")->as_string(), "teleop");
}

TEST(CliRuri, ShorthandIsNormalised) {
  auto r = test::run_cli({"ruri", "parse", "rcan://opencastor.rover.abc123/nav"});
  EXPECT_EQ(r.exit_code, 0);
  json::Value v = parse_out(r.out);
  EXPECT_EQ(v.get("canonical")->as_string(), "rcan://local.rcan/opencastor/rover/abc123/nav");
  EXPECT_TRUE(v.get("port")->is_null());
}

TEST(CliRuri, InvalidPrintsReasonAndExitsOne) {
  auto r = test::run_cli({"ruri", "parse", "rcan://local.rcan/opencastor/rover"});
  EXPECT_EQ(r.exit_code, 1);
  json::Value v = parse_out(r.out);
  EXPECT_EQ(v.get("valid")->as_bool(), false);
  EXPECT_EQ(v.get("error_code")->as_string(), "INVALID_RURI");
  EXPECT_EQ(v.get("reason")->as_string(), "missing device-id segment");
}

TEST(CliRuri, UsageErrorsExitTwo) {
  EXPECT_EQ(test::run_cli({"ruri"}).exit_code, 2);
  EXPECT_EQ(test::run_cli({"ruri", "parse"}).exit_code, 2);
  EXPECT_EQ(test::run_cli({"ruri", "frobnicate", "x"}).exit_code, 2);
  EXPECT_EQ(test::run_cli({"no-such-verb"}).exit_code, 2);
  EXPECT_EQ(test::run_cli({"ruri", "--help"}).exit_code, 0);
}

// Every verb, and every sub-verb after it, answers --help (and -h) with its usage on stdout and
// exit 0 — never "unknown option --help" — and does nothing else (no request, no file).
TEST(CliHelp, EveryVerbAndSubVerbAnswersHelp) {
  auto top = test::run_cli({"--help"});
  ASSERT_EQ(top.exit_code, 0);
  std::vector<std::string> verbs;
  std::istringstream lines(top.out);
  for (std::string line; std::getline(lines, line);)
    if (line.size() > 2 && line.rfind("  ", 0) == 0 && line[2] >= 'a' && line[2] <= 'z')
      verbs.push_back(line.substr(2, line.find(' ', 2) - 2));
  ASSERT_GE(verbs.size(), 25u) << top.out;
  const std::vector<std::vector<std::string>> subs = {
      {"token", "issue"},      {"token", "inspect"}, {"token", "revoke"},    {"keys", "generate"},
      {"keys", "issuer"},      {"audit", "verify"},  {"audit", "export"},    {"fleet", "estop"},
      {"fleet", "run"},        {"lease", "grant"},   {"transfer", "accept"}, {"consent", "grant"},
      {"message", "check"},    {"ruri", "parse"},    {"json", "canonical"},  {"thoughts", "get"},
      {"watermark", "verify"}, {"command", "move"}};
  std::vector<std::vector<std::string>> all;
  for (const auto& v : verbs) all.push_back({v});
  all.insert(all.end(), subs.begin(), subs.end());
  for (auto argv : all) {
    for (const char* flag : {"--help", "-h"}) {
      auto a = argv;
      a.push_back(flag);
      auto r = test::run_cli(a, {}, {"RCAN_URL=http://127.0.0.1:1"});
      EXPECT_EQ(r.exit_code, 0) << a[0] << " " << (a.size() > 2 ? a[1] : "") << " " << flag << ": "
                                << r.err;
      EXPECT_NE(r.out.find("usage"), std::string::npos) << a[0] << " " << flag << ": " << r.out;
    }
  }
}

TEST(CliJson, CanonicalBytesOnStdout) {
  auto r = test::run_cli({"json", "canonical"}, R"({"b":1.0,"a":"Café","c":[{"z":1,"y":2}]})");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out, R"({"a":"Café","b":1,"c":[{"y":2,"z":1}]})");
}

TEST(CliJson, BadInputGivesErrorBodyAndExitOne) {
  auto r = test::run_cli({"json", "canonical"}, R"({"a":1,"a":2})");
  EXPECT_EQ(r.exit_code, 1);
  json::Value v = parse_out(r.out);
  EXPECT_EQ(v.get("type")->as_string(), "ERROR");
  EXPECT_EQ(v.get("payload")->get("error_code")->as_string(), "MALFORMED_JSON");
  EXPECT_GT(v.get("timestamp_ms")->as_int(), 0);
  r = test::run_cli({"json", "canonical"}, std::string(200000, '['));
  EXPECT_EQ(r.exit_code, 1);
}

TEST(CliMessage, NormalisesAnRcanPyMessageToTheSeedShape) {
  auto r = test::run_cli(
      {"message", "check"},
      R"({"rcan":"3.2","msg_id":"11111111-2222-4333-8444-555555555555","timestamp":1740721482.934,)"
      R"("cmd":"move_forward","target":"rcan://registry.rcan.dev/acme/robotarm/v2/unit-001","params":{"speed":0.5}})");
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value v = parse_out(r.out);
  EXPECT_EQ(v.get("type")->as_string(), "COMMAND");
  EXPECT_EQ(v.get("message_id")->as_string(), "11111111-2222-4333-8444-555555555555");
  EXPECT_EQ(v.get("timestamp_ms")->as_int(), 1740721482934);
  EXPECT_EQ(v.get("payload")->get("action")->as_string(), "move_forward");
  EXPECT_EQ(v.get("target_ruri")->as_string(),
            "rcan://registry.rcan.dev/acme/robotarm/v2/unit-001");
  EXPECT_EQ(v.get("priority")->as_string(), "NORMAL");
  EXPECT_EQ(v.get("sender_type")->as_string(), "human");
}

TEST(CliMessage, SchemaFailureNamesTheMissingField) {
  auto r = test::run_cli({"message", "check"}, R"({"version":"1.3","type":"COMMAND"})");
  EXPECT_EQ(r.exit_code, 1);
  json::Value v = parse_out(r.out);
  EXPECT_EQ(v.get("payload")->get("error_code")->as_string(), "SCHEMA_VALIDATION_FAILED");
  EXPECT_EQ(v.get("payload")->get("detail")->get("missing_field")->as_string(), "payload");
}

TEST(CliMessage, HostileBodiesNeverCrash) {
  for (const std::string& body :
       {std::string(""), std::string("\xff\xfe"), std::string("null"), std::string(70000, 'x'),
        std::string("{\"payload\":") + std::string(5000, '[')}) {
    auto r = test::run_cli({"message", "check"}, body);
    EXPECT_EQ(r.exit_code, 1);
    json::Value v = parse_out(r.out);
    EXPECT_EQ(v.get("type")->as_string(), "ERROR");
  }
}

TEST(CliSelfcheck, AllKnownAnswersPass) {
  auto r = test::run_cli({"selfcheck"});
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("0 failed"), std::string::npos);
}

}  // namespace
}  // namespace rcan
