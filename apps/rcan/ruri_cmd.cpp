// rcan ruri — parse, validate and normalise RURIs.
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "rcan/errors.h"
#include "rcan/ruri.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage: rcan ruri parse <ruri>\n"
    "  Prints {\"valid\":true,\"canonical\":…,\"registry\":…,\"manufacturer\":…,\"model\":…,\n"
    "  \"device_id\":…,\"port\":…,\"capability\":…,\"form\":…} and exits 0, or\n"
    "  {\"valid\":false,\"error_code\":\"INVALID_RURI\",\"reason\":…,\"segment\":…} and exits 1.\n"
    "  Accepted forms: canonical, v1.1 dot shorthand, the SDKs' 5-segment form, and\n"
    "  rcan://local.rcan/discovered/<ip>:<port>; output is always canonical.\n";

int ruri_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  if (args[0] != "parse") return usage_error("ruri", "unknown subcommand " + args[0]);
  if (args.size() != 2) return usage_error("ruri", "parse takes exactly one RURI");
  auto r = parse_ruri(args[1]);
  json::Object out;
  if (!r.ok()) {
    out.set("valid", false);
    out.set("error_code", std::string(error_name(r.error().code)));
    out.set("reason", r.error().message);
    out.set("segment", r.error().field);
    std::cout << json::dump(out) << "\n";
    return 1;
  }
  out.set("valid", true);
  out.set("canonical", r->str());
  out.set("registry", r->registry);
  out.set("manufacturer", r->manufacturer);
  out.set("model", r->model);
  out.set("device_id", r->device_id);
  out.set("port", r->port ? json::Value(static_cast<int64_t>(*r->port)) : json::Value());
  out.set("capability", r->capability.empty() ? json::Value() : json::Value(r->capability));
  if (r->form == Ruri::Form::kSdk5) out.set("version", r->version);
  out.set("form", std::string(ruri_form_name(r->form)));
  std::cout << json::dump(out) << "\n";
  return 0;
}

const Registration kReg{"ruri", "parse, validate and normalise RURIs", &ruri_main};

}  // namespace
}  // namespace rcan::cli
