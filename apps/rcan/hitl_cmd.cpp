// rcan pending | authorize | thoughts — §16 human-in-the-loop and thought log on a running
// node (docs/PROTOCOL.md §16 on HTTP), through rcan::client. Conventions: net_common.h.
#include <cstdio>
#include <iostream>

#include "net_common.h"

namespace rcan::cli {
namespace {

std::optional<Options> parse(const char* verb, const Args& args, const std::vector<std::string>& flags,
                             const std::vector<std::string>& valued, int& rc) {
  std::vector<std::string> f = flags, v = valued;
  f.insert(f.end(), net_flags().begin(), net_flags().end());
  v.insert(v.end(), net_valued().begin(), net_valued().end());
  Options o(args, f, v);
  if (!o.ok()) {
    rc = usage_error(verb, o.error());
    return std::nullopt;
  }
  return o;
}

constexpr const char* kPendingHelp =
    "usage: rcan pending [--url URL] [--token-file F] [--json]\n"
    "  Lists commands waiting for a human authorization (GET /rcan/v1/pending): message id,\n"
    "  action type, description, who sent it and when the wait ends.\n";

int pending_main(const Args& args) {
  if (help_requested(args, (std::string(kPendingHelp) + kNetHelp).c_str())) return 0;
  int rc = 0;
  auto o = parse("pending", args, {}, {}, rc);
  if (!o) return rc;
  if (!o->positional().empty()) return usage_error("pending", "unexpected argument " + o->positional()[0]);
  std::string err;
  auto co = client_options(*o, true, err);
  if (!err.empty()) return usage_error("pending", err);
  client::Client c(co);
  auto p = c.pending();
  if (!p.ok()) return report_error("pending", p.error(), want_json(*o));
  if (want_json(*o)) {
    json::Array a;
    for (const auto& e : *p) a.push_back(e.raw);
    std::cout << json::dump(json::Value(json::Object{{"pending", a}})) << "\n";
    return 0;
  }
  if (p->empty()) {
    std::printf("nothing waits for an authorization\n");
    return 0;
  }
  std::vector<std::vector<std::string>> rows;
  for (const auto& e : *p)
    rows.push_back({e.message_id, e.action_type, e.description, e.principal, when(e.expires_at_ms)});
  print_table({"MESSAGE_ID", "ACTION", "DESCRIPTION", "FROM", "EXPIRES"}, rows);
  return 0;
}

constexpr const char* kAuthorizeHelp =
    "usage: rcan authorize MESSAGE_ID (--approve | --deny) [--reason TEXT] [--url URL]\n"
    "                      [--token-file F] [--json]\n"
    "  Decides a pending command (POST /rcan/v1/authorize with an AUTHORIZE message).\n";

int authorize_main(const Args& args) {
  if (help_requested(args, (std::string(kAuthorizeHelp) + kNetHelp).c_str())) return 0;
  int rc = 0;
  auto o = parse("authorize", args, {"approve", "deny"}, {"reason"}, rc);
  if (!o) return rc;
  if (o->positional().size() != 1) return usage_error("authorize", "give exactly one MESSAGE_ID");
  if (o->has("approve") == o->has("deny")) return usage_error("authorize", "give --approve or --deny");
  std::string err;
  auto co = client_options(*o, true, err);
  if (!err.empty()) return usage_error("authorize", err);
  client::Client c(co);
  auto r = c.authorize(o->positional()[0], o->has("approve"), o->get("reason"));
  if (!r.ok()) return report_error("authorize", r.error(), want_json(*o));
  if (want_json(*o)) std::cout << json::dump(r->raw) << "\n";
  else
    std::printf("%s %s (%s)\n", o->has("approve") ? green("approved").c_str() : yellow("denied").c_str(),
                o->positional()[0].c_str(), r->type.empty() ? "OK" : r->type.c_str());
  return 0;
}

constexpr const char* kThoughtsHelp =
    "usage: rcan thoughts THOUGHT_ID [--url URL] [--token-file F] [--json]\n"
    "  Shows one entry of the §16.5 thought log (GET /api/thoughts/<id>): provider, model,\n"
    "  layer, instruction, action, confidence; `reasoning` only when the token has scope config.\n";

int thoughts_main(const Args& args) {
  if (help_requested(args, (std::string(kThoughtsHelp) + kNetHelp).c_str())) return 0;
  int rc = 0;
  auto o = parse("thoughts", args, {}, {}, rc);
  if (!o) return rc;
  if (o->positional().size() != 1) return usage_error("thoughts", "give exactly one THOUGHT_ID");
  std::string err;
  auto co = client_options(*o, true, err);
  if (!err.empty()) return usage_error("thoughts", err);
  client::Client c(co);
  auto t = c.thought(o->positional()[0]);
  if (!t.ok()) return report_error("thoughts", t.error(), want_json(*o));
  if (want_json(*o)) {
    std::cout << json::dump(t->raw) << "\n";
    return 0;
  }
  auto row = [](const char* k, const std::string& v) { std::printf("%-12s %s\n", k, v.c_str()); };
  row("id", bold(t->id));
  row("time", when(t->timestamp_ms));
  row("provider", t->provider);
  row("model", t->model);
  row("layer", t->layer);
  row("instruction", t->instruction);
  row("action", brief(t->action, 120));
  if (t->confidence) {
    char b[32];
    std::snprintf(b, sizeof b, "%.3f", *t->confidence);
    row("confidence", b);
  } else {
    row("confidence", "(unknown)");
  }
  row("reasoning", t->reasoning ? *t->reasoning : dim("(needs scope config)"));
  return 0;
}

const Registration kPending{"pending", "list commands waiting for a human authorization", &pending_main};
const Registration kAuthorize{"authorize", "approve or deny a pending command", &authorize_main};
const Registration kThoughts{"thoughts", "look up a §16 thought log entry", &thoughts_main};

}  // namespace
}  // namespace rcan::cli
