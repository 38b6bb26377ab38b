// rcan token — issue and inspect JWTs (see include/rcan/crypto/jwt.h).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <optional>

#include "base/clock.h"
#include "base/strings.h"
#include "cli.h"
#include "login_cmd.h"
#include "node_http.h"
#include "rcan/crypto/cnf.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/errors.h"
#include "rcan/hash.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage:\n"
    "  rcan token get --registry URL --client-id ID (--client-secret-file F | --client-key K)\n"
    "                 --robot RRN|RURI|fleet:ID [--scope S] [--save F]\n"
    "      Asks rcan-registry's token authority for a token (client credentials).\n"
    "  rcan token issue --key FILE --sub S --role R --aud RURI [--scope a,b] [--ttl 1h]\n"
    "                   [--iss I] [--alg EdDSA|ES256|RS256|HS256] [--kid K] [--fleet id1,id2]\n"
    "                   [--sender-type T] [--cloud-provider P] [--function-name F]\n"
    "                   [--bind-key DIR [--bind-alg ed25519|ml-dsa-65]]\n"
    "      Prints a signed JWT. FILE is a PEM private key (Ed25519, P-256, RSA >= 2048) or a raw\n"
    "      32-byte ed25519.seed; with --alg HS256 it is a shared-secret file (>= 32 bytes, one\n"
    "      trailing newline ignored). The key file must not be group/world accessible. There is\n"
    "      no default key. R is creator|owner|leasee|user|guest. --iss defaults to \"rcan-cli\".\n"
    "      --bind-key binds the token to a key pair of DIR (`rcan keys generate --dir DIR`; its\n"
    "      public half, by default ed25519): the token carries a cnf claim (RFC 7800) and a robot\n"
    "      accepts it only on messages signed by that key. Tokens sent over MQTT must be bound.\n"
    "  rcan token inspect [TOKEN] [--key PUBFILE | --secret FILE] [--iss I] [--aud RURI]\n"
    "                     [--device ID] [--leeway S] [--now UNIX]\n"
    "      Reads the token from the argument or stdin and prints {header, claims}. Given a key\n"
    "      (PEM public key, JWK or JWKS; or an HS256 secret file) it verifies the token the way\n"
    "      the robot does: issuer --iss (default: the token's own iss, trusted because you named\n"
    "      the key), audience --aud (skipped when absent), fleet --device (skipped when absent).\n"
    "  rcan token revoke TOKEN | --jti J [--exp UNIX] | --sub S | --kid K  [--iss I]\n"
    "                    [--reason TEXT] [--url URL] [--token-file F]\n"
    "      Asks the robot (OWNER) to refuse a token from now on, also across restarts: TOKEN\n"
    "      (\"-\" reads it from stdin) by its jti; --sub every token of that subject issued so\n"
    "      far (of issuer --iss, else of any issuer); --kid every token signed under that key\n"
    "      id. Open streams of a revoked token are closed. URL and token as the other node verbs\n"
    "      ($RCAN_URL, $RCAN_TOKEN_FILE).\n"
    "  rcan token revocations [--url URL] [--token-file F]\n"
    "      Lists the robot's revocations (OWNER).\n"
    "  Issued tokens carry a fresh jti (a UUID). The robot's own issuer key is\n"
    "  <data dir>/issuer/ed25519.seed (issuer \"rcand-local\"): with --iss rcand-local it mints\n"
    "  tokens that robot accepts, e.g. a new OWNER token once owner.token (24 h) has expired.\n"
    "  Exit: 0 issued / valid / revoked (or decoded, without a key), 1 invalid or refused by the\n"
    "  robot, 2 usage, malformed token or no answer.\n";

int64_t unix_now() { return unix_seconds(); }

// The `cnf` claim for the public key of `alg` in the key directory `dir`.
Result<json::Value> bound_key_claim(const std::string& dir, const std::string& alg) {
  if (alg != "ed25519" && alg != "ml-dsa-65")
    return Error(ErrorCode::kSchemaValidationFailed, "--bind-alg must be ed25519 or ml-dsa-65");
  auto pub = keys::load_public_dir(dir);
  if (!pub.ok()) return Error(pub.error().code, "--bind-key " + dir + ": " + pub.error().message);
  if (alg == "ed25519") return cnf::make(msgsig::Alg::kEd25519, pub->ed25519_pk);
  return cnf::make(msgsig::Alg::kMlDsa65, pub->mldsa65_pk);
}

int issue_main(const Args& args) {
  Options o(args, {},
            {"key", "sub", "role", "scope", "aud", "ttl", "iss", "alg", "kid", "fleet",
             "sender-type", "cloud-provider", "function-name", "bind-key", "bind-alg"});
  if (!o.ok()) return usage_error("token issue", o.error());
  if (!o.positional().empty())
    return usage_error("token issue", "unexpected argument " + o.positional()[0]);
  if (!o.has("key") || o.get("key").empty())
    return usage_error("token issue", "--key FILE is required (there is no default signing key)");
  if (o.get("sub").empty()) return usage_error("token issue", "--sub is required");
  if (o.get("aud").empty()) return usage_error("token issue", "--aud is required");
  if (o.get("aud").rfind("rcan://", 0) != 0)
    return usage_error("token issue", "--aud must be an rcan:// RURI");
  std::string role = o.get("role");
  if (jwt::role_level(role) == 0)
    return usage_error("token issue", "--role must be one of creator, owner, leasee, user, guest");
  auto ttl = jwt::parse_duration(o.get("ttl", "1h"));
  if (!ttl) return usage_error("token issue", "--ttl must look like 90s, 15m, 1h or 7d");
  std::optional<jwt::Alg> want;
  if (o.has("alg")) {
    want = jwt::alg_from_name(o.get("alg"));
    if (!want) return usage_error("token issue", "--alg must be EdDSA, ES256, RS256 or HS256");
  }
  auto key = jwt::SigningKey::from_file(o.get("key"), want == jwt::Alg::kHS256);
  if (!key.ok()) return usage_error("token issue", key.error().message);
  if (want && *want != key->alg())
    return usage_error("token issue", "--alg " + o.get("alg") + " does not match the key (a " +
                                          std::string(jwt::alg_name(key->alg())) + " key)");
  std::string sender_type = o.get("sender-type");
  if (!sender_type.empty() && sender_type != "human" && sender_type != "robot" &&
      sender_type != "cloud_function" && sender_type != "system")
    return usage_error("token issue",
                       "--sender-type must be human, robot, cloud_function or system");
  if (sender_type == "cloud_function" && o.get("cloud-provider").empty())
    return usage_error("token issue",
                       "--sender-type cloud_function needs --cloud-provider (RCAN 8.5)");

  std::optional<json::Value> cnf;
  if (o.has("bind-key")) {
    auto bound = bound_key_claim(o.get("bind-key"), o.get("bind-alg", "ed25519"));
    if (!bound.ok()) return usage_error("token issue", bound.error().message);
    cnf = std::move(bound).value();
  } else if (o.has("bind-alg")) {
    return usage_error("token issue", "--bind-alg goes with --bind-key");
  }

  int64_t now = unix_now();
  json::Object c;
  c.set("iss", o.get("iss", "rcan-cli"));
  c.set("sub", o.get("sub"));
  c.set("aud", o.get("aud"));
  c.set("role", role);
  json::Array scopes;
  for (auto& s : split_list(o.get("scope"))) scopes.emplace_back(s);
  c.set("scope", std::move(scopes));
  if (o.has("fleet")) {
    json::Array fleet;
    for (auto& s : split_list(o.get("fleet"))) fleet.emplace_back(s);
    c.set("fleet", std::move(fleet));
  }
  if (!sender_type.empty()) c.set("sender_type", sender_type);
  if (!o.get("cloud-provider").empty()) c.set("cloud_provider", o.get("cloud-provider"));
  if (!o.get("function-name").empty()) c.set("function_name", o.get("function-name"));
  c.set("iat", now);
  c.set("exp", now + *ttl);
  c.set("jti", new_uuid_v4());  // what `rcan token revoke` names it by
  if (cnf) c.set("cnf", std::move(*cnf));
  auto tok = jwt::issue(c, *key, o.get("kid"));
  if (!tok.ok()) {
    std::fprintf(stderr, "rcan token issue: %s\n", tok.error().message.c_str());
    return 1;
  }
  std::cout << *tok << "\n";
  return 0;
}

int inspect_main(const Args& args) {
  Options o(args, {}, {"key", "secret", "iss", "aud", "device", "leeway", "now"});
  if (!o.ok()) return usage_error("token inspect", o.error());
  if (o.positional().size() > 1) return usage_error("token inspect", "give at most one token");
  if (o.has("key") && o.has("secret"))
    return usage_error("token inspect", "give --key or --secret, not both");
  std::string token(trim(o.positional().empty() ? read_stdin() : o.positional()[0]));
  auto d = jwt::decode(token);
  json::Object out;
  if (!d.ok()) {
    out.set("valid", false);
    out.set("error", d.error().message);
    std::cout << json::dump(out) << "\n";
    return 2;
  }
  out.set("header", json::Value(d->header.raw));
  out.set("claims", json::Value(d->claims));
  if (!o.has("key") && !o.has("secret")) {
    out.set("verified", false);
    std::cout << json::dump(out) << "\n";
    return 0;
  }
  bool secret = o.has("secret");
  auto keys = jwt::load_verification_keys(secret ? o.get("secret") : o.get("key"), secret);
  if (!keys.ok()) return usage_error("token inspect", keys.error().message);
  std::string iss = o.get("iss");
  if (iss.empty()) {
    const json::Value* ti = d->claims.find("iss");
    if (ti && ti->is_string()) iss = ti->as_string();
  }
  jwt::TrustStore ts;
  for (auto& k : *keys) ts.add(iss, k);
  jwt::VerifyOptions vo;
  vo.audience = o.get("aud");
  vo.skip_audience = vo.audience.empty();
  if (o.has("device")) vo.fleet_ids = {o.get("device")};
  vo.skip_fleet = !o.has("device");
  vo.require_role = false;
  int64_t now = unix_now();
  try {
    if (o.has("leeway")) vo.leeway_s = std::stoll(o.get("leeway"));
    if (o.has("now")) now = std::stoll(o.get("now"));
  } catch (...) {
    return usage_error("token inspect", "--leeway and --now take integers");
  }
  jwt::JwtVerifier v(std::move(ts), vo);
  auto r = v.verify(token, now);
  out.set("verified", true);
  if (!r.ok()) {
    out.set("valid", false);
    out.set("error_code", std::string(error_name(r.error().code)));
    out.set("error", r.error().message);
    out.set("reason", r.error().reason);
    std::cout << json::dump(out) << "\n";
    return 1;
  }
  out.set("valid", true);
  out.set("role", r->role);
  out.set("role_level", r->role_level);
  json::Array scopes;
  for (auto& s : r->scopes) scopes.emplace_back(s);
  out.set("scopes", std::move(scopes));
  if (vo.skip_audience) out.set("note", "audience not checked (no --aud)");
  std::cout << json::dump(out) << "\n";
  return 0;
}

// Runs one call against the node and prints its answer: 0 on 2xx, 1 refused, 2 no answer.
int node_call(const char* verb, const Options& o, const std::string& method,
              const std::string& body) {
  std::string err;
  std::string token = node_token(o, true, err);
  if (!err.empty()) return usage_error(verb, err);
  auto r = node_request(node_url(o), method, "/rcan/v1/revocations", body, token);
  if (!r.ok()) {
    std::fprintf(stderr, "rcan %s: %s\n", verb, r.error().message.c_str());
    return 2;
  }
  std::cout << r->second << (r->second.empty() || r->second.back() != '\n' ? "\n" : "");
  return r->first >= 200 && r->first < 300 ? 0 : 1;
}

int revoke_main(const Args& args) {
  Options o(args, {}, {"jti", "sub", "kid", "iss", "exp", "reason", "url", "token-file"});
  if (!o.ok()) return usage_error("token revoke", o.error());
  if (o.positional().size() > 1) return usage_error("token revoke", "give at most one TOKEN");
  json::Object body;
  int given = o.positional().empty() ? 0 : 1;
  if (!o.positional().empty()) {
    std::string t = o.positional()[0];
    if (t == "-") {
      std::string line;
      std::getline(std::cin, line);
      t = line;
    }
    t = std::string(trim(t));
    if (t.empty()) return usage_error("token revoke", "TOKEN is empty");
    body.set("token", t);
  }
  for (const char* k : {"jti", "sub", "kid"}) {
    if (!o.has(k)) continue;
    if (o.get(k).empty()) return usage_error("token revoke", std::string("--") + k + " is empty");
    body.set(k, o.get(k));
    ++given;
  }
  if (given != 1)
    return usage_error("token revoke", "give exactly one of TOKEN, --jti, --sub or --kid");
  if (o.has("iss")) body.set("iss", o.get("iss"));
  if (o.has("exp")) {
    if (!o.has("jti")) return usage_error("token revoke", "--exp goes with --jti");
    char* end = nullptr;
    long long e = std::strtoll(o.get("exp").c_str(), &end, 10);
    if (o.get("exp").empty() || *end)
      return usage_error("token revoke", "--exp takes unix seconds");
    body.set("exp", static_cast<int64_t>(e));
  }
  if (o.has("reason")) body.set("reason", o.get("reason"));
  return node_call("token revoke", o, "POST", json::dump(json::Value(std::move(body))));
}

int revocations_main(const Args& args) {
  Options o(args, {}, {"url", "token-file"});
  if (!o.ok()) return usage_error("token revocations", o.error());
  if (!o.positional().empty())
    return usage_error("token revocations", "unexpected argument " + o.positional()[0]);
  return node_call("token revocations", o, "GET", "");
}

int token_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Args rest(args.begin() + 1, args.end());
  if (args[0] == "issue") return issue_main(rest);
  if (args[0] == "inspect") return inspect_main(rest);
  if (args[0] == "get") return token_get_main(rest);
  if (!rest.empty() && (rest[0] == "--help" || rest[0] == "-h")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (args[0] == "revoke") return revoke_main(rest);
  if (args[0] == "revocations") return revocations_main(rest);
  return usage_error(
      "token", "unknown subcommand " + args[0] + " (issue | inspect | get | revoke | revocations)");
}

const Registration kReg{"token", "issue, inspect and revoke JWTs", &token_main};

}  // namespace
}  // namespace rcan::cli
