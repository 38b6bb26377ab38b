// rcan json — canonical JSON and Python-compatible pre-images.
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage: rcan json canonical        read JSON on stdin, write rcan-canonical-json-v1 bytes\n"
    "       rcan json python-dumps     read JSON on stdin, write Python "
    "json.dumps(sort_keys=True,\n"
    "                                  separators=(',',':')) bytes (rcan-py pre-image writer)\n"
    "Exit: 0 ok; 1 malformed input (an error body is printed on stdout).\n";

int json_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  const std::string& sub = args[0];
  if (sub != "canonical" && sub != "python-dumps")
    return usage_error("json", "unknown subcommand " + sub);
  if (args.size() > 1) return usage_error("json", "unexpected argument " + args[1]);
  std::string in = read_stdin();
  json::ParseOptions opts;
  opts.max_bytes = 16u << 20;
  auto v = json::parse(in, opts);
  if (!v.ok()) {
    print_error_body(v.error());
    return 1;
  }
  std::string out = sub == "canonical" ? json::canonical(*v) : json::python_dumps(*v);
  std::fwrite(out.data(), 1, out.size(), stdout);
  return 0;
}

const Registration kReg{"json", "canonical JSON and rcan-py pre-image bytes", &json_main};

}  // namespace
}  // namespace rcan::cli
