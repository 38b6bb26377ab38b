// The registry's storage (docs/REGISTRY.md): robots and their RRNs, API keys, namespace
// delegations (federation), webhooks and proof-of-possession challenges. Two backends with
// the same behaviour: SQLite in WAL mode (one registry instance, the embedded default) and
// PostgreSQL (several stateless instances on one database).
//
// Every call is safe from any thread. Times are ISO-8601 UTC with milliseconds
// ("2026-11-27T05:20:00.000Z"), produced by the caller, so that both backends store the same
// strings and tests control the clock. Values are bound, never spliced into SQL.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/result.h"

namespace rcan::registry {

// One registered robot. RRNs are minted by the store: "RRN-" + 12 digits of a
// monotonically increasing number (unique, gaps allowed), or "RRN-<PREFIX>-" + 12 digits on a
// node authoritative for a delegated prefix (StoreOptions::rrn_prefix).
struct Robot {
  std::string rrn;
  std::string manufacturer, model, version, device_id;  // slugs: [a-z0-9-], at most 64
  std::string rcan_uri;  // rcan://<registry-host>/<manufacturer>/<model>/<version>/<device_id>
  std::string verification_tier = "community";  // community | verified | manufacturer | certified
  std::string description, contact_email, source;
  std::string metadata_json = "{}";  // a JSON object, as the registrant sent it
  // Identity, set by a registration with proof of possession (or a signed update): the
  // robot's public keys, base64url without padding; empty when not proven.
  std::string ed25519_pub, mldsa65_pub;
  // Where the robot answers: a JSON array of {"url": "...", "last_seen": "<time>"}.
  std::string endpoints_json = "[]";
  std::string owner_key_id;  // the API key that registered it (updates and deletes need it)
  std::string registered_at, updated_at;
  bool deleted = false;  // soft delete: the RRN is never minted again
};

// What a registration supplies; the store fills rrn, rcan_uri (from rcan_uri_base + slugs),
// registered_at/updated_at (= now) and deleted.
struct NewRobot {
  std::string manufacturer, model, version, device_id;  // already slugged by the caller
  std::string rcan_uri_base;                            // "rcan://<registry-host>"
  std::string description, contact_email, source;
  std::string metadata_json = "{}";
  std::string ed25519_pub, mldsa65_pub;
  std::string endpoints_json = "[]";
  std::string owner_key_id;
  std::string now;
};

// The record `r` makes (rcan_uri from its base and names, both times `r.now`), without an RRN.
Robot robot_of(const NewRobot& r);

struct Registered {
  Robot robot;
  bool created = false;  // false: (manufacturer, model, version, device_id) was already live
};

// Listing and search. Empty strings do not filter. `q` matches a substring of manufacturer,
// model or rrn (case-insensitive, LIKE metacharacters in q are literal). Newest first.
struct RobotQuery {
  std::string q, manufacturer, model, tier;
  int limit = 20;  // 1..100, clamped by the caller
  int64_t offset = 0;
};

struct RobotPage {
  std::vector<Robot> robots;
  int64_t total = 0;  // matching live robots
};

// A partial update: only the fields that hold a value change; updated_at always does.
struct RobotUpdate {
  std::optional<std::string> description, contact_email, metadata_json, endpoints_json;
  std::optional<std::string> ed25519_pub, mldsa65_pub, verification_tier;
  std::string now;
};

// An API key. The secret is shown once at creation and never stored: the store keeps a
// random salt and SHA-256(salt || secret) (hex). The presented key is "rcan_<id>_<secret>",
// so the lookup is by id and the comparison constant-time (done by the caller).
struct ApiKey {
  std::string id;    // 16 lowercase hex
  std::string salt;  // 32 lowercase hex
  std::string hash;  // 64 lowercase hex
  std::string role;  // "admin" | "registrant" | "robot"
  std::string rrn;   // role "robot": the one robot this key may update; else empty
  std::string label;
  std::string created_at;
  std::string revoked_at;  // empty: active
};

// A namespace prefix delegated to an authoritative node (federation).
struct Delegation {
  std::string prefix;  // [A-Z0-9]{2,8}
  std::string operator_name, node_url, node_pubkey, contact;
  std::string delegated_at, expires_at;  // expires_at empty: no expiry
};

// A webhook subscription. The secret signs each delivery (HMAC-SHA256 over the body), so it
// is stored as given; the database is the registry's secret store and lives in a 0600 file
// or behind PostgreSQL's own authentication.
struct Webhook {
  int64_t id = 0;
  std::string prefix;  // deliveries for robots under this prefix ("RRN" for the root)
  std::string url, secret;
  std::string created_at, last_delivered_at;
  int failure_count = 0;
};

// A one-time proof-of-possession challenge.
struct Challenge {
  std::string id;     // 32 lowercase hex
  std::string nonce;  // base64url of 32 random bytes
  std::string purpose;
  std::string expires_at;
};

// ---- the token authority (docs/REGISTRY.md "Token authority"). Times in unix milliseconds.

// An Ed25519 signing key of the authority. The seed is a secret (the database is the
// registry's secret store). It is published in the JWKS from created_ms and signs from
// sign_from_ms (created_ms + the configured overlap, so verifiers see it before it signs).
struct SigningKeyRecord {
  std::string kid;
  std::string seed;  // base64url, 32 bytes
  int64_t created_ms = 0, sign_from_ms = 0;
};

// An OAuth client. auth "client_secret": salt and hash as for API keys; "private_key_jwt":
// jwk is the client's Ed25519 public JWK (JSON text).
struct Client {
  std::string id, name, auth, salt, hash, jwk;
  std::string owner_key_id;  // the API key that created it
  std::string created_at;
};

// Who may get which tokens for one robot (rrn) or one fleet (fleet).
struct Grant {
  int64_t id = 0;
  std::string principal;   // a client id or "user:<name>"
  std::string rrn, fleet;  // exactly one is set
  std::string role;        // guest | user | leasee | owner
  std::string scope;       // space-separated
  int64_t max_ttl_s = 3600;
  std::string created_by, created_at;
};

// A revoked token (by jti) or subject (every token of sub issued before revoked_ms).
struct Revocation {
  int64_t seq = 0;             // unique and increasing across instances
  std::string jti, sub;        // one or both set
  std::optional<int64_t> exp;  // unix seconds, when known
  std::string revoked_at;      // ISO-8601
  int64_t revoked_ms = 0;
  std::string reason, revoked_by;
};

// A device authorization request (RFC 8628). The device code is stored hashed.
struct DeviceCode {
  std::string device_hash, user_code, client_id, resource, scope;
  int64_t expires_ms = 0, interval_s = 5, last_poll_ms = 0;
  std::string status = "pending";  // pending | approved | denied
  std::string subject;             // set on approval
};

struct StoreOptions {
  std::string rrn_prefix;  // empty: root numbering "RRN-<12 digits>"
};

class Store {
 public:
  virtual ~Store() = default;

  // "sqlite" or "postgresql".
  virtual std::string_view backend() const = 0;

  // ---- robots
  // Mints an RRN atomically; a live robot with the same four slugs is returned with
  // created=false instead (concurrent registrations of the same robot produce one RRN).
  virtual Result<Registered> register_robot(const NewRobot& r) = 0;
  // A live robot by RRN (compared case-insensitively), or nullopt.
  virtual Result<std::optional<Robot>> get_robot(std::string_view rrn) = 0;
  // A live robot by its rcan_uri: a record of this registry's own before a synced copy (a copy
  // never shadows one), else the newest.
  virtual Result<std::optional<Robot>> find_robot_by_uri(std::string_view rcan_uri) = 0;
  virtual Result<RobotPage> list_robots(const RobotQuery& q) = 0;
  // The updated robot, or nullopt when no live robot has that RRN.
  virtual Result<std::optional<Robot>> update_robot(std::string_view rrn, const RobotUpdate& u) = 0;
  // Soft delete; false when no live robot has that RRN.
  virtual Result<bool> delete_robot(std::string_view rrn, std::string_view now) = 0;
  // For federation sync: robots (deleted ones too) with updated_at > since, oldest first.
  virtual Result<std::vector<Robot>> robots_changed_since(std::string_view since, int limit) = 0;
  // A robot pulled from an authoritative node: inserted or replaced by RRN as given.
  virtual Status upsert_synced_robot(const Robot& r) = 0;

  // ---- API keys
  virtual Status put_api_key(const ApiKey& k) = 0;  // id must be new
  virtual Result<std::optional<ApiKey>> get_api_key(std::string_view id) = 0;
  virtual Result<bool> revoke_api_key(std::string_view id, std::string_view now) = 0;
  virtual Result<std::vector<ApiKey>> list_api_keys() = 0;
  // The database's first admin key: `k` (role admin, id new) is inserted only when the database
  // holds no live admin key — one decision for every instance sharing the database. false (and
  // nothing inserted) when it holds one.
  virtual Result<bool> put_first_admin_key(const ApiKey& k) = 0;

  // ---- delegations
  // false when the prefix is already delegated.
  virtual Result<bool> add_delegation(const Delegation& d) = 0;
  virtual Result<std::optional<Delegation>> get_delegation(std::string_view prefix) = 0;
  virtual Result<std::vector<Delegation>> list_delegations() = 0;

  // ---- webhooks
  virtual Result<int64_t> add_webhook(const Webhook& w) = 0;  // returns the id
  virtual Result<std::vector<Webhook>> webhooks_for(std::string_view prefix) = 0;
  virtual Result<bool> delete_webhook(int64_t id) = 0;
  virtual Status record_delivery(int64_t id, bool ok, std::string_view now) = 0;

  // ---- proof-of-possession challenges
  virtual Status put_challenge(const Challenge& c) = 0;
  // Removes and returns the challenge (each is used at most once), or nullopt.
  virtual Result<std::optional<Challenge>> take_challenge(std::string_view id) = 0;
  // Drops challenges that expired before `now`; returns how many.
  virtual Result<int64_t> expire_challenges(std::string_view now) = 0;

  // ---- the token authority. One implementation over both backends (authority_store.cpp) on
  // query(): SQL written with $1… placeholders (SQLite runs them as ?1…), every value bound
  // as text or NULL, every column read as text ("" for NULL).
  Status put_signing_key(const SigningKeyRecord& k);
  Result<std::vector<SigningKeyRecord>> signing_keys();  // oldest first
  Result<bool> delete_signing_key(std::string_view kid);

  Status put_client(const Client& c);
  Result<std::optional<Client>> get_client(std::string_view id);
  Result<std::vector<Client>> list_clients();
  Result<bool> delete_client(std::string_view id);

  Result<int64_t> add_grant(const Grant& g);  // the id
  Result<std::vector<Grant>> grants_of(std::string_view principal);
  Result<std::optional<Grant>> get_grant(int64_t id);
  Result<std::vector<Grant>> list_grants();
  Result<bool> delete_grant(int64_t id);

  Result<int64_t> add_revocation(const Revocation& r);  // the seq
  Result<std::vector<Revocation>> revocations_since(int64_t since, int limit);
  // Whether a token (jti, sub, issued at iat_ms) is revoked.
  Result<bool> is_revoked(std::string_view jti, std::string_view sub, int64_t iat_ms);

  // Records a client assertion's jti until exp_ms; false when it is already recorded.
  Result<bool> use_jti(std::string_view jti, int64_t exp_ms, int64_t now_ms);

  Status put_device_code(const DeviceCode& d);
  Result<std::optional<DeviceCode>> device_by_hash(std::string_view device_hash);
  Result<std::optional<DeviceCode>> device_by_user_code(std::string_view user_code);
  // Sets status and subject of a pending request; false when it is not pending.
  Result<bool> decide_device(std::string_view user_code, std::string_view status,
                             std::string_view subject);
  Status touch_device(std::string_view device_hash, int64_t poll_ms, int64_t interval_s);
  Result<bool> delete_device(std::string_view device_hash);

 protected:
  using Row = std::vector<std::string>;
  using Args = std::vector<std::optional<std::string>>;
  virtual Result<std::vector<Row>> query(const std::string& sql, const Args& args) = 0;
};

// Opens (creating the file and the schema when missing, mode 0600) a SQLite database in WAL
// mode.
Result<std::unique_ptr<Store>> open_sqlite(const std::string& path, const StoreOptions& o = {});
// Connects to PostgreSQL (a libpq conninfo or postgresql:// URL) and creates the schema when
// missing. Several processes may open the same database at once.
Result<std::unique_ptr<Store>> open_postgres(const std::string& conninfo,
                                             const StoreOptions& o = {});
// "postgresql://…" or "postgres://…" → open_postgres; anything else is a SQLite path.
Result<std::unique_ptr<Store>> open_store(const std::string& spec, const StoreOptions& o = {});

}  // namespace rcan::registry
