// RURI parsing against every URI of the shared acceptance matrix (tests/vectors/ruri.json),
// with this project's verdict per docs/PROTOCOL.md §Addressing, plus RRN, aud matching and
// whether a target addresses this robot.
#include "rcan/ruri.h"

#include <gtest/gtest.h>

#include <map>

#include "test_support.h"

namespace rcan {
namespace {

// Expected canonical form, or "!<segment>" for an INVALID_RURI naming that segment.
const std::map<std::string, std::string>& profile_verdicts() {
  static const std::map<std::string, std::string> v{
      {"rcan://registry.rcan.dev/acme/robotarm/v2/unit-001",
       "rcan://registry.rcan.dev/acme/robotarm/v2/unit-001"},
      {"rcan://registry.rcan.dev/acme/robotarm/v2/unit-001/",
       "rcan://registry.rcan.dev/acme/robotarm/v2/unit-001"},
      {"rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6-7890-1234-5678-abcdef012345",
       "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6-7890-1234-5678-abcdef012345"},
      {"rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6/arm",
       "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6/arm"},
      {"rcan://local.rcan/discovered/192.168.1.42:8080",
       "rcan://local.rcan/discovered/192.168.1.42:8080"},
      {"rcan://registry.example.com:9000/universal-robots/ur10e/v1/ur10e-0042", "!registry"},
      {"rcan://rcan.dev/boston-dynamics/spot/bd-spot-001a2b3c", "!device-id"},
      {"rcan://robot.local:8000/bob", "!registry"},
      {"rcan://registry.rcan.dev/ac me/arm/v1/x", "!ruri"},
      {"rcan://registry.rcan.dev/acme//v2/unit-001", "!ruri"},
      {"rcan://r/a/b/v1/x/extra", "!registry"},
      {"http://registry.rcan.dev/acme/arm/v1/x", "!scheme"},
      {"rcan://registry.rcan.dev/acme/arm/v1/unit_01~", "!device-id"},
      {"RCAN://registry.rcan.dev/acme/arm/v1/x", "!scheme"},
      {" rcan://registry.rcan.dev/acme/arm/v1/x ", "!ruri"},
      {"rcan://registry.rcan.dev/acme/arm/v1/x?sig=abc", "!ruri"},
      {"rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6",
       "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6"},
      {"rcan://continuon.cloud/continuon/companion-v1/*", "!device-id"},
      // The expanded v1.1 shorthand (device id of 4..36 alphanumerics under local.rcan).
      {"rcan://local.rcan/opencastor/rover/abc123", "rcan://local.rcan/opencastor/rover/abc123"},
      {"rcan://rcan.dev/org/robot/v1/unit-001", "rcan://rcan.dev/org/robot/v1/unit-001"},
      {"rcan://local.rcan/opencastor/rover/abc12345",
       "rcan://local.rcan/opencastor/rover/abc12345"},
      {"rcan://local.rcan/opencastor/rover", "!device-id"},
      {"rcan://local.rcan/unitree/go2/a1b2c3d4:9000/teleop",
       "rcan://local.rcan/unitree/go2/a1b2c3d4:9000/teleop"},
      {"rcan://registry.rrf.ai/opencastor/rover/abc12345",
       "rcan://registry.rrf.ai/opencastor/rover/abc12345"},
      {"rcan://continuon.cloud/unitree/go2/a1b2c3d4",
       "rcan://continuon.cloud/unitree/go2/a1b2c3d4"},
      {"rcan://my-server.lan/acme/bot-x1/12345678-1234", "!device-id"},
      {"rcan://local.rcan/opencastor", "!model"},
      {"rcan://", "!registry"},
      {"https://example.com/robot", "!scheme"},
      {"rcan://UPPERCASE/mfr/mdl/12345678", "!registry"},
      {"rcan://local.rcan/mfr/mdl/short", "rcan://local.rcan/mfr/mdl/short"},
      {"rcan://robots.acme-corp.com/acme/patrol-bot/a1b2c3d4e5f6", "!device-id"},
      {"rcan://local.rcan/generic/differential-drive/00000001",
       "rcan://local.rcan/generic/differential-drive/00000001"},
      {"rcan://registry.example.com:9000/universal-robots/ur10e/ur10e-0042-aabb", "!registry"},
      {"rcan://rcan.dev/franka-robotics/fr3/fr3-00ff11ee22dd/gripper",
       "rcan://rcan.dev/franka-robotics/fr3/fr3-00ff11ee22dd/gripper"},
      {"rcan://opencastor.rover.abc123/nav", "rcan://local.rcan/opencastor/rover/abc123/nav"},
      {"rcan://robots.acme.corp/acme/arm/a1b2c3d4", "rcan://robots.acme.corp/acme/arm/a1b2c3d4"},
      {"rcan://local.rcan/acme/arm/a1b2c3d4:70000", "!port"},
      {"rcan://local.rcan/acme/arm/a1b2c3d4/", "rcan://local.rcan/acme/arm/a1b2c3d4"},
      {"rcan://local.rcan/acme/arm/A1B2C3D4", "!device-id"},
      {"rcan://local.rcan/acme/arm/a1b2c3d4/nav/waypoints",
       "rcan://local.rcan/acme/arm/a1b2c3d4/nav/waypoints"},
  };
  return v;
}

TEST(Ruri, EveryUriOfTheSharedMatrixGetsTheProfileVerdict) {
  json::Value v = test::load_vector("ruri.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 41u);
  for (const auto& c : cases) {
    const std::string& uri = c.get("uri")->as_string();
    SCOPED_TRACE(uri);
    auto it = profile_verdicts().find(uri);
    ASSERT_NE(it, profile_verdicts().end()) << "no verdict recorded for this URI";
    auto r = parse_ruri(uri);
    if (it->second[0] == '!') {
      ASSERT_FALSE(r.ok()) << "accepted as " << r->str();
      EXPECT_EQ(r.error().code, ErrorCode::kInvalidRuri);
      EXPECT_EQ(r.error().field, it->second.substr(1)) << r.error().message;
      EXPECT_FALSE(r.error().message.empty());
    } else {
      ASSERT_TRUE(r.ok()) << r.error().message;
      EXPECT_EQ(r->str(), it->second);
      // Canonical output re-parses to itself.
      auto again = parse_ruri(r->str());
      ASSERT_TRUE(again.ok());
      EXPECT_EQ(again->str(), it->second);
    }
    // Wherever the spec's normative regex accepts, we accept the same string unchanged.
    if (c.get("results")->get("spec_normative_regex")->as_bool()) {
      bool port_out_of_range = uri.find(":70000") != std::string::npos;
      if (!port_out_of_range) {
        ASSERT_TRUE(r.ok());
        EXPECT_EQ(r->str(), uri);
      }
    }
  }
}

TEST(Ruri, ComponentsOfTheCanonicalForm) {
  auto r = parse_ruri("rcan://local.rcan/unitree/go2/a1b2c3d4:9000/teleop");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->form, Ruri::Form::kCanonical);
  EXPECT_EQ(r->registry, "local.rcan");
  EXPECT_EQ(r->manufacturer, "unitree");
  EXPECT_EQ(r->model, "go2");
  EXPECT_EQ(r->device_id, "a1b2c3d4");
  ASSERT_TRUE(r->port.has_value());
  EXPECT_EQ(*r->port, 9000);
  EXPECT_EQ(r->capability, "teleop");
  EXPECT_EQ(r->base(), "rcan://local.rcan/unitree/go2/a1b2c3d4");
}

TEST(Ruri, Sdk5FormKeepsVersionAndDevice) {
  auto r = parse_ruri("rcan://registry.rcan.dev/acme/robotarm/v2/unit-001");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->form, Ruri::Form::kSdk5);
  EXPECT_EQ(r->version, "v2");
  EXPECT_EQ(r->device_id, "unit-001");
}

TEST(Ruri, SdkFormOfEachRobotIdentity) {
  auto sdk = [](const char* text) {
    auto r = parse_ruri(text);
    EXPECT_TRUE(r.ok()) << text;
    return r.ok() ? sdk_form(*r) : std::string("?");
  };
  // The seed form gains the version segment; port and capability are not identity.
  EXPECT_EQ(sdk("rcan://local.rcan/acme/rover/0a1b2c3d"),
            "rcan://local.rcan/acme/rover/v1/0a1b2c3d");
  EXPECT_EQ(sdk("rcan://registry.rcan.dev/acme/arm/0a1b2c3d:9000/arm"),
            "rcan://registry.rcan.dev/acme/arm/v1/0a1b2c3d");
  EXPECT_EQ(sdk("rcan://acme.arm.unit42"), "rcan://local.rcan/acme/arm/v1/unit42");
  // A 5-segment RURI keeps its own version; a discovered one names no robot.
  EXPECT_EQ(sdk("rcan://registry.rcan.dev/acme/arm/v2/unit-001"),
            "rcan://registry.rcan.dev/acme/arm/v2/unit-001");
  EXPECT_EQ(sdk("rcan://local.rcan/discovered/192.168.1.42:8080"), "");
  // What sdk_form writes reads back as the 5-segment form.
  auto back = parse_ruri(sdk("rcan://local.rcan/acme/rover/0a1b2c3d"));
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->form, Ruri::Form::kSdk5);
  EXPECT_EQ(back->version, "v1");
}

TEST(Ruri, ErrorsNameSegmentAndRule) {
  auto r = parse_ruri("rcan://local.rcan/opencastor/rover");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().message, "missing device-id segment");
  r = parse_ruri("rcan://local.rcan/acme/arm/a1b2c3d4:0");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "port");
  r = parse_ruri("rcan://local.rcan/acme/arm/a1b2c3d4/Nav");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "capability");
  r = parse_ruri("rcan://example.com/a/arm/a1b2c3d4");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "manufacturer");
  EXPECT_NE(r.error().message.find("shorter than 2"), std::string::npos);
  r = parse_ruri("rcan://local.rcan/discovered/999.1.1.1:80");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "device-id");
}

TEST(Ruri, ShorthandOutputIsAFixedPoint) {
  // Found by fuzzing: a shorthand whose id is not hex must still re-parse after expansion.
  for (const char* in :
       {"rcan://a.b.0a1bj2c3d", "rcan://opencastor.rover.abc123/nav", "rcan://x.y.zzzz"}) {
    auto r = parse_ruri(in);
    ASSERT_TRUE(r.ok()) << in << ": " << r.error().message;
    auto again = parse_ruri(r->str());
    ASSERT_TRUE(again.ok()) << r->str() << ": " << again.error().message;
    EXPECT_EQ(again->str(), r->str());
  }
  EXPECT_FALSE(parse_ruri("rcan://local.rcan/acme/arm/abc").ok());    // 3 characters: too short
  EXPECT_FALSE(parse_ruri("rcan://other.reg/acme/arm/abc123").ok());  // only under local.rcan
}

TEST(Ruri, HostileInputIsRejectedCleanly) {
  for (std::string s : {std::string(10000, 'a'), std::string("rcan://") + std::string(600, 'a'),
                        std::string("rcan://\0x/a/b/c", 14),
                        std::string("rcan://\xff\xfe/a/b/12345678"), std::string("rcan:////////"),
                        std::string("rcan://a.b.c"), std::string("rcan://./../../..")}) {
    auto r = parse_ruri(s);
    EXPECT_FALSE(r.ok()) << s;
    if (!r.ok()) {
      EXPECT_EQ(r.error().code, ErrorCode::kInvalidRuri);
    }
  }
}

TEST(AudMatch, WildcardSegmentsAndCapabilities) {
  auto robot = parse_ruri("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6");
  ASSERT_TRUE(robot.ok());
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/*", *robot));
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/*/d3a4b5c6", *robot));
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/*/*", *robot));
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6", *robot));
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6:8080", *robot));
  EXPECT_FALSE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c7", *robot));
  EXPECT_FALSE(aud_matches("rcan://other.cloud/continuon/companion-v1/*", *robot));
  EXPECT_FALSE(aud_matches("rcan://continuon.cloud/continuon/*", *robot));
  EXPECT_FALSE(aud_matches("https://continuon.cloud/continuon/companion-v1/*", *robot));
  EXPECT_FALSE(aud_matches("*", *robot));
  EXPECT_FALSE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6/arm", *robot));
  auto arm = parse_ruri("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6/arm");
  ASSERT_TRUE(arm.ok());
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6/arm", *arm));
  EXPECT_TRUE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/*", *arm));
  EXPECT_FALSE(aud_matches("rcan://continuon.cloud/continuon/companion-v1/*/vision", *arm));
}

TEST(AddressesRobot, EveryFormOfThisRobotAndNoOther) {
  auto self = parse_ruri("rcan://registry.rcan.dev/acme/rover/0a1b2c3d");
  ASSERT_TRUE(self.ok());
  auto verdict = [&](const char* text, std::string* why = nullptr) {
    auto t = parse_ruri(text);
    EXPECT_TRUE(t.ok()) << text;
    return t.ok() && addresses_robot(*t, *self, why);
  };
  // This robot: canonical, with a port or a capability, the SDKs' 5-segment form with any
  // version, the local registry and the dot shorthand (which expands into it).
  for (const char* mine : {"rcan://registry.rcan.dev/acme/rover/0a1b2c3d",
                           "rcan://registry.rcan.dev/acme/rover/0a1b2c3d:8000",
                           "rcan://registry.rcan.dev/acme/rover/0a1b2c3d/arm",
                           "rcan://registry.rcan.dev/acme/rover/v1/0a1b2c3d",
                           "rcan://registry.rcan.dev/acme/rover/v7/0a1b2c3d",
                           "rcan://local.rcan/acme/rover/0a1b2c3d", "rcan://acme.rover.0a1b2c3d"})
    EXPECT_TRUE(verdict(mine)) << mine;
  // Another robot, however close: each differing segment is named.
  std::string why;
  EXPECT_FALSE(verdict("rcan://registry.rcan.dev/acme/rover/0a1b2c3e", &why));
  EXPECT_NE(why.find("device-id '0a1b2c3e'"), std::string::npos) << why;
  EXPECT_FALSE(verdict("rcan://registry.rcan.dev/acme/rover2/0a1b2c3d", &why));
  EXPECT_NE(why.find("model"), std::string::npos) << why;
  EXPECT_FALSE(verdict("rcan://registry.rcan.dev/acme2/rover/0a1b2c3d", &why));
  EXPECT_NE(why.find("manufacturer"), std::string::npos) << why;
  EXPECT_FALSE(verdict("rcan://other.example/acme/rover/0a1b2c3d", &why));
  EXPECT_NE(why.find("registry"), std::string::npos) << why;
  EXPECT_FALSE(verdict("rcan://registry.rcan.dev/acme/rover/v1/0a1b2c3e"));
  EXPECT_FALSE(verdict("rcan://local.rcan/discovered/192.168.1.42:8080", &why));
  EXPECT_NE(why.find("address"), std::string::npos) << why;
}

TEST(Rrn, CanonicalAndAcceptedForms) {
  auto r = parse_rrn("RRN-000000000001");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->str(), "RRN-000000000001");
  r = parse_rrn("RRN-12345678");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->str(), "RRN-000012345678");
  r = parse_rrn("RRN-BD-000000000042");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->prefix, "BD");
  EXPECT_EQ(r->str(), "RRN-BD-000000000042");
  for (const char* bad :
       {"RRN-1234567", "RRN-12345678901234567", "rrn-000000000001", "RRN-00000000000a",
        "RRN-b-000000000001", "RRN--000000000001", "", "RRN-"}) {
    EXPECT_FALSE(parse_rrn(bad).ok()) << bad;
  }
}

// The one text form the registry mints and a node without a registration makes for itself.
TEST(Rrn, FormattedFromANumber) {
  EXPECT_EQ(format_rrn(0), "RRN-000000000000");
  EXPECT_EQ(format_rrn(42), "RRN-000000000042");
  EXPECT_EQ(format_rrn(999'999'999'999), "RRN-999999999999");
  EXPECT_EQ(format_rrn(1'000'000'000'000), "RRN-1000000000000");  // more digits when it has more
  EXPECT_EQ(format_rrn(42, "BD"), "RRN-BD-000000000042");
  EXPECT_EQ(format_rrn(42, "bd"), "RRN-BD-000000000042");  // the prefix upper-cased
  for (int64_t n : {int64_t{1}, int64_t{123'456'789'012}}) {
    auto r = parse_rrn(format_rrn(n, "ACME"));
    ASSERT_TRUE(r.ok()) << n;
    EXPECT_EQ(r->str(), format_rrn(n, "ACME"));
  }
}

}  // namespace
}  // namespace rcan
