// rcan message — validate and normalise RCAN messages.
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "rcan/errors.h"
#include "rcan/message.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage: rcan message check [--max-bytes N]\n"
    "  Reads one message (seed shape or rcan-py shape) on stdin. Prints it normalised in the\n"
    "  seed shape and exits 0, or prints the error body and exits 1.\n";

int message_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  if (args[0] != "check") return usage_error("message", "unknown subcommand " + args[0]);
  Options opt(Args(args.begin() + 1, args.end()), {}, {"max-bytes"});
  if (!opt.ok()) return usage_error("message", opt.error());
  if (!opt.positional().empty()) return usage_error("message", "unexpected argument " + opt.positional()[0]);
  CodecLimits limits;
  if (opt.has("max-bytes")) {
    try {
      limits.max_body_bytes = std::stoul(opt.get("max-bytes"));
    } catch (...) {
      return usage_error("message", "--max-bytes needs a number");
    }
  }
  std::string body = read_stdin();
  auto m = parse_message(body, limits);
  if (!m.ok()) {
    print_error_body(m.error());
    return 1;
  }
  std::cout << json::dump(encode_message(*m)) << "\n";
  return 0;
}

const Registration kReg{"message", "validate and normalise messages", &message_main};

}  // namespace
}  // namespace rcan::cli
