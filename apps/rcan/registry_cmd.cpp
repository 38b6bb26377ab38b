// rcan registry … and rcan resolve — a client of rcan-registry (docs/REGISTRY.md) and of any
// registry that speaks the rcan.dev API. The registry's URL comes from --registry or
// $RCAN_REGISTRY; write operations present the API key in --key-file or $RCAN_REGISTRY_KEY_FILE.
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>

#include "base/clock.h"
#include "cli.h"
#include "net_common.h"
#include "node_http.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/registry_proof.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/registry.h"
#include "rcan/ruri.h"

namespace rcan::cli {
namespace {

constexpr const char* kUsage =
    "usage: rcan registry <command> [--registry URL] [--key-file F] …\n"
    "  register --manufacturer M --model X --version V --device-id D [--description T]\n"
    "           [--contact-email E] [--endpoint URL] [--keys-dir D] [--save-key F]\n"
    "      Registers a robot and prints its RRN. --keys-dir proves that the robot holds the\n"
    "      identity keys in D (rcan keys generate; rcand's <data-dir>/keys): both keys sign\n"
    "      the registry's challenge and the registry records them. --save-key writes the\n"
    "      robot's own API key (shown once) to F with mode 0600.\n"
    "  get RRN | resolve RRN | delete RRN\n"
    "  list [--q TEXT] [--manufacturer M] [--model X] [--tier T] [--limit N] [--offset N]\n"
    "  search [--manufacturer M] [--model X] [--tier T]\n"
    "  update RRN [--description T] [--contact-email E] [--endpoint URL] [--keys-dir D]\n"
    "      A robot that registered its keys signs its updates with them (--keys-dir).\n"
    "  nodes [--prefix P] | manifest\n"
    "  keys create [--role registrant|admin] [--label L] [--save F] | keys list | keys revoke ID\n"
    "  device show CODE | device approve CODE [--yes] | device deny CODE\n"
    "      A device-flow request (rcan login on another machine shows the code): show prints\n"
    "      which client asks (its name, id and who made it), for which robot or fleet and\n"
    "      scopes, and what your grant would give. approve prints the same and asks before it\n"
    "      approves (--yes: without asking, as a script would); the token is issued for your\n"
    "      key's grants to whoever holds the request, so approve only a client you started.\n"
    "The registry: --registry URL, else $RCAN_REGISTRY, else http://127.0.0.1:8090. The API\n"
    "key: --key-file F, else $RCAN_REGISTRY_KEY_FILE (rcan-registry writes its admin key to\n"
    "<data-dir>/admin.key). Exit: 0 success, 1 refused by the registry, 2 usage, 3 unreachable.\n";

constexpr const char* kResolveUsage =
    "usage: rcan resolve RRN|RURI [--registry URL] [--json]\n"
    "  Asks the registry where a robot answers and which keys it proved it holds. A RURI\n"
    "  (rcan://<registry-host>/<manufacturer>/<model>/<version>/<device-id>) is asked of\n"
    "  --registry, else $RCAN_REGISTRY, else https://<registry-host>.\n"
    "  Exit: 0 found, 1 not found or refused, 2 usage, 3 unreachable.\n";

const std::vector<std::string> kValued = {
    "registry",      "key-file", "manufacturer", "model",    "version", "device-id", "description",
    "contact-email", "endpoint", "keys-dir",     "save-key", "q",       "tier",      "limit",
    "offset",        "prefix",   "role",         "label",    "save"};

std::string registry_url(const Options& o, const std::string& fallback = {}) {
  std::string u = o.get("registry");
  if (u.empty())
    if (const char* env = std::getenv("RCAN_REGISTRY")) u = env;
  if (u.empty()) u = fallback.empty() ? "http://127.0.0.1:8090" : fallback;
  while (!u.empty() && u.back() == '/') u.pop_back();
  return u;
}

// The API key, or empty (then `err` says why when required).
std::string api_key(const Options& o, bool required, std::string& err) {
  return secret_from(o, "key-file", "RCAN_REGISTRY_KEY_FILE", required, err);
}

// Percent-encodes a query value.
std::string q_escape(const std::string& s) {
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~') {
      out.push_back(static_cast<char>(c));
    } else {
      out.push_back('%');
      out.push_back(hex[c >> 4]);
      out.push_back(hex[c & 15]);
    }
  }
  return out;
}

std::string query(const Options& o, const std::vector<std::string>& names) {
  std::string q;
  for (const auto& n : names) {
    if (!o.has(n)) continue;
    q += (q.empty() ? "?" : "&") + n + "=" + q_escape(o.get(n));
  }
  return q;
}

struct Answer {
  int exit = 0;  // 0 2xx, 1 refused, 3 unreachable
  int status = 0;
  json::Value body;
  std::string text;
};

Answer call(const std::string& base, const std::string& method, const std::string& path,
            const std::string& body, const std::string& key,
            const std::vector<std::pair<std::string, std::string>>& headers = {}) {
  Answer a;
  auto r = node_request(base, method, path, body, key, headers);
  if (!r.ok()) {
    a.exit = 3;
    a.text = r.error().message;
    const std::string hint = " (is rcand running?)";  // the client library's, about nodes
    if (a.text.size() > hint.size() && a.text.ends_with(hint))
      a.text.resize(a.text.size() - hint.size());
    return a;
  }
  a.status = r->first;
  a.text = r->second;
  auto parsed = json::parse(r->second);
  if (parsed.ok()) a.body = std::move(*parsed);
  a.exit = a.status >= 200 && a.status < 300 ? 0 : 1;
  return a;
}

int report(const std::string& verb, const Answer& a) {
  if (a.exit == 3) {
    std::fprintf(stderr, "rcan %s: registry unreachable: %s\n", verb.c_str(), a.text.c_str());
    return 3;
  }
  std::cout << a.text << (a.text.empty() || a.text.back() != '\n' ? "\n" : "");
  if (a.exit != 0)
    std::fprintf(stderr, "rcan %s: the registry answered %d\n", verb.c_str(), a.status);
  return a.exit;
}

// Writes a secret the registry showed once to a new file with mode 0600.
bool save_secret(const std::string& path, const std::string& secret) {
  std::string line = secret + "\n";
  Status s = keys::write_new_file(
      path, std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(line.data()), line.size()),
      0600);
  if (!s.ok()) {
    std::fprintf(stderr, "rcan registry: cannot save the key to %s: %s\n", path.c_str(),
                 s.error().message.c_str());
    return false;
  }
  return true;
}

int do_register(const Options& o, const std::string& base, const std::string& key) {
  json::Object body;
  std::string slugs[4];
  const char* names[4] = {"manufacturer", "model", "version", "device-id"};
  for (int i = 0; i < 4; ++i) {
    slugs[i] = registry::slugify(o.get(names[i]));
    if (slugs[i].empty() || slugs[i] == "-")
      return usage_error("registry", std::string("register needs --") + names[i]);
  }
  body.set("manufacturer", slugs[0]);
  body.set("model", slugs[1]);
  body.set("version", slugs[2]);
  body.set("device_id", slugs[3]);
  for (const char* f : {"description", "contact-email"}) {
    if (!o.has(f)) continue;
    std::string name = f;
    for (char& c : name)
      if (c == '-') c = '_';
    body.set(name, o.get(f));
  }
  if (o.has("endpoint")) body.set("endpoints", json::Array{json::Value(o.get("endpoint"))});
  if (o.has("keys-dir")) {
    auto k = keys::load_dir(o.get("keys-dir"));
    if (!k.ok()) {
      std::fprintf(stderr, "rcan registry: %s\n", k.error().message.c_str());
      return 1;
    }
    Answer ch = call(base, "GET", "/api/v1/challenge", "", key);
    if (ch.exit != 0) return report("registry", ch);
    const json::Value* id = ch.body.get("challenge_id");
    const json::Value* nonce = ch.body.get("nonce");
    if (id == nullptr || nonce == nullptr || !id->is_string() || !nonce->is_string()) {
      std::fprintf(stderr, "rcan registry: the registry's challenge is malformed: %s\n",
                   ch.text.c_str());
      return 1;
    }
    auto proof =
        registry::sign_proof(*k, id->as_string(),
                             registry::proof_message(id->as_string(), nonce->as_string(), slugs[0],
                                                     slugs[1], slugs[2], slugs[3]));
    if (!proof.ok()) {
      std::fprintf(stderr, "rcan registry: %s\n", proof.error().message.c_str());
      return 1;
    }
    body.set("ed25519_public_key", base64url_encode(k->pub.ed25519_pk));
    body.set("mldsa65_public_key", base64url_encode(k->pub.mldsa65_pk));
    body.set("proof", proof->to_json());
  }
  Answer a = call(base, "POST", "/api/v1/robots", json::dump(json::Value(std::move(body))), key);
  int rc = report("registry", a);
  if (rc == 0 && o.has("save-key")) {
    const json::Value* robot_key = a.body.get("api_key");
    if (robot_key == nullptr || !robot_key->is_string()) {
      std::fprintf(stderr, "rcan registry: no robot key in the answer (already registered?)\n");
      return 1;
    }
    if (!save_secret(o.get("save-key"), robot_key->as_string())) return 1;
  }
  return rc;
}

int do_update(const Options& o, const std::string& base, const std::string& key,
              const std::string& rrn) {
  json::Object body;
  if (o.has("description")) body.set("description", o.get("description"));
  if (o.has("contact-email")) body.set("contact_email", o.get("contact-email"));
  if (o.has("endpoint")) body.set("endpoints", json::Array{json::Value(o.get("endpoint"))});
  if (body.empty())
    return usage_error("registry", "update needs --description, --contact-email or --endpoint");
  const std::string text = json::dump(json::Value(std::move(body)));
  std::vector<std::pair<std::string, std::string>> headers;
  if (o.has("keys-dir")) {  // a robot that proved its keys signs its own updates
    auto k = keys::load_dir(o.get("keys-dir"));
    if (!k.ok()) {
      std::fprintf(stderr, "rcan registry: %s\n", k.error().message.c_str());
      return 1;
    }
    const int64_t ts = unix_ms();
    auto sig = registry::sign_update(*k, registry::update_message(rrn, ts, text));
    if (!sig.ok()) {
      std::fprintf(stderr, "rcan registry: %s\n", sig.error().message.c_str());
      return 1;
    }
    headers = {{"X-RCAN-Timestamp", std::to_string(ts)}, {"X-RCAN-Signature", *sig}};
  }
  return report("registry", call(base, "PATCH", "/api/v1/robots/" + rrn, text, key, headers));
}

int do_keys(const Options& o, const std::string& base, const std::string& key) {
  const auto& pos = o.positional();
  const std::string sub = pos.size() > 1 ? pos[1] : "";
  if (sub == "list") return report("registry", call(base, "GET", "/api/v1/keys", "", key));
  if (sub == "revoke") {
    if (pos.size() < 3) return usage_error("registry", "keys revoke needs the key id");
    return report("registry", call(base, "DELETE", "/api/v1/keys/" + q_escape(pos[2]), "", key));
  }
  if (sub != "create") return usage_error("registry", "keys create|list|revoke ID");
  json::Object body;
  body.set("role", o.get("role", "registrant"));
  if (o.has("label")) body.set("label", o.get("label"));
  Answer a = call(base, "POST", "/api/v1/keys", json::dump(json::Value(std::move(body))), key);
  int rc = report("registry", a);
  if (rc == 0 && o.has("save")) {
    const json::Value* k = a.body.get("key");
    if (k == nullptr || !k->is_string()) {
      std::fprintf(stderr, "rcan registry: no key in the answer\n");
      return 1;
    }
    if (!save_secret(o.get("save"), k->as_string())) return 1;
  }
  return rc;
}

// A device request as the approver reads it, on stderr.
void print_device_request(const json::Value& r) {
  auto at = [&](const char* obj, const char* k) {
    const json::Value* o_v = r.get(obj);
    const json::Value* v = o_v != nullptr && o_v->is_object() ? o_v->get(k) : nullptr;
    return v != nullptr && v->is_string() ? v->as_string() : std::string("-");
  };
  const json::Value* grant = r.get("your_grant");
  std::string gives = "nothing: you hold no grant for it";
  if (grant != nullptr && grant->is_object()) {
    gives = json::string_field(*grant, "role");
    if (const json::Value* sc = grant->get("scopes"); sc != nullptr && sc->is_array()) {
      gives += " with";
      for (const auto& x : sc->as_array())
        if (x.is_string()) gives += " " + x.as_string();
    }
  }
  const std::string scope = json::string_field(r, "scope");
  std::fprintf(stderr,
               "device request %s\n  client      %s (%s, %s)\n  made by     API key %s (%s)\n"
               "  for         %s %s\n  scopes      %s\n  your grant  %s\n",
               json::string_field(r, "user_code").c_str(), at("client", "name").c_str(),
               at("client", "client_id").c_str(), at("client", "auth").c_str(),
               at("client", "created_by").c_str(), at("client", "created_by_label").c_str(),
               at("target", "resource").c_str(), at("target", "rcan_uri").c_str(),
               scope.empty() ? "all that the grant holds" : scope.c_str(), gives.c_str());
}

// device show|approve|deny CODE: an approval is made knowing what it approves (docs/THREATS.md
// T7): the request is shown first, and approved after a yes at the terminal or --yes.
int do_device(const Options& o, const std::string& base, const std::string& key) {
  const auto& pos = o.positional();
  const std::string verb = pos.size() > 1 ? pos[1] : "";
  if ((verb != "show" && verb != "approve" && verb != "deny") || pos.size() < 3)
    return usage_error("registry",
                       "device show CODE | device approve CODE [--yes] | device deny CODE");
  const std::string& code = pos[2];
  if (verb != "deny") {
    Answer shown = call(base, "GET", "/api/v1/device/requests/" + q_escape(code), "", key);
    if (verb == "show" || shown.exit != 0) return report("registry", shown);
    print_device_request(shown.body);
    if (!o.has("yes")) {
      if (::isatty(0) == 0)
        return usage_error("registry",
                           "approve asks at a terminal; give --yes to approve without asking "
                           "(read the request above first)");
      std::fprintf(stderr, "Approve? The token goes to whoever started this request. [y/N] ");
      std::string line;
      if (!std::getline(std::cin, line) || (line != "y" && line != "Y" && line != "yes")) {
        std::fprintf(stderr, "rcan registry: not approved\n");
        return 1;
      }
    }
  }
  json::Object body{{"user_code", code}, {"decision", verb}};
  return report("registry", call(base, "POST", "/api/v1/device/approve",
                                 json::dump(json::Value(std::move(body))), key));
}

int registry_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kUsage, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Options o(args, {"yes"}, kValued);
  if (!o.ok()) return usage_error("registry", o.error());
  const auto& pos = o.positional();
  if (pos.empty()) return usage_error("registry", "which command? (rcan registry --help)");
  const std::string& sub = pos[0];
  const std::string base = registry_url(o);
  const bool writes =
      sub == "register" || sub == "update" || sub == "delete" || sub == "keys" || sub == "device";
  std::string err;
  const std::string key = api_key(o, writes, err);
  if (!err.empty()) return usage_error("registry", err);

  auto rrn_arg = [&](std::string& out) {
    if (pos.size() < 2) return false;
    auto n = registry::normalize_rrn(pos[1]);
    if (!n) return false;
    out = *n;
    return true;
  };
  std::string rrn;
  if (sub == "register") return do_register(o, base, key);
  if (sub == "keys") return do_keys(o, base, key);
  if (sub == "device") return do_device(o, base, key);
  if (sub == "list")
    return report(
        "registry",
        call(base, "GET",
             "/api/v1/robots" + query(o, {"q", "manufacturer", "model", "tier", "limit", "offset"}),
             "", key));
  if (sub == "search")
    return report(
        "registry",
        call(base, "GET", "/api/v1/robots/search" + query(o, {"manufacturer", "model", "tier"}), "",
             key));
  if (sub == "nodes")
    return report("registry", call(base, "GET", "/api/v1/nodes" + query(o, {"prefix"}), "", key));
  if (sub == "manifest")
    return report("registry", call(base, "GET", "/.well-known/rcan-node.json", "", key));
  if (sub == "get" || sub == "resolve" || sub == "delete" || sub == "update") {
    if (!rrn_arg(rrn))
      return usage_error("registry", sub + " needs an RRN (RRN-000000000001, RRN-BD-…)");
    if (sub == "get")
      return report("registry", call(base, "GET", "/api/v1/robots/" + rrn, "", key));
    if (sub == "resolve")
      return report("registry", call(base, "GET", "/api/v1/resolve/" + rrn, "", key));
    if (sub == "delete")
      return report("registry", call(base, "DELETE", "/api/v1/robots/" + rrn, "", key));
    return do_update(o, base, key, rrn);
  }
  return usage_error("registry", "unknown command '" + sub + "' (rcan registry --help)");
}

// Prints where a resolved robot answers and its keys, one per line (the registry's resolve
// answer: rrn, record, keys {ed25519, mldsa65}, endpoints [{url, last_seen}]).
void print_resolved(const json::Value& v) {
  auto str = [](const json::Value* o, const char* k) {
    const json::Value* m = o != nullptr ? o->get(k) : nullptr;
    return m != nullptr && m->is_string() ? m->as_string() : std::string();
  };
  const json::Value* record = v.get("record");
  std::cout << "rrn: " << str(&v, "rrn") << "\n";
  std::cout << "rcan_uri: " << str(record, "rcan_uri") << "\n";
  if (const json::Value* eps = v.get("endpoints"); eps != nullptr && eps->is_array()) {
    for (const auto& e : eps->as_array()) {
      std::string seen = str(&e, "last_seen");
      std::cout << "endpoint: " << str(&e, "url")
                << (seen.empty() ? "" : " (last seen " + seen + ")") << "\n";
    }
  }
  const json::Value* keys = v.get("keys");
  for (const char* k : {"ed25519", "mldsa65"})
    if (!str(keys, k).empty()) std::cout << k << "_public_key: " << str(keys, k) << "\n";
}

int resolve_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kResolveUsage, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Options o(args, {"json"}, {"registry"});
  if (!o.ok()) return usage_error("resolve", o.error());
  if (o.positional().size() != 1) return usage_error("resolve", "one RRN or RURI");
  const std::string& what = o.positional()[0];
  Answer a;
  if (auto rrn = registry::normalize_rrn(what)) {
    a = call(registry_url(o), "GET", "/api/v1/resolve/" + *rrn, "", "");
  } else {
    auto r = parse_ruri(what);
    if (!r.ok()) return usage_error("resolve", "not an RRN or a RURI: " + r.error().message);
    a = call(registry_url(o, "https://" + r->registry), "GET",
             "/api/v1/resolve?uri=" + q_escape(what), "", "");
  }
  if (a.exit != 0 || o.has("json")) return report("resolve", a);
  print_resolved(a.body);
  return 0;
}

}  // namespace

Result<std::string> robot_url_from_registry(const std::string& rrn_or_ruri,
                                            const std::string& registry) {
  std::string base = registry;
  if (base.empty())
    if (const char* env = std::getenv("RCAN_REGISTRY"); env && *env) base = env;
  std::string path;
  if (auto rrn = registry::normalize_rrn(rrn_or_ruri)) {
    if (base.empty())
      return Error(ErrorCode::kSchemaValidationFailed,
                   "an RRN is resolved through a registry: --registry URL or RCAN_REGISTRY");
    path = "/api/v1/resolve/" + *rrn;
  } else {
    auto r = parse_ruri(rrn_or_ruri);
    if (!r.ok())
      return Error(ErrorCode::kInvalidRuri, "not a node URL, RRN or RURI: " + r.error().message);
    if (base.empty()) base = "https://" + r->registry;
    path = "/api/v1/resolve?uri=" + q_escape(rrn_or_ruri);
  }
  while (!base.empty() && base.back() == '/') base.pop_back();
  Answer a = call(base, "GET", path, "", "");
  if (a.exit == 3)
    return Error(ErrorCode::kNotFound, "registry " + base + " unreachable: " + a.text);
  if (a.exit != 0)
    return Error(ErrorCode::kNotFound, "registry " + base + " does not know " + rrn_or_ruri + " (" +
                                           std::to_string(a.status) + ")");
  if (const json::Value* eps = a.body.get("endpoints"); eps != nullptr && eps->is_array())
    for (const auto& e : eps->as_array())
      if (const json::Value* u = e.get("url");
          u != nullptr && u->is_string() && !u->as_string().empty())
        return u->as_string();
  return Error(ErrorCode::kNotFound,
               rrn_or_ruri + " has published no endpoint in registry " + base);
}

namespace {

const Registration kReg{"registry", "register, find and manage robots in an RCAN registry",
                        &registry_main};
const Registration kResolveReg{"resolve", "where a robot (RRN or RURI) answers, and its keys",
                               &resolve_main};

}  // namespace
}  // namespace rcan::cli
