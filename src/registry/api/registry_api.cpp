#include "registry/api/registry_api.h"

#include <chrono>
#include <ctime>

#include "base/clock.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "registry/api/impl.h"
#include "runtime/log.h"

namespace rcan::registry::api {
namespace {

constexpr const char* kAllowMethods = "GET, POST, PATCH, DELETE, OPTIONS";

void add_cors(HttpResponse& r) {
  r.headers.emplace_back("Access-Control-Allow-Origin", "*");
  r.headers.emplace_back("Access-Control-Allow-Methods", kAllowMethods);
  r.headers.emplace_back("Access-Control-Allow-Headers", "Content-Type, Authorization");
}

std::string address_of(const std::string& remote) {
  size_t colon = remote.rfind(':');
  if (colon == std::string::npos) return remote;
  std::string a = remote.substr(0, colon);
  if (a.size() >= 2 && a.front() == '[' && a.back() == ']') a = a.substr(1, a.size() - 2);
  return a;
}

std::vector<std::string> forwarded_for(const HttpRequest& req) {
  std::vector<std::string> out;
  for (const auto& [name, value] : req.headers)
    if (name == "x-forwarded-for") out.push_back(value);
  return out;
}

HttpResponse too_many(int64_t retry_after_s, const std::string& what) {
  HttpResponse r = project_error(ErrorCode::kRateLimited, "Rate limited — slow down requests", what,
                                 "rate_limited");
  r.headers.emplace_back("Retry-After", std::to_string(retry_after_s));
  return r;
}

bool is_hex(std::string_view s) {
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return true;
}

std::string random_hex(size_t bytes) {
  Bytes b(bytes);
  if (!random_bytes(b.data(), b.size())) return {};
  return to_hex(b);
}

}  // namespace

std::string iso_utc(int64_t ms) {
  std::time_t secs = static_cast<std::time_t>(ms / 1000);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[96];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900,
                tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                static_cast<int>(ms % 1000));
  return buf;
}

int64_t iso_utc_ms(std::string_view s) {
  int y = 0, mo = 0, d = 0, h = 0, mi = 0, sec = 0, ms = 0;
  char z = 0;
  const std::string text(s.substr(0, 32));
  if (s.size() != 24 ||
      std::sscanf(text.c_str(), "%4d-%2d-%2dT%2d:%2d:%2d.%3d%c", &y, &mo, &d, &h, &mi, &sec, &ms,
                  &z) != 8 ||
      z != 'Z')
    return -1;
  std::tm tm{};
  tm.tm_year = y - 1900;
  tm.tm_mon = mo - 1;
  tm.tm_mday = d;
  tm.tm_hour = h;
  tm.tm_min = mi;
  tm.tm_sec = sec;
  const std::time_t t = timegm(&tm);
  return t < 0 ? -1 : static_cast<int64_t>(t) * 1000 + ms;
}

HttpResponse json_response(int status, const json::Value& body) {
  HttpResponse r;
  r.status = status;
  r.body = json::dump(body);
  return r;
}

HttpResponse ref_error(int status, std::string msg) {
  return json_response(status, json::Object{{"error", std::move(msg)}});
}

HttpResponse project_error(ErrorCode code, std::string msg, std::string field, std::string reason) {
  Error e(code, std::move(msg), std::move(field), std::move(reason));
  int64_t ms = unix_ms();
  json::Value body = error_body(e, "", ms);
  // The SDK clients show body.error: keep the message there too.
  body.as_object().set("error", e.message);
  return json_response(http_status(code), body);
}

HttpResponse from_error(const Error& e) {
  return project_error(e.code, e.message, e.field, e.reason);
}

HttpResponse store_error(const Error& e) {
  log(LogLevel::kError, "registry_store_error", json::Object{{"error", e.message}});
  return ref_error(500, "Internal server error");
}

RegistryApi::Impl::Impl(Store& s, audit::AuditLog* a, ApiOptions opts)
    : store(s),
      audit_log(a),
      o(std::move(opts)),
      write_key(o.write_per_key),
      write_addr(o.write_per_address),
      anon_addr(o.anonymous_per_address),
      read_addr(o.read_per_address) {
  while (!o.public_url.empty() && o.public_url.back() == '/') o.public_url.pop_back();
  if (o.node_seed.size() != ed25519::kSeedBytes) o.node_seed = ed25519::random_seed();
  auto pub = ed25519::public_key_from_seed(o.node_seed);
  if (pub.ok()) node_pub = *pub;
  metrics.add_gauge("rcan_registry_robots", "Live robots in the registry", [this] {
    RobotQuery q;
    q.limit = 1;
    auto page = store.list_robots(q);
    return page.ok() ? static_cast<double>(page->total) : -1.0;
  });
  metrics.add_counter_fn("rcan_registry_audit_failures_total",
                         "Changes whose audit record could not be written",
                         [this] { return static_cast<double>(audit_failures.load()); });
  webhooks = std::make_unique<WebhookDispatcher>(store, o.webhooks, [this] { return now_ms(); });
  struct Counter {
    const char* name;
    const char* help;
    std::atomic<uint64_t>* value;
  } counters[] = {
      {"rcan_registry_webhook_deliveries_total", "Webhook deliveries answered 2xx",
       &webhooks->delivered},
      {"rcan_registry_webhook_failures_total", "Webhook deliveries that failed every attempt",
       &webhooks->failed},
      {"rcan_registry_webhook_failed_attempts_total", "Webhook delivery attempts that failed",
       &webhooks->attempts_failed},
      {"rcan_registry_webhook_dropped_total", "Webhook events or deliveries dropped: queue full",
       &webhooks->dropped},
      {"rcan_registry_webhook_skipped_total",
       "Webhook deliveries skipped: the subscription failed too often", &webhooks->skipped},
      {"rcan_registry_webhook_refused_address_total",
       "Webhook deliveries refused: the host resolved to no public address",
       &webhooks->refused_address}};
  for (const Counter& c : counters)
    metrics.add_counter_fn(c.name, c.help,
                           [v = c.value] { return static_cast<double>(v->load()); });
  if (!o.sync_from.empty() || o.sync_delegations) {
    // Every record a pull writes is a change of this registry: audited like the API's own.
    puller = std::make_unique<SyncPuller>(
        store, o.sync_from, o.sync_interval_ms, o.allow_http_node_urls, o.sync_delegations,
        [this](const Robot& r, const std::string& from) {
          audit("REGISTRY_SYNC_IMPORTED", "sync:" + from, r.rcan_uri,
                json::Object{{"rrn", r.rrn}, {"deleted", r.deleted}, {"from", from}});
        });
    Counter sync_counters[] = {
        {"rcan_registry_sync_pulls_total", "Sync pulls from authoritative nodes", &puller->pulls},
        {"rcan_registry_sync_failures_total", "Sync pulls that failed", &puller->failures},
        {"rcan_registry_sync_imported_total", "Robots taken from sync answers", &puller->imported},
        {"rcan_registry_sync_refused_total",
         "Sync records refused: malformed, or of a prefix not delegated to that node",
         &puller->refused}};
    for (const Counter& c : sync_counters)
      metrics.add_counter_fn(c.name, c.help,
                             [v = c.value] { return static_cast<double>(v->load()); });
  }
  build_manifest();
}

int64_t RegistryApi::Impl::now_ms() const {
  if (o.wall_ms) return o.wall_ms();
  return unix_ms();
}

std::optional<Caller> RegistryApi::Impl::authenticate(const HttpRequest& req, HttpResponse& err) {
  std::string_view token = req.bearer();
  while (!token.empty() && token.back() == ' ') token.remove_suffix(1);
  if (token.empty()) {
    err = project_error(ErrorCode::kAuthRequired, "Authorization required", "authorization",
                        "missing");
    return std::nullopt;
  }
  err = project_error(ErrorCode::kAuthInvalid, "Invalid API key", "authorization", "invalid");
  // rcan_<16 hex id>_<64 hex secret>
  if (token.size() != 5 + 16 + 1 + 64 || token.substr(0, 5) != "rcan_" || token[21] != '_')
    return std::nullopt;
  std::string_view id = token.substr(5, 16), secret = token.substr(22);
  if (!is_hex(id) || !is_hex(secret)) return std::nullopt;
  auto key = store.get_api_key(id);
  if (!key.ok()) {
    err = store_error(key.error());
    return std::nullopt;
  }
  if (!*key || !(*key)->revoked_at.empty()) return std::nullopt;
  std::string presented = sha256_hex((*key)->salt + std::string(secret));
  if (!constant_time_equal(presented, (*key)->hash)) return std::nullopt;
  return Caller{std::move(**key)};
}

bool RegistryApi::Impl::proves_credential(const HttpRequest& req) {
  const std::string_view authorization = req.header("authorization");
  if (!req.bearer().empty()) {
    HttpResponse err;
    return authenticate(req, err).has_value();
  }
  if (req.path != "/oauth/token" && req.path != "/oauth/introspect" &&
      req.path != "/oauth/device_authorization")
    return false;
  // A client's credentials (oauth_routes.cpp authenticate_client), checked without spending an
  // assertion's jti: the route checks them again, and in full.
  std::optional<Form> f;
  if (req.header("content-type").substr(0, 33) == "application/x-www-form-urlencoded")
    if (auto parsed = parse_form(req.body); parsed.ok()) f = std::move(*parsed);
  std::string id, secret;
  if (auto basic = parse_basic(authorization)) {
    id = basic->id;
    secret = basic->secret;
  } else if (f && f->has("client_secret")) {
    id = f->get("client_id");
    secret = f->get("client_secret");
  } else if (f && f->has("client_assertion")) {
    auto d = jwt::decode(f->get("client_assertion"));
    const json::Value* iss = d ? d->claims.find("iss") : nullptr;
    if (iss == nullptr || !iss->is_string()) return false;
    id = iss->as_string();
    if (id.empty() || id.size() > 64) return false;
    auto c = store.get_client(id);
    if (!c.ok() || !*c || (*c)->auth != "private_key_jwt") return false;
    auto jwk = json::parse((*c)->jwk);
    if (!jwk) return false;
    auto vk = jwt::VerificationKey::from_jwk(*jwk);
    return vk && d->header.alg == jwt::alg_name(vk->alg()) &&
           vk->verify(d->signing_input, d->signature);
  } else {
    return false;
  }
  if (id.empty() || id.size() > 64) return false;
  auto c = store.get_client(id);
  return c.ok() && *c && (*c)->auth == "client_secret" &&
         constant_time_equal(sha256_hex((*c)->salt + secret), (*c)->hash);
}

std::optional<HttpResponse> RegistryApi::Impl::limit_key(const std::string& key_id) {
  if (int64_t wait = write_key.take(key_id, steady_us()); wait > 0)
    return too_many(wait, "api_key");
  return std::nullopt;
}

std::optional<HttpResponse> RegistryApi::Impl::audit_unavailable() {
  if (audit_log == nullptr || audit_log->available()) return std::nullopt;
  return project_error(ErrorCode::kAuditUnavailable,
                       "The audit log does not take records: no change is made", "audit",
                       "audit_unavailable");
}

void RegistryApi::Impl::audit(const std::string& event, const std::string& principal,
                              const std::string& ruri, json::Object detail) {
  if (audit_log == nullptr) return;
  audit::AuditEntry e;
  e.principal = principal;
  e.ruri = ruri;
  e.message_id = new_uuid_v4();
  e.event = event;
  e.outcome = "ok";
  e.sender_type = "human";
  e.detail = std::move(detail);
  auto r = audit_log->append(std::move(e));
  if (!r.ok()) {
    audit_failures.fetch_add(1);
    log(LogLevel::kError, "registry_audit_failed",
        json::Object{{"event", event}, {"error", r.error().message}});
  }
}

Result<std::string> RegistryApi::Impl::create_key(const std::string& role, const std::string& rrn,
                                                  const std::string& label, const std::string& by) {
  ApiKey k;
  k.id = random_hex(8);
  k.salt = random_hex(16);
  std::string secret = random_hex(32);
  if (k.id.empty() || k.salt.empty() || secret.empty())
    return Error(ErrorCode::kInternal, "no randomness for a new API key");
  k.hash = sha256_hex(k.salt + secret);
  k.role = role;
  k.rrn = rrn;
  k.label = label;
  k.created_at = now();
  if (Status s = store.put_api_key(k); !s.ok()) return s.error();
  audit("REGISTRY_KEY_CREATED", by, registry_ruri(),
        json::Object{{"key_id", k.id}, {"role", role}, {"rrn", rrn}, {"label", label}});
  return "rcan_" + k.id + "_" + secret;
}

HttpResponse RegistryApi::Impl::serve(const HttpRequest& req) {
  const std::string& m = req.method;
  const std::string& p = req.path;
  // A challenge is a row in the store whatever the method: it counts as a write.
  bool write =
      m == "POST" || m == "PATCH" || m == "DELETE" || m == "PUT" || p == "/api/v1/challenge";
  if (m == "OPTIONS") {
    HttpResponse r;
    r.status = 204;
    r.content_type.clear();
    return r;
  }
  // The client's address (behind a trusted proxy: the one it forwarded for). A write is judged
  // by who proves to send it first: one that proves a credential spends its address's bucket of
  // such writes (and its key's, in the route), never the anonymous one a flood empties.
  const std::string addr =
      client_address(address_of(req.remote_addr), forwarded_for(req), o.trusted_proxies);
  RateLimiter& bucket = !write ? read_addr : proves_credential(req) ? write_addr : anon_addr;
  if (int64_t wait = bucket.take(addr, steady_us()); wait > 0)
    return too_many(wait, &bucket == &anon_addr ? "anonymous" : "address");
  auto not_allowed = [&] { return ref_error(405, "Method not allowed"); };
  if (p == "/healthz") {
    return m == "GET" ? json_response(200, json::Object{{"status", "ok"},
                                                        {"backend", std::string(store.backend())}})
                      : not_allowed();
  }
  if (p == "/metrics") {
    if (m != "GET") return not_allowed();
    HttpResponse r;
    r.content_type = "text/plain; version=0.0.4";
    r.body = metrics.render();
    return r;
  }
  if (p == "/.well-known/rcan-node.json") {
    if (m != "GET") return not_allowed();
    HttpResponse r;
    r.body = manifest;
    r.headers.emplace_back("Cache-Control", "public, max-age=3600");
    return r;
  }
  if (p == "/.well-known/jwks.json") return m == "GET" ? jwks() : not_allowed();
  if (p == "/oauth/token") return oauth_token(req);
  if (p == "/oauth/introspect") return introspect(req);
  if (p == "/oauth/device_authorization") return device_authorization(req);
  if (p == "/device" || p == "/device/") return m == "GET" ? device_page(req) : not_allowed();
  constexpr std::string_view kApi = "/api/v1/";
  if (p.rfind(kApi, 0) != 0) return ref_error(404, "Not found");
  std::string_view rest = std::string_view(p).substr(kApi.size());
  while (!rest.empty() && rest.back() == '/') rest.remove_suffix(1);
  // rcan-py's NodeClient appends /api/v1/robots/<rrn> to a manifest's api_base, which already
  // ends in /api/v1 (rcan-ts appends /robots/<rrn>): serve both.
  if (rest.rfind("api/v1/robots/", 0) == 0) rest.remove_prefix(7);
  if (rest == "robots") {
    if (m == "GET") return list_robots(req);
    if (m == "POST") return register_robot(req);
    return not_allowed();
  }
  if (rest == "robots/search") return m == "GET" ? search_robots(req) : not_allowed();
  if (rest.rfind("robots/", 0) == 0) {
    auto rrn = parse_rrn(rest.substr(7));
    if (!rrn) return ref_error(404, "Not found");
    if (m == "GET") return get_robot(rrn->rrn);
    if (m == "PATCH") return patch_robot(req, rrn->rrn);
    if (m == "DELETE") return delete_robot(req, rrn->rrn);
    return not_allowed();
  }
  if (rest == "resolve") return m == "GET" ? resolve_uri(req) : not_allowed();
  if (rest.rfind("resolve/", 0) == 0)
    return m == "GET" ? resolve(req, std::string(rest.substr(8))) : not_allowed();
  if (rest == "nodes") {
    if (m == "GET") return list_nodes(req);
    if (m == "POST") return add_node(req);
    return not_allowed();
  }
  if (rest.rfind("nodes/", 0) == 0)
    return m == "GET" ? get_node(std::string(rest.substr(6))) : not_allowed();
  if (rest == "challenge")
    return m == "GET" || m == "POST" ? challenge(m == "POST") : not_allowed();
  if (rest == "keys") {
    if (m == "GET") return list_keys(req);
    if (m == "POST") return create_key_route(req);
    return not_allowed();
  }
  if (rest.rfind("keys/", 0) == 0)
    return m == "DELETE" ? revoke_key(req, std::string(rest.substr(5))) : not_allowed();
  if (rest == "revocations") {
    if (m == "GET") return list_revocations(req);
    if (m == "POST") return revoke(req);
    return not_allowed();
  }
  if (rest == "authority/keys/rotate") return m == "POST" ? rotate_keys(req) : not_allowed();
  if (rest == "clients") return m == "GET" || m == "POST" ? clients_route(req) : not_allowed();
  if (rest.rfind("clients/", 0) == 0)
    return m == "DELETE" ? delete_client(req, std::string(rest.substr(8))) : not_allowed();
  if (rest == "grants") return m == "GET" || m == "POST" ? grants_route(req) : not_allowed();
  if (rest.rfind("grants/", 0) == 0)
    return m == "DELETE" ? delete_grant(req, std::string(rest.substr(7))) : not_allowed();
  if (rest == "sync") return m == "GET" ? sync(req) : not_allowed();
  if (rest == "webhooks" || rest == "webhooks/register") {
    if (m == "GET" && rest == "webhooks") return list_webhooks(req);
    if (m == "POST") return add_webhook(req);
    return not_allowed();
  }
  if (rest.rfind("webhooks/", 0) == 0)
    return m == "DELETE" ? delete_webhook(req, std::string(rest.substr(9))) : not_allowed();
  if (rest == "device/approve") return m == "POST" ? device_approve(req) : not_allowed();
  if (rest.rfind("device/requests/", 0) == 0)
    return m == "GET" ? device_request_route(req, std::string(rest.substr(16))) : not_allowed();
  return ref_error(404, "Not found");
}

namespace {

// The metrics label of a path: its route pattern, never the raw path (bounded label set).
std::string route_label(std::string_view p) {
  static constexpr std::string_view kFixed[] = {"/healthz",
                                                "/metrics",
                                                "/.well-known/rcan-node.json",
                                                "/api/v1/robots",
                                                "/api/v1/robots/search",
                                                "/api/v1/nodes",
                                                "/api/v1/resolve",
                                                "/api/v1/challenge",
                                                "/api/v1/keys",
                                                "/.well-known/jwks.json",
                                                "/oauth/token",
                                                "/oauth/introspect",
                                                "/oauth/device_authorization",
                                                "/device",
                                                "/api/v1/revocations",
                                                "/api/v1/authority/keys/rotate",
                                                "/api/v1/clients",
                                                "/api/v1/grants",
                                                "/api/v1/device/approve",
                                                "/api/v1/webhooks",
                                                "/api/v1/webhooks/register",
                                                "/api/v1/sync"};
  for (auto f : kFixed)
    if (p == f) return std::string(f);
  static constexpr std::pair<std::string_view, std::string_view> kPrefixes[] = {
      {"/api/v1/api/v1/robots/", "/api/v1/robots/{rrn}"},
      {"/api/v1/robots/", "/api/v1/robots/{rrn}"},
      {"/api/v1/resolve/", "/api/v1/resolve/{rrn}"},
      {"/api/v1/nodes/", "/api/v1/nodes/{prefix}"},
      {"/api/v1/keys/", "/api/v1/keys/{id}"},
      {"/api/v1/clients/", "/api/v1/clients/{id}"},
      {"/api/v1/grants/", "/api/v1/grants/{id}"},
      {"/api/v1/webhooks/", "/api/v1/webhooks/{id}"},
      {"/api/v1/device/requests/", "/api/v1/device/requests/{user_code}"}};
  for (auto [pre, label] : kPrefixes)
    if (p.rfind(pre, 0) == 0) return std::string(label);
  return "other";
}

}  // namespace

RegistryApi::RegistryApi(Store& store, audit::AuditLog* audit, ApiOptions options)
    : impl_(std::make_unique<Impl>(store, audit, std::move(options))) {}

RegistryApi::~RegistryApi() = default;

HttpResponse RegistryApi::serve(const HttpRequest& req) {
  HttpResponse r = impl_->serve(req);
  add_cors(r);
  impl_->metrics.count_request(route_label(req.path), r.status);
  return r;
}

void RegistryApi::handle(HttpRequest req, Respond respond) { respond(serve(req)); }

Result<std::string> RegistryApi::create_key(const std::string& role, const std::string& rrn,
                                            const std::string& label, const std::string& by) {
  return impl_->create_key(role, rrn, label, by);
}

const std::string& RegistryApi::manifest() const { return impl_->manifest; }

}  // namespace rcan::registry::api
