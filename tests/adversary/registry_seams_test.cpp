// The seams between a robot and its registry, tried as an attacker with only the public
// interfaces would (docs/THREATS.md T1, T3): a real rcan-registry and real rcand nodes on
// loopback, both started here. The attacker is a registrant of the registry the robot trusts —
// anyone the registry's admin gave a registrant key, or anyone at all on an open registry.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "joining_robot.h"
#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {
namespace {

const std::string kTrust = "  trust_tokens: true\n";

// A registrant key of its own, made by the registry's admin.
std::string new_registrant(const RegistryDaemon& reg, const std::string& label) {
  auto k = reg.send("POST", "/api/v1/keys", R"({"role":"registrant","label":")" + label + R"("})",
                    reg.admin_key());
  EXPECT_EQ(k.status, 201) << k.body;
  return str(json_of(k.body), "key");
}

// What a registrant can get from the registry for `rrn`: a client of its own, an OWNER grant on
// the record and a token for it. Empty when the registry refuses any step.
std::string owner_token(const RegistryDaemon& reg, const std::string& key, const std::string& rrn,
                        std::string* refusal = nullptr) {
  auto c = reg.send("POST", "/api/v1/clients", R"({"name":"ops","auth":"client_secret"})", key);
  EXPECT_EQ(c.status, 201) << c.body;
  const json::Value client = json_of(c.body);
  auto g = reg.send("POST", "/api/v1/grants",
                    R"({"principal":")" + str(client, "client_id") + R"(","robot":")" + rrn +
                        R"(","role":"owner","scope":["status","control","config"]})",
                    key);
  EXPECT_EQ(g.status, 201) << g.body;
  auto t = http(reg.port(), "POST", "/oauth/token",
                "grant_type=client_credentials&client_id=" + str(client, "client_id") +
                    "&client_secret=" + str(client, "client_secret") + "&resource=" + rrn,
                {{"Content-Type", "application/x-www-form-urlencoded"}});
  if (t.status != 200) {
    if (refusal != nullptr) *refusal = t.body;
    return {};
  }
  return str(json_of(t.body), "access_token");
}

// The OWNER-only audit log of the robot at `port`, read with `token`.
int read_audit(uint16_t port, const std::string& token) {
  return http(port, "GET", "/api/audit?limit=1", "", {{"Authorization", "Bearer " + token}}).status;
}

// A registry with one registrant, Alice (her key in a 0600 file), whose robots the attacks aim at.
class AdversaryRegistry : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_FALSE(reg.url().empty()); }
  TempDir dir;
  RegistryDaemon reg{dir.file("registry")};
  const std::string alice_file =
      registrant_key_file(reg, dir.file("registry"), dir.file("alice.key"));
};
using AdversaryRegistryToRobot = AdversaryRegistry;
using AdversaryRegistryDeviceFlow = AdversaryRegistry;

// T1 (review finding F1, HIGH). Before the fix: the registry took a token's aud from the
// record's unchecked metadata.ruri, and rcand accepted '*' per segment from the registry's
// issuer without comparing the rrn claim with its own RRN; a registrant who wrote
// rcan://*/*/*/* (or the victim's RURI, readable by anyone) into its own record's metadata and
// granted itself OWNER there read the victim robot's audit log (200), claimed it and moved it.
TEST_F(AdversaryRegistryToRobot, ARegistrantCannotMintItselfOwnerOfAnotherRegistrantsRobot) {
  JoiningRobot robot(dir.file("robot"), reg.url(), alice_file, kRuri, kTrust);
  const std::string victim = robot.start();
  ASSERT_EQ(victim.rfind("RRN-", 0), 0u);
  // The control: its own registrant's OWNER token works, so a 401 below is the robot's verdict.
  const std::string alice_token = owner_token(reg, first_line(alice_file), victim);
  ASSERT_FALSE(alice_token.empty());
  EXPECT_EQ(read_audit(robot.port(), alice_token), 200);

  const std::string mallory = new_registrant(reg, "mallory");
  struct Attempt {
    std::string what, model, version, device, metadata;
  };
  const std::vector<Attempt> attempts{
      {"a wildcard RURI in its own record", "bot", "v1", "deadbeef",
       R"({"ruri":"rcan://*/*/*/*"})"},
      {"the victim's RURI in its own record", "bot", "v1", "deadbee1",
       R"({"ruri":")" + std::string(kRuri) + R"("})"},
      {"the victim's names under another version", "rover", "v2", "0a1b2c3d",
       R"({"ruri":")" + std::string(kRuri) + R"("})"},
  };
  for (const Attempt& a : attempts) {
    SCOPED_TRACE(a.what);
    const std::string manufacturer = a.model == "rover" ? "acme" : "evil";
    auto r = reg.register_proven(mallory, manufacturer, a.model, a.version, a.device, a.metadata);
    // The registry refuses a record whose RURI is not the robot its proof named, or is taken.
    EXPECT_TRUE(r.status == 400 || r.status == 409) << r.status << " " << r.body;
    if (r.status != 201) continue;
    // Registered all the same: whatever token it gets, the robot must refuse it.
    const std::string tok = owner_token(reg, mallory, str(json_of(r.body), "rrn"));
    if (!tok.empty()) {
      EXPECT_EQ(read_audit(robot.port(), tok), 401);
    }
  }
  // The victim's own names: not the attacker's to adopt.
  auto squat = reg.register_proven(mallory, "acme", "rover", "v1", "0a1b2c3d", "{}");
  EXPECT_EQ(squat.status, 409) << squat.body;
  EXPECT_NE(squat.body.find(victim), std::string::npos) << squat.body;
  // Its own robot, proven and consistent, gets tokens that name that robot alone.
  auto own = reg.register_proven(mallory, "evil", "bot", "v1", "deadbee2",
                                 R"({"ruri":"rcan://local.rcan/evil/bot/deadbee2"})");
  ASSERT_EQ(own.status, 201) << own.body;
  const std::string own_token = owner_token(reg, mallory, str(json_of(own.body), "rrn"));
  ASSERT_FALSE(own_token.empty());
  EXPECT_EQ(read_audit(robot.port(), own_token), 401);
  // A record that proved no key gets no token at all.
  auto unproven = reg.send("POST", "/api/v1/robots",
                           R"({"manufacturer":"evil","model":"bot","version":"v1",)"
                           R"("device_id":"deadbee3","metadata":{"ruri":"rcan://*/*/*/*"}})",
                           mallory);
  ASSERT_EQ(unproven.status, 201) << unproven.body;
  std::string why;
  EXPECT_TRUE(owner_token(reg, mallory, str(json_of(unproven.body), "rrn"), &why).empty());
  EXPECT_NE(why.find("proved no key"), std::string::npos) << why;
  EXPECT_EQ(read_audit(robot.port(), alice_token), 200);
}

// T3 (review finding F3). Before the fix: names registered before the robot joined were
// answered `already_existed` to anyone, and rcand adopted that RRN without comparing keys —
// it then served under the squatter's record and could never refresh it (403 forever).
TEST_F(AdversaryRegistryToRobot, ARobotDoesNotAdoptARecordSomeoneElseRegisteredFirst) {
  // `key` registers `ruri`'s names with keys of its own first; a robot of Alice's with that
  // RURI then joins, and must not adopt the record: `says` is in its log.
  auto joins_without_adopting = [&](const std::string& key, const std::string& ruri,
                                    const std::string& device, const std::string& says) {
    auto first =
        reg.register_proven(key, "acme", "rover", "v1", device, R"({"ruri":")" + ruri + R"("})");
    ASSERT_EQ(first.status, 201) << first.body;
    const std::string taken = str(json_of(first.body), "rrn");
    JoiningRobot robot(dir.file(device), reg.url(), alice_file, ruri);
    EXPECT_NE(robot.start(), taken);
    EXPECT_FALSE(std::filesystem::exists(robot.data() + "/registry/state.json"));
    EXPECT_NE(robot.proc().err().find(taken + says), std::string::npos) << robot.proc().err();
    EXPECT_EQ(robot.stop(), 0);
  };
  // Another registrant registered the names: the registry does not answer already_existed.
  joins_without_adopting(new_registrant(reg, "mallory"), kRuri, "0a1b2c3d", "");
  // The same registrant's key registered them with other keys (a key shared by a team, a copied
  // robot): the registry answers already_existed, and the robot compares the keys.
  joins_without_adopting(first_line(alice_file), "rcan://local.rcan/acme/rover/0a1b2c3e",
                         "0a1b2c3e", " with other keys");
}

HttpReply form_post(const RegistryDaemon& reg, const std::string& path, const std::string& body) {
  return http(reg.port(), "POST", path, body,
              {{"Content-Type", "application/x-www-form-urlencoded"}});
}

// T7 (review finding F7). Before the fix: anyone started a device request for a victim's robot
// under any client id (the victim's own confidential client included: its id is no secret),
// `rcan registry device approve` showed the victim only {user_code, decision}, and the
// attacker's poll returned an OWNER token for the victim's robot.
TEST_F(AdversaryRegistryDeviceFlow, AnApprovalIsInformedAndAConfidentialClientCannotBeBorrowed) {
  const std::string alice = first_line(alice_file);
  auto robot = reg.register_proven(alice, "acme", "rover", "v1", "0a1b2c3d",
                                   R"({"ruri":")" + std::string(kRuri) + R"("})");
  ASSERT_EQ(robot.status, 201) << robot.body;
  const std::string rrn = str(json_of(robot.body), "rrn");
  // Alice's key holds OWNER on her robot (so her approval would give OWNER), and her own
  // confidential client for her tools.
  std::string alice_id;
  auto keys = json_of(reg.get("/api/v1/keys", reg.admin_key()).body);
  for (const auto& k : keys.get("keys")->as_array())
    if (str(k, "label") == "fleet-ops") alice_id = str(k, "id");
  ASSERT_FALSE(alice_id.empty());
  ASSERT_EQ(reg.send("POST", "/api/v1/grants",
                     R"({"principal":"user:)" + alice_id + R"(","robot":")" + rrn +
                         R"(","role":"owner","scope":["status","control","config"]})",
                     alice)
                .status,
            201);
  auto own_client =
      reg.send("POST", "/api/v1/clients", R"({"name":"alice-cli","auth":"client_secret"})", alice);
  ASSERT_EQ(own_client.status, 201);

  // Mallory borrows Alice's client id: refused without its secret.
  auto borrowed =
      form_post(reg, "/oauth/device_authorization",
                "client_id=" + str(json_of(own_client.body), "client_id") + "&resource=" + rrn);
  EXPECT_EQ(borrowed.status, 401) << borrowed.body;

  // Mallory makes a public client of her own with the same name and sends Alice the code.
  const std::string mallory = new_registrant(reg, "mallory");
  auto decoy =
      reg.send("POST", "/api/v1/clients", R"({"name":"alice-cli","auth":"none"})", mallory);
  ASSERT_EQ(decoy.status, 201) << decoy.body;
  const std::string decoy_id = str(json_of(decoy.body), "client_id");
  auto started =
      form_post(reg, "/oauth/device_authorization", "client_id=" + decoy_id + "&resource=" + rrn);
  ASSERT_EQ(started.status, 200) << started.body;
  const std::string user_code = str(json_of(started.body), "user_code");
  const std::string device_code = str(json_of(started.body), "device_code");

  // What Alice sees names the client's maker, not only its name: Mallory's key.
  auto shown = run_cli(
      {"registry", "device", "show", user_code, "--registry", reg.url(), "--key-file", alice_file});
  ASSERT_EQ(shown.exit_code, 0) << shown.out << shown.err;
  EXPECT_NE(shown.out.find("\"created_by_label\":\"mallory\""), std::string::npos) << shown.out;
  EXPECT_NE(shown.out.find("\"role\":\"owner\""), std::string::npos) << shown.out;
  // The page anyone with the code opens shows what is asked, and sends the approver to `show`
  // for who made the client (no key id or label for whoever holds a code).
  auto page = reg.get("/device?user_code=" + user_code);
  EXPECT_NE(page.body.find("alice-cli"), std::string::npos) << page.body;
  EXPECT_NE(page.body.find(rrn), std::string::npos) << page.body;
  EXPECT_NE(page.body.find("rcan registry device show " + user_code), std::string::npos);
  EXPECT_EQ(page.body.find("mallory"), std::string::npos) << page.body;
  // Others do not learn of the request.
  EXPECT_EQ(reg.get("/api/v1/device/requests/" + user_code, new_registrant(reg, "eve")).status,
            404);
  // An approval typed without reading is not taken: it asks, and with no one to ask, refuses.
  auto approve = run_cli({"registry", "device", "approve", user_code, "--registry", reg.url(),
                          "--key-file", alice_file});
  EXPECT_EQ(approve.exit_code, 2) << approve.out << approve.err;
  EXPECT_NE(approve.err.find("mallory"), std::string::npos) << approve.err;
  auto poll = form_post(reg, "/oauth/token",
                        "grant_type=urn%3Aietf%3Aparams%3Aoauth%3Agrant-type%3Adevice_code"
                        "&client_id=" +
                            decoy_id + "&device_code=" + device_code);
  EXPECT_EQ(str(json_of(poll.body), "error"), "authorization_pending") << poll.body;
}

}  // namespace
}  // namespace rcan::test
