// rcan message — validate and normalise RCAN messages.
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "net_common.h"
#include "rcan/errors.h"
#include "rcan/message.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage: rcan message check [--max-bytes N]\n"
    "  Reads one message (seed shape or rcan-py shape) on stdin. Prints it normalised in the\n"
    "  seed shape and exits 0, or prints the error body and exits 1.\n"
    "usage: rcan message send [--url URL] [--token-file F] [--json]\n"
    "  Reads one message (any accepted shape) on stdin, checks it locally, and sends it as is to\n"
    "  the node (POST /rcan/v1/command); prints the node's answer (exit codes: rcan --help).\n";

int send_main(const Args& args) {
  Options o(args, net_flags(), net_valued());
  if (!o.ok()) return usage_error("message send", o.error());
  if (!o.positional().empty())
    return usage_error("message send", "unexpected argument " + o.positional()[0]);
  std::string err;
  auto co = client_options(o, true, err);
  if (!err.empty()) return usage_error("message send", err);
  std::string body = read_stdin();
  auto m = parse_message(body, CodecLimits{});
  if (!m.ok()) {
    print_error_body(m.error());
    return 1;
  }
  auto v = json::parse(body);
  if (!v.ok()) return usage_error("message send", v.error().message);
  client::Client c(co);
  auto r = c.send(*v);
  if (!r.ok()) return report_error("message send", r.error(), want_json(o));
  std::cout << json::dump(r->raw) << "\n";
  return r->pending() ? kExitPending : kExitOk;
}

int message_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  if (args[0] == "send") return send_main(Args(args.begin() + 1, args.end()));
  if (args[0] != "check")
    return usage_error("message", "unknown subcommand " + args[0] + " (check, send)");
  Options opt(Args(args.begin() + 1, args.end()), {}, {"max-bytes"});
  if (!opt.ok()) return usage_error("message", opt.error());
  if (!opt.positional().empty())
    return usage_error("message", "unexpected argument " + opt.positional()[0]);
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

const Registration kReg{"message", "validate, normalise and send messages", &message_main};

}  // namespace
}  // namespace rcan::cli
