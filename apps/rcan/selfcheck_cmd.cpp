// rcan selfcheck — known-answer checks of the library on this machine.
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "cli.h"
#include "rcan/encoding.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/roles.h"
#include "rcan/ruri.h"

namespace rcan::cli {
namespace {

struct Check {
  const char* name;
  std::function<bool()> fn;
};

int selfcheck_main(const Args& args) {
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h")) {
    std::puts(
        "usage: rcan selfcheck\n  Runs known-answer checks (canonical JSON, Python pre-images, "
        "RURI,\n  roles, message codec, SHA-256, HMAC) and exits 0 when all pass.");
    return 0;
  }
  std::vector<Check> checks{
      {"canonical JSON (rcan-canonical-json-v1)",
       [] {
         auto v = json::parse(R"({"b":[1.0,{"z":null,"a":"Café ☕"}],"a":-0.0,"c":1e-05})");
         return v.ok() &&
                json::canonical(*v) == R"({"a":0,"b":[1,{"a":"Café ☕","z":null}],"c":1e-05})";
       }},
      {"Python json.dumps pre-image",
       [] {
         auto v = json::parse(R"({"t":1740721483.0,"n":"café","x":1e16,"i":7})");
         return v.ok() &&
                json::python_dumps(*v) == R"({"i":7,"n":"caf\u00e9","t":1740721483.0,"x":1e+16})";
       }},
      {"RURI parse and normalise",
       [] {
         auto a = parse_ruri("rcan://opencastor.rover.abc123/nav");
         auto b = parse_ruri("rcan://local.rcan/opencastor/rover");
         return a.ok() && a->str() == "rcan://local.rcan/opencastor/rover/abc123/nav" && !b.ok() &&
                b.error().field == "device-id";
       }},
      {"capability matrix",
       [] {
         return !role_allows(Role::kGuest, Capability::kTeleop) &&
                role_allows(Role::kUser, Capability::kNavigation) &&
                !role_allows(Role::kUser, Capability::kArm) &&
                role_allows(Role::kLeasee, Capability::kArm) &&
                !role_allows(Role::kOwner, Capability::kModelDeployment);
       }},
      {"message codec (both shapes)",
       [] {
         auto m = parse_message(std::string_view(
             R"({"rcan":"3.2","msg_id":"11111111-2222-4333-8444-555555555555","timestamp":1740721482.934,)"
             R"("cmd":"move_forward","target":"rcan://registry.rcan.dev/acme/robotarm/v2/unit-001","params":{"speed":0.5}})"));
         return m.ok() && m->type == MessageType::kCommand && m->action() == "move_forward" &&
                m->timestamp_ms == 1740721482934;
       }},
      {"SHA-256 (FIPS 180-4 'abc')",
       [] {
         return sha256_hex("abc") ==
                "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
       }},
      {"HMAC-SHA256 (RFC 4231 case 2)",
       [] {
         return hmac_sha256_hex("Jefe", "what do ya want for nothing?") ==
                "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843";
       }},
  };
  int failed = 0;
  for (const auto& c : checks) {
    bool ok = c.fn();
    std::printf("%-44s %s\n", c.name, ok ? "ok" : "FAILED");
    if (!ok) ++failed;
  }
  std::printf("%zu passed, %d failed\n", checks.size() - static_cast<size_t>(failed), failed);
  return failed ? 1 : 0;
}

const Registration kReg{"selfcheck", "run known-answer checks of the library", &selfcheck_main};

}  // namespace
}  // namespace rcan::cli
