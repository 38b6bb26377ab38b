// rcan pending | authorize | thoughts — §16 HiTL decisions and the thought log on a running
// node (docs/AI.md). URL from --url or $RCAN_URL, token from --token-file or $RCAN_TOKEN_FILE.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>

#include "base/clock.h"
#include "cli.h"
#include "node_http.h"
#include "rcan/errors.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

constexpr const char* kPendingHelp =
    "usage: rcan pending [--url URL] [--token-file F] [--json]\n"
    "  Lists the commands a HiTL gate holds (GET /rcan/v1/pending): message id, action type,\n"
    "  who asked, time left. OWNER and CREATOR see all; others their own.\n"
    "  Exit: 0 listed, 1 refused by the node, 2 usage or unreachable.\n";
constexpr const char* kAuthorizeHelp =
    "usage: rcan authorize MESSAGE_ID --approve|--deny [--reason TEXT] [--url URL] [--token-file "
    "F] [--json]\n"
    "  Sends an AUTHORIZE for a held command (POST /rcan/v1/authorize). Only OWNER or CREATOR\n"
    "  tokens are accepted. On approve the node dispatches it and prints the result.\n"
    "  Exit: 0 accepted, 1 refused by the node (its error is printed), 2 usage or unreachable.\n";
constexpr const char* kThoughtsHelp =
    "usage: rcan thoughts get THOUGHT_ID [--url URL] [--token-file F]\n"
    "  Prints a §16.5 thought record (GET /api/thoughts/<id>); reasoning only with a config-scope\n"
    "  token. Exit: 0 found, 1 refused or unknown, 2 usage or unreachable.\n";

int64_t now_ms() { return unix_ms(); }

struct Conn {
  Target target;
  std::string token;
};

// Common options; returns 0 on success, else the exit code to return.
int connect_opts(const char* verb, const Options& o, Conn& c) {
  if (!o.ok()) return usage_error(verb, o.error());
  std::string url = o.get("url");
  if (url.empty())
    if (const char* env = std::getenv("RCAN_URL")) url = env;
  if (url.empty()) url = "http://127.0.0.1:8080";
  auto t = parse_url(url);
  if (!t.ok()) return usage_error(verb, t.error().message);
  c.target = *t;
  std::string err;
  c.token = token_from(o, true, err);
  if (!err.empty()) return usage_error(verb, err);
  return 0;
}

int send(const char* verb, const Conn& c, const std::string& method, const std::string& path,
         const std::string& body, std::pair<int, std::string>& out) {
  auto r = request(c.target, method, path, body, c.token);
  if (!r.ok()) {
    std::fprintf(stderr, "rcan %s: %s\n", verb, r.error().message.c_str());
    return 2;
  }
  out = *r;
  return 0;
}

int pending_main(const Args& args) {
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h"))
    return std::fputs(kPendingHelp, stdout), 0;
  Options o(args, {"json"}, {"url", "token-file"});
  Conn c;
  if (int rc = connect_opts("pending", o, c)) return rc;
  if (!o.positional().empty())
    return usage_error("pending", "unexpected argument " + o.positional()[0]);
  std::pair<int, std::string> r;
  if (int rc = send("pending", c, "GET", "/rcan/v1/pending", "", r)) return rc;
  auto v = json::parse(r.second);
  if (o.has("json") || r.first != 200 || !v.ok() || !v->get("pending") ||
      !v->get("pending")->is_array()) {
    std::cout << r.second << "\n";
    return r.first == 200 ? 0 : 1;
  }
  const auto& items = v->get("pending")->as_array();
  if (items.empty()) std::puts("nothing is waiting for authorization");
  for (const auto& i : items) {
    auto s = [&](const char* k) {
      const json::Value* f = i.get(k);
      return f ? (f->is_string() ? f->as_string() : json::dump(*f)) : std::string("-");
    };
    const json::Value* left = i.get("timeout_remaining_ms");
    std::printf("%s  %-16s by %-16s %6.1f s left (on timeout: %s)\n", s("message_id").c_str(),
                s("action_type").c_str(), s("requested_by").c_str(),
                left && left->is_int() ? static_cast<double>(left->as_int()) / 1000 : 0.0,
                s("on_timeout").c_str());
  }
  return 0;
}

int authorize_main(const Args& args) {
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h"))
    return std::fputs(kAuthorizeHelp, stdout), 0;
  Options o(args, {"approve", "deny", "json"}, {"url", "token-file", "reason"});
  Conn c;
  if (int rc = connect_opts("authorize", o, c)) return rc;
  if (o.positional().size() != 1) return usage_error("authorize", "give exactly one MESSAGE_ID");
  if (o.has("approve") == o.has("deny"))
    return usage_error("authorize", "give --approve or --deny");
  json::Object payload{{"message_id", o.positional()[0]},
                       {"decision", o.has("approve") ? "approve" : "deny"}};
  if (o.has("reason")) payload.set("reason", o.get("reason"));
  json::Object m{{"version", "1.0.0"},
                 {"message_id", new_uuid_v4()},
                 {"type", "AUTHORIZE"},
                 {"timestamp_ms", now_ms()},
                 {"payload", payload}};
  std::pair<int, std::string> r;
  if (int rc = send("authorize", c, "POST", "/rcan/v1/authorize", json::dump(json::Value(m)), r))
    return rc;
  if (o.has("json") || r.first != 200) {
    std::cout << r.second << "\n";
  } else {
    auto v = json::parse(r.second);
    const json::Value* p = v.ok() ? v->get("payload") : nullptr;
    const json::Value* wm = p ? p->get("watermark_token") : nullptr;
    if (o.has("approve"))
      std::printf("approved %s: dispatched (HTTP %d)%s%s\n", o.positional()[0].c_str(), r.first,
                  wm && wm->is_string() ? ", watermark " : "",
                  wm && wm->is_string() ? wm->as_string().c_str() : "");
    else
      std::printf("denied %s: dropped (HTTP %d)\n", o.positional()[0].c_str(), r.first);
  }
  return r.first == 200 ? 0 : 1;
}

int thoughts_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h")
    return std::fputs(kThoughtsHelp, stdout), args.empty() ? 2 : 0;
  if (args[0] != "get")
    return usage_error("thoughts", "unknown subcommand " + args[0] + " (try: get)");
  Options o(Args(args.begin() + 1, args.end()), {}, {"url", "token-file"});
  Conn c;
  if (int rc = connect_opts("thoughts", o, c)) return rc;
  if (o.positional().size() != 1) return usage_error("thoughts", "give exactly one THOUGHT_ID");
  const std::string& id = o.positional()[0];
  for (char ch : id)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' || ch == '.' ||
          ch == ':'))
      return usage_error("thoughts", "a thought id holds letters, digits and - _ . : only");
  std::pair<int, std::string> r;
  if (int rc = send("thoughts", c, "GET", "/api/thoughts/" + id, "", r)) return rc;
  std::cout << r.second << "\n";
  return r.first == 200 ? 0 : 1;
}

const Registration kPending{"pending", "list commands held by a HiTL gate on a running node",
                            &pending_main};
const Registration kAuthorize{"authorize", "approve or deny a held command (OWNER/CREATOR)",
                              &authorize_main};
const Registration kThoughts{"thoughts", "read the thought log of a running node", &thoughts_main};

}  // namespace
}  // namespace rcan::cli
