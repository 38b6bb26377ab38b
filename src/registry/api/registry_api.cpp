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
      read_addr(o.read_per_address),
      open_register_addr(o.open_registration_per_address) {
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

std::string RegistryApi::Impl::client_of(const HttpRequest& req) const {
  return client_address(address_of(req.remote_addr), forwarded_for(req), o.trusted_proxies);
}

std::optional<RegistryApi::Impl::Registrant> RegistryApi::Impl::registrant_of(
    const HttpRequest& req, HttpResponse& err) {
  if (o.open_registration && req.header("authorization").empty()) {
    const std::string addr = client_of(req);
    if (int64_t wait = open_register_addr.take(addr, steady_us()); wait > 0) {
      err = too_many(wait, "open_registration");
      return std::nullopt;
    }
    return Registrant{std::nullopt, kAnonymousOwner, "anonymous:" + addr};
  }
  auto caller = authenticate(req, err);
  if (!caller) return std::nullopt;
  if (auto l = limit_key(caller->key.id)) {
    err = *l;
    return std::nullopt;
  }
  if (!caller->is("admin") && !caller->is("registrant")) {
    err = project_error(ErrorCode::kInsufficientPrivileges,
                        "registering needs a registrant or admin key", "authorization", "role");
    return std::nullopt;
  }
  return Registrant{caller, caller->key.id, "apikey:" + caller->key.id};
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

Result<RegistryApi::Impl::NewKey> RegistryApi::Impl::new_key(const std::string& role,
                                                             const std::string& rrn,
                                                             const std::string& label) {
  NewKey n;
  n.key.id = random_hex(8);
  n.key.salt = random_hex(16);
  std::string secret = random_hex(32);
  if (n.key.id.empty() || n.key.salt.empty() || secret.empty())
    return Error(ErrorCode::kInternal, "no randomness for a new API key");
  n.key.hash = sha256_hex(n.key.salt + secret);
  n.key.role = role;
  n.key.rrn = rrn;
  n.key.label = label;
  n.key.created_at = now();
  n.presented = "rcan_" + n.key.id + "_" + secret;
  return n;
}

Result<std::string> RegistryApi::Impl::create_key(const std::string& role, const std::string& rrn,
                                                  const std::string& label, const std::string& by) {
  auto n = new_key(role, rrn, label);
  if (!n.ok()) return n.error();
  if (Status s = store.put_api_key(n->key); !s.ok()) return s.error();
  audit("REGISTRY_KEY_CREATED", by, registry_ruri(),
        json::Object{{"key_id", n->key.id}, {"role", role}, {"rrn", rrn}, {"label", label}});
  return n->presented;
}

Result<std::optional<std::string>> RegistryApi::Impl::create_first_admin_key() {
  auto n = new_key("admin", "", "first start");
  if (!n.ok()) return n.error();
  auto put = store.put_first_admin_key(n->key);
  if (!put.ok()) return put.error();
  if (!*put) return std::optional<std::string>();
  audit("REGISTRY_KEY_CREATED", "system:first-start", registry_ruri(),
        json::Object{
            {"key_id", n->key.id}, {"role", "admin"}, {"rrn", ""}, {"label", "first start"}});
  return std::optional<std::string>(n->presented);
}

HttpResponse RegistryApi::Impl::serve(const HttpRequest& req, const Routes::Match& route) {
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
  const std::string addr = client_of(req);
  RateLimiter& bucket = !write ? read_addr : proves_credential(req) ? write_addr : anon_addr;
  if (int64_t wait = bucket.take(addr, steady_us()); wait > 0)
    return too_many(wait, &bucket == &anon_addr ? "anonymous" : "address");
  if (route.found())
    return route.route->handler(*this, req, route.params.empty() ? "" : route.params[0]);
  if (route.method_not_allowed()) return ref_error(405, "Method not allowed");
  return ref_error(404, "Not found");
}

RegistryApi::RegistryApi(Store& store, audit::AuditLog* audit, ApiOptions options)
    : impl_(std::make_unique<Impl>(store, audit, std::move(options))) {}

RegistryApi::~RegistryApi() = default;

HttpResponse RegistryApi::serve(const HttpRequest& req) {
  static const std::string kOther = "other";
  const auto route = registry_routes().find(req.method, routing_path(req.path));
  HttpResponse r = impl_->serve(req, route);
  add_cors(r);
  // The metrics label: the route's, never the raw path (a bounded label set).
  impl_->metrics.count_request(route.label_or(kOther), r.status);
  return r;
}

void RegistryApi::handle(HttpRequest req, Respond respond) { respond(serve(req)); }

Result<std::string> RegistryApi::create_key(const std::string& role, const std::string& rrn,
                                            const std::string& label, const std::string& by) {
  return impl_->create_key(role, rrn, label, by);
}

Result<std::optional<std::string>> RegistryApi::create_first_admin_key() {
  return impl_->create_first_admin_key();
}

const std::string& RegistryApi::manifest() const { return impl_->manifest; }

}  // namespace rcan::registry::api
