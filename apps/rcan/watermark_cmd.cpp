// rcan watermark — compute and check §16.6 watermark tokens.
#include <algorithm>
#include <cstdio>
#include <iostream>

#include "base/clock.h"
#include "cli.h"
#include "net_common.h"
#include "rcan/crypto/watermark.h"
#include "rcan/hash.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage:\n"
    "  rcan watermark compute --key-file SK --rrn R --thought-id T --timestamp ISO\n"
    "      Prints rcan-wm-v1:<32 hex> = HMAC-SHA256(key, \"R:T:ISO\")[0:16]. SK is the robot's\n"
    "      ML-DSA-65 secret key as a raw 4032-byte file, or a 32-byte mldsa65.seed (the secret\n"
    "      key is derived from it with ML-DSA.KeyGen_internal), or a key directory (its\n"
    "      mldsa65.seed). The file must not be group/world accessible. ISO is used verbatim;\n"
    "      the node writes UTC YYYY-MM-DDTHH:MM:SS.ffffff (`--timestamp now` prints that form\n"
    "      on stderr and uses it).\n"
    "  rcan watermark check TOKEN\n"
    "      Whole-string format check ^rcan-wm-v1:[0-9a-f]{32}$ (no surrounding whitespace).\n"
    "  rcan watermark verify TOKEN [--rrn R] [--url URL] [--json]\n"
    "      Asks the node (public GET /api/v1/watermark/verify) whether TOKEN is in its audit\n"
    "      log; prints the audit entry it belongs to. Exit 0 found, 1 not found / invalid.\n"
    "  rcan watermark verify --key-file SK --rrn R --thought-id T --timestamp ISO TOKEN\n"
    "      Recomputes and compares in constant time.\n"
    "  Exit: 0 ok / valid, 1 invalid, 2 usage or unreadable key.\n";

int compute_or_verify(const Args& args, bool verify) {
  const char* verb = verify ? "watermark verify" : "watermark compute";
  Options o(args, {}, {"key-file", "rrn", "thought-id", "timestamp"});
  if (!o.ok()) return usage_error(verb, o.error());
  for (const char* need : {"key-file", "rrn", "thought-id", "timestamp"})
    if (!o.has(need)) return usage_error(verb, std::string("--") + need + " is required");
  if (verify ? o.positional().size() != 1 : !o.positional().empty())
    return usage_error(verb, verify ? "give exactly one TOKEN" : "unexpected argument");
  std::string ts = o.get("timestamp");
  if (ts == "now") {
    ts = watermark::format_timestamp(wall_now());
    std::fprintf(stderr, "timestamp: %s\n", ts.c_str());
  }
  auto key = watermark::load_key(o.get("key-file"));
  if (!key.ok()) return usage_error(verb, key.error().message);
  int rc = 0;
  if (verify) {
    bool ok = watermark::verify(*key, o.get("rrn"), o.get("thought-id"), ts, o.positional()[0]);
    std::cout << (ok ? "valid" : "invalid") << "\n";
    rc = ok ? 0 : 1;
  } else {
    std::cout << watermark::compute(*key, o.get("rrn"), o.get("thought-id"), ts) << "\n";
  }
  secure_wipe(key->data(), key->size());
  return rc;
}

int node_verify(const Args& args) {
  std::vector<std::string> flags = net_flags(), valued{"rrn"};
  valued.insert(valued.end(), net_valued().begin(), net_valued().end());
  Options o(args, flags, valued);
  if (!o.ok()) return usage_error("watermark verify", o.error());
  if (o.positional().size() != 1) return usage_error("watermark verify", "give exactly one TOKEN");
  std::string err;
  auto co = client_options(o, false, err);
  if (!err.empty()) return usage_error("watermark verify", err);
  client::Client c(co);
  auto v = c.watermark_verify(o.positional()[0], o.get("rrn"));
  if (!v.ok()) return report_error("watermark verify", v.error(), want_json(o));
  if (want_json(o)) {
    json::Object out{{"valid", v->valid},
                     {"rrn", v->rrn},
                     {"watermark_token", v->watermark_token},
                     {"audit_entry", v->audit_entry}};
    std::cout << json::dump(json::Value(std::move(out))) << "\n";
  } else {
    std::printf("%s %s (rrn %s)\n", v->valid ? green("valid").c_str() : red("invalid").c_str(),
                v->watermark_token.c_str(), v->rrn.c_str());
    if (v->audit_entry.is_object())
      for (const auto& [k, val] : v->audit_entry.as_object())
        std::printf("  %-16s %s\n", k.c_str(), brief(val, 100).c_str());
  }
  return v->valid ? 0 : 1;
}

int watermark_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Args rest(args.begin() + 1, args.end());
  if (args[0] == "compute") return compute_or_verify(rest, false);
  if (args[0] == "verify") {
    bool local = std::any_of(rest.begin(), rest.end(),
                             [](const std::string& a) { return a.rfind("--key-file", 0) == 0; });
    if (local) return compute_or_verify(rest, true);
    return node_verify(rest);
  }
  if (args[0] == "check") {
    if (rest.size() != 1) return usage_error("watermark check", "give exactly one TOKEN");
    Status s = watermark::check_format(rest[0]);
    json::Object out;
    out.set("valid", s.ok());
    if (!s.ok()) out.set("error", s.error().message);
    std::cout << json::dump(json::Value(std::move(out))) << "\n";
    return s.ok() ? 0 : 1;
  }
  return usage_error("watermark", "unknown subcommand " + args[0] + " (compute | check | verify)");
}

const Registration kReg{"watermark", "compute and check §16.6 watermark tokens", &watermark_main};

}  // namespace
}  // namespace rcan::cli
