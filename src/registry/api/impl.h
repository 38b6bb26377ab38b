// The registry API's internals, shared by its route files (not an interface).
#pragma once

#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/crypto/jwt.h"
#include "rcan/json.h"
#include "registry/api/body.h"
#include "registry/api/oauth_form.h"
#include "registry/api/registry_api.h"
#include "registry/api/sync.h"
#include "transport/router.h"

namespace rcan::registry::api {

using transport::HttpRequest;
using transport::HttpResponse;

// What a token is for: one robot (rrn, its owner) or a fleet; aud is the token's audience.
struct Target {
  std::string rrn, fleet, aud, owner_key_id;
  // Why no token may be issued for this robot (robot_audience, unique_audience); the target
  // still names the robot for a revocation by its owner.
  std::optional<Error> refused;
};
// The grant that allows a token request, with the scopes and role the token gets.
struct GrantChoice {
  Grant grant;
  std::vector<std::string> scopes;
  std::string role;
};

// Who presented which API key.
struct Caller {
  ApiKey key;
  bool is(std::string_view role) const { return key.role == role; }
};

class RegistryApi::Impl {
 public:
  Impl(Store& store, audit::AuditLog* audit, ApiOptions o);

  // The rows' handler: the API, the request and the path's `*` segment (empty when none).
  using RouteFn = HttpResponse (*)(Impl&, const HttpRequest&, const std::string&);
  using Routes = transport::Router<RouteFn>;
  // Answers `req`, whose route is `route` (registry_routes().find on routing_path()): OPTIONS
  // and the rate limits first, then the route's handler, or 404 / 405.
  HttpResponse serve(const HttpRequest& req, const Routes::Match& route);

  // ---- helpers (registry_api.cpp)
  std::string now() const { return iso_utc(now_ms()); }
  int64_t now_ms() const;
  // Who the bearer is: nullopt with `err` set (401) when the key is missing, malformed,
  // unknown, revoked or wrong.
  std::optional<Caller> authenticate(const HttpRequest& req, HttpResponse& err);
  // Whether the request proves who sends it: a valid API key, or at the OAuth endpoints a
  // client's valid secret or signed assertion. Without side effects; what proves nothing is
  // anonymous (serve(): its own, smaller rate limit).
  bool proves_credential(const HttpRequest& req);
  // 429 when `key_id`'s write bucket is empty.
  std::optional<HttpResponse> limit_key(const std::string& key_id);
  // The client's address (behind a trusted proxy: the one it forwarded for).
  std::string client_of(const HttpRequest& req) const;
  // A write on /robots/{rrn}: the authenticated, rate-limited caller and the live robot, or
  // nullopt with the refusal (the reference's wording) in `refusal`.
  struct RobotWrite {
    Caller caller;
    Robot robot;
  };
  std::optional<RobotWrite> robot_write(const HttpRequest& req, const std::string& rrn,
                                        HttpResponse& refusal);
  // Appends a change to the audit log (logs and counts a failure: the change is stored).
  void audit(const std::string& event, const std::string& principal, const std::string& ruri,
             json::Object detail);
  // 503 when the audit log does not take records (no change is made then).
  std::optional<HttpResponse> audit_unavailable();
  // A fresh key: its stored form and the form presented once ("rcan_<id>_<secret>").
  struct NewKey {
    ApiKey key;
    std::string presented;
  };
  Result<NewKey> new_key(const std::string& role, const std::string& rrn, const std::string& label);
  Result<std::string> create_key(const std::string& role, const std::string& rrn,
                                 const std::string& label, const std::string& by);
  Result<std::optional<std::string>> create_first_admin_key();
  std::string registry_ruri() const { return "rcan://" + o.host + "/registry/rcan-registry/node"; }
  std::string uri_base() const { return "rcan://" + o.host; }

  // ---- robots (robots_routes.cpp)
  HttpResponse register_robot(const HttpRequest& req);
  // Who registers: an authenticated admin or registrant, or with open_registration anyone who
  // sends no credentials at all (a wrong key is still refused) within the address's limit.
  // nullopt with `err` set when refused.
  struct Registrant {
    std::optional<Caller> caller;  // nullopt: anonymous
    std::string owner_key_id;      // the record's owner (kAnonymousOwner when anonymous)
    std::string principal;         // for the audit record
  };
  std::optional<Registrant> registrant_of(const HttpRequest& req, HttpResponse& err);
  // The owner of an anonymously registered robot: no key's id (ids are 16 hex digits), so no
  // key owns it but its own robot key — and not "" (a synced copy's mark).
  static constexpr const char* kAnonymousOwner = "anonymous";
  HttpResponse list_robots(const HttpRequest& req);
  HttpResponse search_robots(const HttpRequest& req);
  HttpResponse get_robot(const std::string& rrn);
  HttpResponse patch_robot(const HttpRequest& req, const std::string& rrn);
  HttpResponse delete_robot(const HttpRequest& req, const std::string& rrn);
  HttpResponse resolve(const HttpRequest& req, const std::string& raw);
  // The resolve answer for `r`, resolved by `by` (this node, or the authoritative node of a
  // synced copy), cache_status `cache`.
  HttpResponse resolved(const Robot& r, const std::string& ns, const std::string& by,
                        const char* cache);
  // GET /api/v1/resolve?uri=<RURI>: the robot registered here under that RURI (the 4-segment
  // canonical form names version v1, as rcand registers itself).
  HttpResponse resolve_uri(const HttpRequest& req);
  json::Object robot_json(const Robot& r) const;
  // What a deleted robot is to anyone (sync, webhooks): its RRN, status, deleted and the time
  // of the deletion — none of its content.
  static json::Object tombstone_json(const Robot& r);

  // ---- keys, nodes, challenges, manifest (admin_routes.cpp)
  HttpResponse challenge(bool post);  // 200 on GET, 201 on POST
  HttpResponse create_key_route(const HttpRequest& req);
  HttpResponse list_keys(const HttpRequest& req);
  HttpResponse revoke_key(const HttpRequest& req, const std::string& id);
  HttpResponse list_nodes(const HttpRequest& req);
  HttpResponse get_node(const std::string& prefix);
  HttpResponse add_node(const HttpRequest& req);
  json::Object self_node() const;
  void build_manifest();
  // The registration's proof of possession: nullopt when it holds (or there are no keys).
  std::optional<HttpResponse> check_proof(const Registration& r);
  // A signed update by a robot that proved its keys: nullopt when it holds.
  std::optional<HttpResponse> check_signed_update(const HttpRequest& req, const Robot& robot);

  // ---- federation sync (sync_routes.cpp)
  HttpResponse sync(const HttpRequest& req);

  // ---- webhooks (webhook_routes.cpp)
  HttpResponse list_webhooks(const HttpRequest& req);
  HttpResponse add_webhook(const HttpRequest& req);
  HttpResponse delete_webhook(const HttpRequest& req, const std::string& id);
  // Queues `event` about `r` for its namespace's subscriptions (a deleted `r`: its tombstone).
  void notify(const char* event, const Robot& r);

  // ---- the token authority (authority.cpp, authority_routes.cpp)
  HttpResponse jwks();
  HttpResponse oauth_token(const HttpRequest& req);
  HttpResponse introspect(const HttpRequest& req);
  HttpResponse list_revocations(const HttpRequest& req);
  HttpResponse revoke(const HttpRequest& req);
  HttpResponse rotate_keys(const HttpRequest& req);
  HttpResponse clients_route(const HttpRequest& req);
  HttpResponse delete_client(const HttpRequest& req, const std::string& id);
  HttpResponse grants_route(const HttpRequest& req);
  HttpResponse delete_grant(const HttpRequest& req, const std::string& id);
  HttpResponse device_authorization(const HttpRequest& req);
  HttpResponse device_approve(const HttpRequest& req);
  HttpResponse device_page(const HttpRequest& req);
  // A pending device request as its approver sees it (docs/THREATS.md T7): the client (name,
  // id, auth, the API key that made it and its label), the target (resource, RRN or fleet, the
  // robot's RURI and owner key), the scopes asked and when it expires. kNotFound when the code
  // names no pending request.
  Result<json::Object> device_request(const std::string& user_code);
  // GET /api/v1/device/requests/{user_code}: device_request, for an admin or a key that holds a
  // grant on its target (who else could approve it), with the role and scopes the caller's
  // grant would give.
  HttpResponse device_request_route(const HttpRequest& req, const std::string& user_code);
  // The stored keys (cached for a second; `fresh` reloads), rotated when due.
  Result<std::vector<SigningKeyRecord>> authority_keys(bool fresh = false);
  // A new key that signs from now + overlap (now when there is none).
  Result<SigningKeyRecord> new_signing_key(int64_t now_ms, bool first);
  // Verifies a token of this authority (signature, iss, exp) and its revocation; the claims
  // or an error saying why it is not active.
  Result<jwt::Claims> check_own_token(std::string_view token);

  // Whether `aud` (robot_audience of `r`) is `r`'s alone: refused (reason ruri_taken) when
  // another live record registered before `r` (any, for a record not stored yet) has it.
  Status unique_audience(const Robot& r, const std::string& aud);
  // "fleet:<id>", an RRN or a RURI → the target (kNotFound reason "unknown" when none).
  Result<Target> resolve_target(const std::string& resource);
  // The first grant of `principal` for `t` that allows `scope` (space-separated; empty: the
  // grant's) and `role` (empty: the grant's). Errors carry the OAuth error as reason
  // (unauthorized_client, invalid_scope).
  Result<GrantChoice> choose_grant(const std::string& principal, const Target& t,
                                   const std::string& scope, const std::string& role);
  // Signs a token for `sub` and answers the token response (RFC 6749 §5.1).
  HttpResponse issue_token(const std::string& sub, const Target& t, const GrantChoice& c);

  std::optional<Client> authenticate_client(const HttpRequest& req, const Form& f,
                                            HttpResponse& err, bool allow_public);
  HttpResponse device_token(const Client& client, const Form& f);

  std::mutex keys_mu;
  std::vector<SigningKeyRecord> keys_cache;
  int64_t keys_loaded_ms = -1;

  Store& store;
  audit::AuditLog* audit_log;
  ApiOptions o;
  Bytes node_pub;
  std::string manifest;
  Metrics metrics;
  RateLimiter write_key, write_addr, anon_addr, read_addr;
  RateLimiter open_register_addr;  // anonymous registrations (ApiOptions::open_registration)
  // Revocations by one non-admin API key (docs/THREATS.md T4): every robot that trusts this
  // registry keeps each one, so a registrant may not turn its own tokens into a flood of them.
  RateLimiter revoke_by_key{BucketConfig{kRevocationsPerKeyPerS, kRevocationBurstPerKey}};
  static constexpr double kRevocationsPerKeyPerS = 1.0 / 60;  // one a minute, after the burst
  static constexpr double kRevocationBurstPerKey = 60;
  std::atomic<uint64_t> audit_failures{0};
  // Last: its worker stops before the rest goes.
  std::unique_ptr<WebhookDispatcher> webhooks;
  std::unique_ptr<SyncPuller> puller;  // with o.sync_from or o.sync_delegations only
};

// Every route of the API (routes.cpp).
using RegistryRoutes = RegistryApi::Impl::Routes;
const RegistryRoutes& registry_routes();
// The path the routes match: under /api/v1/ without trailing slashes, and /api/v1/api/v1/robots/
// read as /api/v1/robots/.
std::string routing_path(std::string_view path);

// Answers.
HttpResponse json_response(int status, const json::Value& body);
// The reference's error form {"error": msg} (plus "error_code" naming the project's code).
HttpResponse ref_error(int status, std::string msg);
// The project's error body (include/rcan/errors.h) for what the reference does not define.
HttpResponse project_error(ErrorCode code, std::string msg, std::string field = {},
                           std::string reason = {});
HttpResponse from_error(const Error& e);   // project_error of a Result's error
HttpResponse store_error(const Error& e);  // 500, logged

}  // namespace rcan::registry::api
