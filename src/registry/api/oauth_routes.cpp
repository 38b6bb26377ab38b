// The OAuth 2.0 endpoints of the token authority: POST /oauth/token (client credentials,
// device code), POST /oauth/device_authorization and POST /oauth/introspect.
#include "rcan/crypto/ed25519.h"
#include "rcan/hash.h"
#include "registry/api/authority_internal.h"
#include "registry/api/oauth_form.h"

namespace rcan::registry::api {
namespace {

constexpr const char* kAssertionType = "urn:ietf:params:oauth:client-assertion-type:jwt-bearer";
constexpr const char* kDeviceGrant = "urn:ietf:params:oauth:grant-type:device_code";

bool form_content(const HttpRequest& req) {
  std::string_view ct = req.header("content-type");
  return ct.rfind("application/x-www-form-urlencoded", 0) == 0;
}

// The OAuth error of a Result's error (reason names it when it is one).
HttpResponse grant_error(const Error& e) {
  if (e.reason == "unauthorized_client") return oauth_error(400, "unauthorized_client", e.message);
  if (e.reason == "invalid_scope") return oauth_error(400, "invalid_scope", e.message);
  if (e.code == ErrorCode::kInternal) return store_error(e);
  return oauth_error(400, "invalid_request", e.message);
}

}  // namespace

// Authenticates the client of a token or introspection request: HTTP Basic, client_secret in
// the form, or a private_key_jwt assertion (RFC 7523). nullopt with `err` set (401
// invalid_client, or 400 invalid_request for a request using two methods).
std::optional<Client> RegistryApi::Impl::authenticate_client(const HttpRequest& req, const Form& f,
                                                             HttpResponse& err, bool allow_public) {
  auto basic = parse_basic(req.header("authorization"));
  int methods =
      (basic ? 1 : 0) + (f.has("client_secret") ? 1 : 0) + (f.has("client_assertion") ? 1 : 0);
  if (methods > 1) {
    err = oauth_error(400, "invalid_request", "use one client authentication method");
    return std::nullopt;
  }
  auto fail = [&](const std::string& why) {
    err = oauth_error(401, "invalid_client", why);
    if (basic) err.headers.emplace_back("WWW-Authenticate", "Basic realm=\"rcan-registry\"");
    return std::nullopt;
  };
  std::string id;
  if (basic)
    id = basic->id;
  else if (f.has("client_assertion")) {
    if (f.get("client_assertion_type") != kAssertionType)
      return fail("client_assertion_type must be " + std::string(kAssertionType));
    auto d = jwt::decode(f.get("client_assertion"));
    if (!d) return fail("the client assertion is not a JWT");
    const json::Value* iss = d->claims.find("iss");
    if (iss == nullptr || !iss->is_string()) return fail("the client assertion has no iss");
    id = iss->as_string();
    if (f.has("client_id") && f.get("client_id") != id)
      return fail("client_id and the assertion's iss differ");
  } else {
    id = f.get("client_id");
  }
  if (id.empty() || id.size() > 64) return fail("client authentication failed");
  auto c = store.get_client(id);
  if (!c) {
    err = store_error(c.error());
    return std::nullopt;
  }
  if (!*c) return fail("client authentication failed");
  const Client& client = **c;
  if (methods == 0) {
    // Only a public client (auth "none", made for the device flow) goes without: a confidential
    // client's id is no secret, and whoever starts a device request under it gets the token the
    // approver meant for that client (docs/THREATS.md T7).
    if (allow_public && client.auth == "none") return client;
    return fail(client.auth == "none" ? "a public client is for the device flow only"
                                      : "client authentication required: this client is "
                                        "confidential (" +
                                            client.auth + ")");
  }
  if (basic || f.has("client_secret")) {
    if (client.auth != "client_secret") return fail("client authentication failed");
    std::string secret = basic ? basic->secret : f.get("client_secret");
    if (!constant_time_equal(sha256_hex(client.salt + secret), client.hash))
      return fail("client authentication failed");
    return client;
  }
  // private_key_jwt: signed by the registered key, iss = sub = client_id, aud = the token
  // endpoint, exp at most 5 minutes ahead, jti used once.
  if (client.auth != "private_key_jwt") return fail("client authentication failed");
  auto jwk = json::parse(client.jwk);
  if (!jwk) return fail("client authentication failed");
  auto vk = jwt::VerificationKey::from_jwk(*jwk);
  if (!vk) return fail("client authentication failed");
  std::string assertion = f.get("client_assertion");
  auto d = jwt::decode(assertion);
  if (!d || d->header.alg != jwt::alg_name(vk->alg()) ||
      !vk->verify(d->signing_input, d->signature))
    return fail("the client assertion's signature does not verify");
  auto str = [&](const char* k) -> std::string {
    const json::Value* v = d->claims.find(k);
    return v != nullptr && v->is_string() ? v->as_string() : "";
  };
  if (str("sub") != id) return fail("the client assertion's sub must be the client id");
  std::string endpoint = o.public_url + "/oauth/token";
  bool aud_ok = false;
  if (const json::Value* a_v = d->claims.find("aud")) {
    if (a_v->is_string()) aud_ok = a_v->as_string() == endpoint;
    if (a_v->is_array())
      for (const auto& a : a_v->as_array())
        aud_ok = aud_ok || (a.is_string() && a.as_string() == endpoint);
  }
  if (!aud_ok) return fail("the client assertion's aud must be " + endpoint);
  const json::Value* exp_v = d->claims.find("exp");
  if (exp_v == nullptr || !exp_v->is_int()) return fail("the client assertion has no exp");
  int64_t now = now_ms();
  int64_t exp = exp_v->as_int();
  if (exp * 1000 <= now) return fail("the client assertion has expired");
  if (exp * 1000 > now + 300000 + 60000)
    return fail("the client assertion's exp is more than 5 minutes ahead");
  std::string jti = str("jti");
  if (jti.empty() || jti.size() > 256) return fail("the client assertion needs a jti");
  auto fresh = store.use_jti(id + ":" + jti, exp * 1000, now);
  if (!fresh) {
    err = store_error(fresh.error());
    return std::nullopt;
  }
  if (!*fresh) return fail("the client assertion was already used");
  return client;
}

HttpResponse RegistryApi::Impl::oauth_token(const HttpRequest& req) {
  if (req.method != "POST") return oauth_error(405, "invalid_request", "use POST");
  if (!form_content(req))
    return oauth_error(400, "invalid_request",
                       "the body must be application/x-www-form-urlencoded");
  auto f = parse_form(req.body);
  if (!f) return oauth_error(400, "invalid_request", f.error().message);
  std::string gt = f->get("grant_type");
  if (gt.empty()) return oauth_error(400, "invalid_request", "grant_type is required");
  if (gt != "client_credentials" && gt != kDeviceGrant)
    return oauth_error(400, "unsupported_grant_type",
                       "grant_type must be client_credentials or " + std::string(kDeviceGrant));
  HttpResponse err;
  auto client = authenticate_client(req, *f, err, gt == kDeviceGrant);
  if (!client) return err;
  if (auto a = audit_unavailable()) return *a;
  if (gt == kDeviceGrant) return device_token(*client, *f);
  std::string resource = f->has("resource") ? f->get("resource") : f->get("audience");
  if (resource.empty())
    return oauth_error(400, "invalid_request",
                       "resource (an RRN, a RURI or fleet:<id>) is required");
  auto t = resolve_target(resource);
  if (!t) return grant_error(t.error());
  auto c = choose_grant(client->id, *t, f->get("scope"), f->get("role"));
  if (!c) return grant_error(c.error());
  return issue_token(client->id, *t, *c);
}

// GET /device (RFC 8628 verification_uri): what the person at a browser does with the code a
// device showed them. The page reflects nothing but a well-formed user code and the registry's
// own URL (escaped), and runs no script.
HttpResponse RegistryApi::Impl::device_page(const HttpRequest& req) {
  auto escape = [](std::string_view in) {
    std::string out;
    for (char c : in) {
      switch (c) {
        case '<':
          out += "&lt;";
          break;
        case '>':
          out += "&gt;";
          break;
        case '&':
          out += "&amp;";
          break;
        case '"':
          out += "&quot;";
          break;
        case '\'':
          out += "&#39;";
          break;
        default:
          out.push_back(c);
      }
    }
    return out;
  };
  const std::string code = normalize_user_code(req.query_value("user_code"));
  const std::string shown = code.empty() ? "CODE" : code;
  // What is asked, so that a person approves knowing it (docs/THREATS.md T7): the client by
  // name and id and who made it, the robot or fleet, the scopes. Only for a pending code.
  std::string asked;
  if (!code.empty())
    if (auto req_json = device_request(code); req_json.ok()) {
      const json::Object& d = *req_json;
      auto field = [&](const char* obj, const char* k) {
        const json::Value* o_v = d.find(obj);
        const json::Value* v = o_v != nullptr && o_v->is_object() ? o_v->get(k) : nullptr;
        return v != nullptr && v->is_string() ? escape(v->as_string()) : std::string("?");
      };
      const json::Value* scope = d.find("scope");
      // Anyone holding the code reads this page: the client's name and what it asks for, not
      // who made it (an API key's id and label are for an approver, device show).
      asked = "<table>\n<tr><th>client</th><td>" + field("client", "name") +
              "</td></tr>\n<tr><th>for</th><td>" + field("target", "resource") +
              "</td></tr>\n<tr><th>scopes</th><td>" +
              (scope != nullptr && scope->is_string() && !scope->as_string().empty()
                   ? escape(scope->as_string())
                   : std::string("all that your grant holds")) +
              "</td></tr>\n</table>\n<p>A client's name is whatever its maker chose. Approve "
              "only a request you started yourself: the token goes to whoever holds it. "
              "<code>rcan registry device show " +
              code + "</code> names the API key that made the client.</p>\n";
    }
  const std::string url = escape(o.public_url);
  HttpResponse r;
  r.content_type = "text/html; charset=utf-8";
  r.headers.emplace_back("Content-Security-Policy", "default-src 'none'; base-uri 'none'");
  r.headers.emplace_back("Cache-Control", "no-store");
  r.body =
      "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
      "<title>Approve a device - rcan-registry</title></head><body>\n<h1>Approve a device</h1>\n" +
      std::string(code.empty()
                      ? "<p>A program (rcan login, or a robot's own tooling) shows you a code of "
                        "eight letters and sends you here.</p>\n"
                      : "<p>A program asked this registry for a token and showed you the code "
                        "<strong>" +
                            code + "</strong>.</p>\n" + asked) +
      "<p>If you started it, approve it with your registry API key:</p>\n<pre>rcan registry "
      "device approve " +
      shown + " --registry " + url +
      " --key-file YOUR-KEY-FILE</pre>\n<p>If you did not, refuse it:</p>\n<pre>rcan registry "
      "device deny " +
      shown + " --registry " + url +
      " --key-file YOUR-KEY-FILE</pre>\n<p>The token carries only the grants your key holds on "
      "the robot or fleet the program asked for. A code expires " +
      std::to_string(o.device_ttl_s / 60) +
      " minutes after it was shown; the same decision is <code>POST /api/v1/device/approve</code> "
      "with your key.</p>\n</body></html>\n";
  return r;
}

HttpResponse RegistryApi::Impl::device_authorization(const HttpRequest& req) {
  if (req.method != "POST") return oauth_error(405, "invalid_request", "use POST");
  if (!form_content(req))
    return oauth_error(400, "invalid_request",
                       "the body must be application/x-www-form-urlencoded");
  auto f = parse_form(req.body);
  if (!f) return oauth_error(400, "invalid_request", f.error().message);
  HttpResponse err;
  auto client = authenticate_client(req, *f, err, true);
  if (!client) return err;
  std::string resource = f->has("resource") ? f->get("resource") : f->get("audience");
  if (resource.empty()) return oauth_error(400, "invalid_request", "resource is required");
  auto t = resolve_target(resource);
  if (!t) return grant_error(t.error());
  if (!parse_scope(f->get("scope"))) return oauth_error(400, "invalid_scope", "malformed scope");
  DeviceCode d;
  std::string device_code = random_b64url(32);
  Bytes raw(8);
  if (device_code.empty() || !random_bytes(raw.data(), raw.size()))
    return store_error(Error(ErrorCode::kInternal, "no randomness"));
  std::string code;
  for (uint8_t b : raw) code.push_back(kUserCodeAlphabet[b % 20]);
  d.device_hash = sha256_hex(device_code);
  d.user_code = code.substr(0, 4) + "-" + code.substr(4);
  d.client_id = client->id;
  d.resource = resource;
  d.scope = f->get("scope");
  int64_t now = now_ms();
  d.expires_ms = now + o.device_ttl_s * 1000;
  d.interval_s = o.device_interval_s;
  d.last_poll_ms = 0;
  if (Status s = store.put_device_code(d); !s.ok()) return store_error(s.error());
  std::string uri = o.public_url + "/device";
  HttpResponse r = json_response(
      200, json::Object{{"device_code", device_code},
                        {"user_code", d.user_code},
                        {"verification_uri", uri},
                        {"verification_uri_complete", uri + "?user_code=" + d.user_code},
                        {"expires_in", o.device_ttl_s},
                        {"interval", o.device_interval_s}});
  r.headers.emplace_back("Cache-Control", "no-store");
  return r;
}

HttpResponse RegistryApi::Impl::device_token(const Client& client, const Form& f) {
  std::string code = f.get("device_code");
  if (code.empty() || code.size() > 256)
    return oauth_error(400, "invalid_request", "device_code is required");
  std::string hash = sha256_hex(code);
  auto d = store.device_by_hash(hash);
  if (!d) return store_error(d.error());
  if (!*d || (*d)->client_id != client.id)
    return oauth_error(400, "invalid_grant", "unknown device_code");
  int64_t now = now_ms();
  if (now >= (*d)->expires_ms) {
    (void)store.delete_device(hash);
    return oauth_error(400, "expired_token", "the device code has expired");
  }
  if ((*d)->status == "denied") {
    (void)store.delete_device(hash);
    return oauth_error(400, "access_denied", "the request was denied");
  }
  if ((*d)->status == "pending") {
    bool fast = (*d)->last_poll_ms > 0 && now - (*d)->last_poll_ms < (*d)->interval_s * 1000;
    int64_t interval = fast ? (*d)->interval_s + 5 : (*d)->interval_s;
    if (Status s = store.touch_device(hash, now, interval); !s.ok()) return store_error(s.error());
    if (fast) return oauth_error(400, "slow_down", "poll every " + std::to_string(interval) + " s");
    return oauth_error(400, "authorization_pending", "waiting for the person to approve");
  }
  auto gone = store.delete_device(hash);  // one token per approval
  if (!gone) return store_error(gone.error());
  if (!*gone) return oauth_error(400, "invalid_grant", "the device code was already used");
  auto t = resolve_target((*d)->resource);
  if (!t) return grant_error(t.error());
  auto c = choose_grant((*d)->subject, *t, (*d)->scope, "");
  if (!c) return grant_error(c.error());
  return issue_token((*d)->subject, *t, *c);
}

HttpResponse RegistryApi::Impl::introspect(const HttpRequest& req) {
  if (req.method != "POST") return oauth_error(405, "invalid_request", "use POST");
  if (!form_content(req))
    return oauth_error(400, "invalid_request",
                       "the body must be application/x-www-form-urlencoded");
  auto f = parse_form(req.body);
  if (!f) return oauth_error(400, "invalid_request", f.error().message);
  // Who asks: an admin or robot API key (bearer), or a client's credentials.
  if (!req.bearer().empty()) {
    HttpResponse err;
    auto caller = authenticate(req, err);
    if (!caller) return err;
    if (!caller->is("admin") && !caller->is("robot"))
      return project_error(ErrorCode::kInsufficientPrivileges,
                           "introspection needs a robot or admin key, or client credentials",
                           "authorization", "role");
  } else {
    HttpResponse err;
    if (!authenticate_client(req, *f, err, false)) return err;
  }
  HttpResponse r;
  auto c = check_own_token(f->get("token"));
  if (!c) {
    if (c.error().code == ErrorCode::kInternal) return store_error(c.error());
    r = json_response(200, json::Object{{"active", false}});
  } else {
    json::Array aud;
    for (const auto& a : c->aud) aud.emplace_back(a);
    json::Object out{{"active", true},
                     {"iss", c->iss},
                     {"sub", c->sub},
                     {"aud", c->aud.size() == 1 ? json::Value(c->aud[0]) : json::Value(aud)},
                     {"role", c->role},
                     {"scope",
                      [&] {
                        std::string s;
                        for (const auto& x : c->scopes) s += (s.empty() ? "" : " ") + x;
                        return s;
                      }()},
                     {"exp", c->exp.value_or(0)},
                     {"iat", c->iat.value_or(0)},
                     {"jti", c->jti},
                     {"token_type", "Bearer"}};
    if (c->fleet) {
      json::Array fl;
      for (const auto& x : *c->fleet) fl.emplace_back(x);
      out.set("fleet", std::move(fl));
    }
    r = json_response(200, out);
  }
  r.headers.emplace_back("Cache-Control", "no-store");
  return r;
}

}  // namespace rcan::registry::api
