// rcan login (the device authorization grant, RFC 8628) and rcan token get (client credentials,
// with a client secret or private_key_jwt, RFC 7523) against rcan-registry's token authority
// (docs/REGISTRY.md "Token authority"). The access token is printed, or saved with mode 0600.
#include "login_cmd.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <thread>

#include "base/clock.h"
#include "client/net.h"
#include "rcan/client.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/errors.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

constexpr const char* kLoginUsage =
    "usage: rcan login --registry URL --client-id ID --resource RRN|RURI|fleet:ID [--scope S]\n"
    "                  [--client-secret-file F | --client-key DIR-or-seed-file] [--save F]\n"
    "  Asks the registry for a token by the device flow: prints a code and the page where a\n"
    "  person approves it (POST /api/v1/device/approve with their API key), then waits. A\n"
    "  public client (auth none) needs no credential; a confidential one authenticates as with\n"
    "  rcan token get. The token is printed, or written to F (mode 0600). Exit: 0 token,\n"
    "  1 refused or expired, 2 usage, 3 unreachable.\n";

constexpr const char* kGetUsage =
    "usage: rcan token get --registry URL --client-id ID\n"
    "                      (--client-secret-file F | --client-key DIR-or-seed-file)\n"
    "                      --robot RRN|RURI|fleet:ID [--scope S] [--save F]\n"
    "  Client credentials: the secret (client_secret_basic) or a private_key_jwt assertion\n"
    "  signed with the Ed25519 seed (DIR/ed25519.seed, or the seed file itself). Exit: 0 token,\n"
    "  1 refused, 2 usage, 3 unreachable.\n";

std::string form_escape(std::string_view s) {
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (unsigned char c : s) {
    if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
        c == '.' || c == '_' || c == '~') {
      out.push_back(static_cast<char>(c));
    } else {
      out.push_back('%');
      out.push_back(hex[c >> 4]);
      out.push_back(hex[c & 15]);
    }
  }
  return out;
}

struct Reply {
  int exit = 0;  // 0 2xx, 1 refused, 3 unreachable
  int status = 0;
  json::Value body;
  std::string text;
};

Reply post_form(const std::string& base, const std::string& path, const std::string& body) {
  Reply a;
  auto ep = client::parse_endpoint(base);
  if (!ep.ok()) {
    a.exit = 3;
    a.text = ep.error().message;
    return a;
  }
  auto r = client::net::http_exchange(*ep, "POST", path, body,
                                      {{"Content-Type", "application/x-www-form-urlencoded"}},
                                      15000, "", false);
  if (!r.ok()) {
    a.exit = 3;
    a.text = r.error().message;
    return a;
  }
  a.status = r->status;
  a.text = r->body;
  auto parsed = json::parse(r->body);
  if (parsed.ok()) a.body = std::move(*parsed);
  a.exit = a.status >= 200 && a.status < 300 ? 0 : 1;
  return a;
}

int64_t num(const json::Value& v, const char* k, int64_t def) {
  const json::Value* x = v.is_object() ? v.get(k) : nullptr;
  return x != nullptr && x->is_int() ? x->as_int() : def;
}

std::string base_of(const Options& o) {
  std::string u = o.get("registry");
  if (u.empty())
    if (const char* env = std::getenv("RCAN_REGISTRY")) u = env;
  if (u.empty()) u = "http://127.0.0.1:8090";
  while (!u.empty() && u.back() == '/') u.pop_back();
  return u;
}

int deliver(const std::string& verb, const Options& o, const Reply& a) {
  std::string token = json::string_field(a.body, "access_token");
  if (token.empty()) {
    std::fprintf(stderr, "rcan %s: no access_token in the answer\n", verb.c_str());
    return 1;
  }
  if (!o.has("save")) {
    std::cout << token << "\n";
    return 0;
  }
  std::string line = token + "\n";
  Status s = keys::write_new_file(
      o.get("save"),
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(line.data()), line.size()), 0600);
  if (!s.ok()) {
    std::fprintf(stderr, "rcan %s: %s\n", verb.c_str(), s.error().message.c_str());
    return 1;
  }
  std::fprintf(stderr, "rcan %s: token saved to %s (expires in %lld s)\n", verb.c_str(),
               o.get("save").c_str(), static_cast<long long>(num(a.body, "expires_in", 0)));
  return 0;
}

int refused(const std::string& verb, const Reply& a) {
  if (a.exit == 3) {
    std::fprintf(stderr, "rcan %s: registry unreachable: %s\n", verb.c_str(), a.text.c_str());
    return 3;
  }
  std::fprintf(stderr, "rcan %s: the registry answered %d: %s %s\n", verb.c_str(), a.status,
               json::string_field(a.body, "error").c_str(),
               json::string_field(a.body, "error_description").c_str());
  return 1;
}

// The client's credential as form fields ("&client_id=…&client_secret=…", or a fresh
// private_key_jwt assertion: one per request, its jti is used once); "&client_id=…" alone for a
// public client (neither option given).
Result<std::string> client_auth(const Options& o, const std::string& id, const std::string& base) {
  if (o.has("client-secret-file")) {
    auto secret = read_file(o.get("client-secret-file"));
    if (!secret.ok()) return secret.error();
    std::string s = *secret;
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
    return "&client_id=" + form_escape(id) + "&client_secret=" + form_escape(s);
  }
  if (!o.has("client-key")) return "&client_id=" + form_escape(id);
  std::string path = o.get("client-key");
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) path += "/ed25519.seed";
  auto key = jwt::SigningKey::from_file(path);
  if (!key.ok()) return key.error();
  if (key->alg() != jwt::Alg::kEdDSA)
    return Error(ErrorCode::kSchemaValidationFailed, "--client-key must be an Ed25519 key");
  const int64_t now = unix_seconds();
  json::Object c{{"iss", id},  {"sub", id},        {"aud", base + "/oauth/token"},
                 {"iat", now}, {"exp", now + 120}, {"jti", new_uuid_v4()}};
  auto assertion = jwt::issue(c, *key);
  if (!assertion.ok()) return assertion.error();
  return "&client_id=" + form_escape(id) +
         "&client_assertion_type=urn%3Aietf%3Aparams%3Aoauth%3Aclient-assertion-type%3Ajwt-"
         "bearer&client_assertion=" +
         *assertion;
}

int login_main(const Args& args) {
  Options o(
      args, {"help"},
      {"registry", "client-id", "resource", "scope", "save", "client-secret-file", "client-key"});
  if (!o.ok()) return usage_error("login", o.error());
  if (o.has("help")) {
    std::fputs(kLoginUsage, stdout);
    return 0;
  }
  if (o.get("client-id").empty() || o.get("resource").empty())
    return usage_error("login", "--client-id and --resource are required");
  if (o.has("client-secret-file") && o.has("client-key"))
    return usage_error("login", "give at most one of --client-secret-file and --client-key");
  std::string base = base_of(o);
  auto auth = client_auth(o, o.get("client-id"), base);
  if (!auth.ok()) return usage_error("login", auth.error().message);
  std::string body = "resource=" + form_escape(o.get("resource")) + *auth;
  if (o.has("scope")) body += "&scope=" + form_escape(o.get("scope"));
  Reply da = post_form(base, "/oauth/device_authorization", body);
  if (da.exit != 0) return refused("login", da);
  std::string device_code = json::string_field(da.body, "device_code");
  int64_t interval = num(da.body, "interval", 5);
  int64_t expires_in = num(da.body, "expires_in", 600);
  std::fprintf(stderr,
               "To approve, open %s and enter the code %s\n  (or: %s)\nWaiting for approval…\n",
               json::string_field(da.body, "verification_uri").c_str(),
               json::string_field(da.body, "user_code").c_str(),
               json::string_field(da.body, "verification_uri_complete").c_str());
  auto deadline = steady_now() + std::chrono::seconds(expires_in + 5);
  while (steady_now() < deadline) {
    std::this_thread::sleep_for(std::chrono::seconds(interval));
    auto poll_auth = client_auth(o, o.get("client-id"), base);
    if (!poll_auth.ok()) return usage_error("login", poll_auth.error().message);
    Reply t = post_form(base, "/oauth/token",
                        "grant_type=urn%3Aietf%3Aparams%3Aoauth%3Agrant-type%3Adevice_code"
                        "&device_code=" +
                            form_escape(device_code) + *poll_auth);
    if (t.exit == 0) return deliver("login", o, t);
    std::string err = json::string_field(t.body, "error");
    if (err == "authorization_pending") continue;
    if (err == "slow_down") {
      interval += 5;
      continue;
    }
    return refused("login", t);
  }
  std::fprintf(stderr, "rcan login: the code expired before it was approved\n");
  return 1;
}

}  // namespace

int token_get_main(const Args& args) {
  Options o(
      args, {"help"},
      {"registry", "client-id", "client-secret-file", "client-key", "robot", "scope", "save"});
  if (!o.ok()) return usage_error("token get", o.error());
  if (o.has("help")) {
    std::fputs(kGetUsage, stdout);
    return 0;
  }
  std::string id = o.get("client-id"), robot = o.get("robot");
  if (id.empty() || robot.empty())
    return usage_error("token get", "--client-id and --robot are required");
  if (o.has("client-secret-file") == o.has("client-key"))
    return usage_error("token get", "give one of --client-secret-file and --client-key");
  std::string base = base_of(o);
  std::string body = "grant_type=client_credentials&resource=" + form_escape(robot);
  if (o.has("scope")) body += "&scope=" + form_escape(o.get("scope"));
  auto auth = client_auth(o, id, base);
  if (!auth.ok()) return usage_error("token get", auth.error().message);
  body += *auth;
  Reply t = post_form(base, "/oauth/token", body);
  if (t.exit != 0) return refused("token get", t);
  return deliver("token get", o, t);
}

namespace {
const Registration kReg{
    "login", "get a token from a registry by the device flow (a person approves)", &login_main};
}  // namespace

}  // namespace rcan::cli
