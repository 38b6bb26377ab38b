// rcan lease | transfer | consent — leases, ownership transfer and consent requests on a
// running node (docs/SESSIONS.md). Thin wrappers over the node's HTTP routes; the node's URL
// and token come from --url / $RCAN_URL and --token-file / $RCAN_TOKEN_FILE.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iostream>

#include "cli.h"
#include "node_http.h"
#include "rcan/errors.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

// "90", "90s", "30m", "2h", "1d" → seconds; -1 when malformed.
int64_t parse_duration(const std::string& s) {
  if (s.empty() || s.size() > 12) return -1;
  char* end = nullptr;
  int64_t v = std::strtoll(s.c_str(), &end, 10);
  if (end == s.c_str() || v <= 0) return -1;
  std::string unit(end);
  if (unit.empty() || unit == "s") return v;
  if (unit == "m") return v * 60;
  if (unit == "h") return v * 3600;
  if (unit == "d") return v * 86400;
  return -1;
}

struct Call {
  std::string method, path;
  json::Object body;
};

// Runs one call and prints the answer; exit 0 on 2xx, 1 when the node refused, 2 otherwise.
int perform(const std::string& verb, const Options& o, const Call& c) {
  std::string err;
  std::string token = node_token(o, true, err);
  if (!err.empty()) return usage_error(verb, err);
  auto r = node_request(node_url(o), c.method, c.path,
                        c.body.empty() ? "" : json::dump(json::Value(c.body)), token);
  if (!r.ok()) {
    std::fprintf(stderr, "rcan %s: %s\n", verb.c_str(), r.error().message.c_str());
    return 2;
  }
  std::cout << r->second << (r->second.empty() || r->second.back() != '\n' ? "\n" : "");
  return r->first >= 200 && r->first < 300 ? 0 : 1;
}

const char* kLeaseUsage =
    "usage: rcan lease grant --leasee SUB [--duration 2h]\n"
    "       rcan lease list\n"
    "       rcan lease revoke LEASE_ID\n"
    "       rcan lease allow LEASE_ID --user SUB [--role user|guest] [--duration 30m]\n"
    "  [--url URL] [--token-file F]; an OWNER grants and revokes, the LEASEE allows.\n";

int lease_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kLeaseUsage, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Options o(Args(args.begin() + 1, args.end()), {},
            {"url", "token-file", "leasee", "duration", "user", "role"});
  if (!o.ok()) return usage_error("lease", o.error());
  const std::string& sub = args[0];
  Call c;
  auto duration = [&](const char* def, int64_t& out) {
    out = parse_duration(o.get("duration", def));
    return out > 0;
  };
  int64_t secs = 0;
  if (sub == "grant") {
    if (o.get("leasee").empty()) return usage_error("lease", "grant needs --leasee SUB");
    if (!duration("1h", secs))
      return usage_error("lease", "--duration must be like 90s, 30m, 2h or 1d");
    c = {"POST", "/rcan/v1/leases",
         json::Object{{"leasee", o.get("leasee")}, {"duration_s", secs}}};
  } else if (sub == "list") {
    c = {"GET", "/rcan/v1/leases", {}};
  } else if (sub == "revoke") {
    if (o.positional().size() != 1) return usage_error("lease", "revoke needs LEASE_ID");
    c = {"DELETE", "/rcan/v1/leases/" + o.positional()[0], {}};
  } else if (sub == "allow") {
    if (o.positional().size() != 1 || o.get("user").empty())
      return usage_error("lease", "allow needs LEASE_ID --user SUB");
    if (!duration("1h", secs))
      return usage_error("lease", "--duration must be like 90s, 30m, 2h or 1d");
    c = {"POST", "/rcan/v1/leases/" + o.positional()[0] + "/grants",
         json::Object{
             {"user_id", o.get("user")}, {"role", o.get("role", "user")}, {"duration_s", secs}}};
  } else {
    return usage_error("lease", "unknown subcommand " + sub + " (grant, list, revoke, allow)");
  }
  return perform("lease", o, c);
}

const char* kTransferUsage =
    "usage: rcan transfer request --to SUB [--note TEXT]\n"
    "       rcan transfer accept TRANSFER_ID --agreement REF\n"
    "       rcan transfer cancel\n"
    "       rcan transfer status\n"
    "  [--url URL] [--token-file F]; the owner requests and cancels, the new owner accepts.\n";

int transfer_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kTransferUsage, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Options o(Args(args.begin() + 1, args.end()), {},
            {"url", "token-file", "to", "note", "agreement"});
  if (!o.ok()) return usage_error("transfer", o.error());
  const std::string& sub = args[0];
  Call c;
  if (sub == "request") {
    if (o.get("to").empty()) return usage_error("transfer", "request needs --to SUB");
    json::Object b{{"action", "request"}, {"new_owner", o.get("to")}};
    if (o.has("note")) b.set("note", o.get("note"));
    c = {"POST", "/rcan/v1/transfer", b};
  } else if (sub == "accept") {
    if (o.positional().size() != 1 || o.get("agreement").empty())
      return usage_error("transfer", "accept needs TRANSFER_ID --agreement REF");
    c = {"POST", "/rcan/v1/transfer",
         json::Object{{"action", "accept"},
                      {"transfer_id", o.positional()[0]},
                      {"agreement", o.get("agreement")}}};
  } else if (sub == "cancel") {
    c = {"POST", "/rcan/v1/transfer", json::Object{{"action", "cancel"}}};
  } else if (sub == "status") {
    c = {"GET", "/rcan/v1/transfer", {}};
  } else {
    return usage_error("transfer",
                       "unknown subcommand " + sub + " (request, accept, cancel, status)");
  }
  return perform("transfer", o, c);
}

const char* kConsentUsage =
    "usage: rcan consent list\n"
    "       rcan consent grant CONSENT_ID [--kind lease|grant] [--duration 1h]\n"
    "       rcan consent deny CONSENT_ID [--reason TEXT]\n"
    "  [--url URL] [--token-file F]; needs the owner's token.\n";

int consent_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kConsentUsage, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Options o(Args(args.begin() + 1, args.end()), {},
            {"url", "token-file", "kind", "duration", "reason"});
  if (!o.ok()) return usage_error("consent", o.error());
  const std::string& sub = args[0];
  Call c;
  if (sub == "list") {
    c = {"GET", "/rcan/v1/consent", {}};
  } else if (sub == "grant" || sub == "deny") {
    if (o.positional().size() != 1) return usage_error("consent", sub + " needs CONSENT_ID");
    json::Object b;
    if (sub == "grant") {
      b.set("kind", o.get("kind", "lease"));
      if (o.has("duration")) {
        int64_t secs = parse_duration(o.get("duration"));
        if (secs <= 0) return usage_error("consent", "--duration must be like 90s, 30m, 2h or 1d");
        b.set("duration_s", secs);
      }
    } else if (o.has("reason")) {
      b.set("reason", o.get("reason"));
    }
    c = {"POST", "/rcan/v1/consent/" + o.positional()[0] + "/" + sub, b};
  } else {
    return usage_error("consent", "unknown subcommand " + sub + " (list, grant, deny)");
  }
  return perform("consent", o, c);
}

const Registration kLease{"lease", "grant, list, revoke leases on a running node (OWNER)",
                          &lease_main};
const Registration kTransfer{"transfer", "ownership transfer: request, accept, cancel, status",
                             &transfer_main};
const Registration kConsent{"consent", "consent requests: list, grant, deny (OWNER)",
                            &consent_main};

}  // namespace
}  // namespace rcan::cli
