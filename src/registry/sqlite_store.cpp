// The registry's storage in SQLite (store.h): one file in WAL mode, created 0600, one
// connection behind a mutex with its prepared statements cached. RRNs are minted from a
// counter row inside BEGIN IMMEDIATE, so two processes on one file never mint the same number.
#include <fcntl.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <mutex>
#include <thread>
#include <unordered_map>

#include "base/clock.h"
#include "base/strings.h"
#include "rcan/ruri.h"
#include "registry/store.h"
#include "registry/store_internal.h"

namespace rcan::registry {
namespace {

using detail::db_error;

constexpr int kSchemaVersion = 1;

const char* const kSchema = R"SQL(
CREATE TABLE IF NOT EXISTS registry_meta (
  key   TEXT PRIMARY KEY,
  value TEXT NOT NULL
);
INSERT OR IGNORE INTO registry_meta (key, value) VALUES ('schema_version', '1');
CREATE TABLE IF NOT EXISTS rrn_counter (
  id   INTEGER PRIMARY KEY CHECK (id = 1),
  last INTEGER NOT NULL
);
INSERT OR IGNORE INTO rrn_counter (id, last) VALUES (1, 0);
CREATE TABLE IF NOT EXISTS robots (
  seq               INTEGER PRIMARY KEY AUTOINCREMENT,
  rrn               TEXT NOT NULL UNIQUE,
  manufacturer      TEXT NOT NULL,
  model             TEXT NOT NULL,
  version           TEXT NOT NULL,
  device_id         TEXT NOT NULL,
  rcan_uri          TEXT NOT NULL,
  verification_tier TEXT NOT NULL,
  description       TEXT NOT NULL,
  contact_email     TEXT NOT NULL,
  source            TEXT NOT NULL,
  metadata_json     TEXT NOT NULL,
  ed25519_pub       TEXT NOT NULL,
  mldsa65_pub       TEXT NOT NULL,
  endpoints_json    TEXT NOT NULL,
  owner_key_id      TEXT NOT NULL,
  registered_at     TEXT NOT NULL,
  updated_at        TEXT NOT NULL,
  deleted           INTEGER NOT NULL DEFAULT 0,
  synced            INTEGER NOT NULL DEFAULT 0  -- pulled from an authoritative node
);
CREATE UNIQUE INDEX IF NOT EXISTS robots_live_slugs
  ON robots (manufacturer, model, version, device_id) WHERE deleted = 0 AND synced = 0;
CREATE INDEX IF NOT EXISTS robots_uri ON robots (rcan_uri);
CREATE INDEX IF NOT EXISTS robots_registered ON robots (registered_at, seq);
CREATE INDEX IF NOT EXISTS robots_updated ON robots (updated_at, seq);
CREATE TABLE IF NOT EXISTS api_keys (
  id         TEXT PRIMARY KEY,
  salt       TEXT NOT NULL,
  hash       TEXT NOT NULL,
  role       TEXT NOT NULL,
  rrn        TEXT NOT NULL,
  label      TEXT NOT NULL,
  created_at TEXT NOT NULL,
  revoked_at TEXT NOT NULL DEFAULT ''
);
CREATE TABLE IF NOT EXISTS delegations (
  prefix        TEXT PRIMARY KEY,
  operator_name TEXT NOT NULL,
  node_url      TEXT NOT NULL,
  node_pubkey   TEXT NOT NULL,
  contact       TEXT NOT NULL,
  delegated_at  TEXT NOT NULL,
  expires_at    TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS webhooks (
  id                INTEGER PRIMARY KEY AUTOINCREMENT,
  prefix            TEXT NOT NULL,
  url               TEXT NOT NULL,
  secret            TEXT NOT NULL,
  created_at        TEXT NOT NULL,
  last_delivered_at TEXT NOT NULL DEFAULT '',
  failure_count     INTEGER NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS webhooks_prefix ON webhooks (prefix);
CREATE TABLE IF NOT EXISTS challenges (
  id         TEXT PRIMARY KEY,
  nonce      TEXT NOT NULL,
  purpose    TEXT NOT NULL,
  expires_at TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS challenges_expiry ON challenges (expires_at);
CREATE TABLE IF NOT EXISTS authority_keys (
  kid          text PRIMARY KEY,
  seed         text NOT NULL,
  created_ms   INTEGER NOT NULL,
  sign_from_ms INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS authority_clients (
  id           text PRIMARY KEY,
  name         text NOT NULL,
  auth         text NOT NULL,
  salt         text NOT NULL,
  hash         text NOT NULL,
  jwk          text NOT NULL,
  owner_key_id text NOT NULL,
  created_at   text NOT NULL
);
CREATE TABLE IF NOT EXISTS authority_grants (
  id         INTEGER PRIMARY KEY AUTOINCREMENT,
  principal  text NOT NULL,
  rrn        text NOT NULL,
  fleet      text NOT NULL,
  role       text NOT NULL,
  scope      text NOT NULL,
  max_ttl_s  INTEGER NOT NULL,
  created_by text NOT NULL,
  created_at text NOT NULL
);
CREATE INDEX IF NOT EXISTS authority_grants_principal ON authority_grants (principal);
CREATE TABLE IF NOT EXISTS authority_revocations (
  seq        INTEGER PRIMARY KEY AUTOINCREMENT,
  jti        text,
  sub        text,
  exp        INTEGER,
  revoked_at text NOT NULL,
  revoked_ms INTEGER NOT NULL,
  reason     text NOT NULL,
  revoked_by text NOT NULL
);
CREATE INDEX IF NOT EXISTS authority_revocations_jti ON authority_revocations (jti);
CREATE INDEX IF NOT EXISTS authority_revocations_sub ON authority_revocations (sub);
CREATE TABLE IF NOT EXISTS authority_used_jtis (
  jti    text PRIMARY KEY,
  exp_ms INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS authority_device_codes (
  device_hash  text PRIMARY KEY,
  user_code    text NOT NULL UNIQUE,
  client_id    text NOT NULL,
  resource     text NOT NULL,
  scope        text NOT NULL,
  expires_ms   INTEGER NOT NULL,
  interval_s   INTEGER NOT NULL,
  last_poll_ms INTEGER NOT NULL,
  status       text NOT NULL,
  subject      text NOT NULL
);
)SQL";

#define ROBOT_COLUMNS                                                                        \
  "rrn, manufacturer, model, version, device_id, rcan_uri, verification_tier, description, " \
  "contact_email, source, metadata_json, ed25519_pub, mldsa65_pub, endpoints_json, "         \
  "owner_key_id, registered_at, updated_at, deleted"
#define ROBOT_VALUES "?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?"

// A cached statement in use: bound left to right, reset (and unbound) when it goes out of scope.
class Stmt {
 public:
  explicit Stmt(sqlite3_stmt* s) : s_(s) {}
  ~Stmt() {
    sqlite3_reset(s_);
    sqlite3_clear_bindings(s_);
  }
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;

  Stmt& bind(std::string_view v) {
    sqlite3_bind_text(s_, ++n_, v.data() == nullptr ? "" : v.data(), static_cast<int>(v.size()),
                      SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& bind(const std::string& v) { return bind(std::string_view(v)); }
  Stmt& bind(const char* v) { return bind(std::string_view(v)); }
  Stmt& bind(const std::optional<std::string>& v) {
    if (!v) {
      sqlite3_bind_null(s_, ++n_);
      return *this;
    }
    return bind(std::string_view(*v));
  }
  Stmt& bind(int64_t v) {
    sqlite3_bind_int64(s_, ++n_, v);
    return *this;
  }
  Stmt& bind(int v) { return bind(static_cast<int64_t>(v)); }
  Stmt& bind(bool v) { return bind(static_cast<int64_t>(v ? 1 : 0)); }
  template <typename... A>
  Stmt& bind_all(const A&... a) {
    (bind(a), ...);
    return *this;
  }

  int step() { return sqlite3_step(s_); }
  // Steps to the end (statements with RETURNING finish their work there).
  int finish() {
    int rc;
    while ((rc = sqlite3_step(s_)) == SQLITE_ROW) {
    }
    return rc;
  }
  std::string text(int col) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(s_, col));
    return p == nullptr ? std::string() : std::string(p, sqlite3_column_bytes(s_, col));
  }
  int64_t integer(int col) const { return sqlite3_column_int64(s_, col); }

  Robot robot() const {
    Robot r;
    int i = 0;
    for (std::string* f : {&r.rrn, &r.manufacturer, &r.model, &r.version, &r.device_id, &r.rcan_uri,
                           &r.verification_tier, &r.description, &r.contact_email, &r.source,
                           &r.metadata_json, &r.ed25519_pub, &r.mldsa65_pub, &r.endpoints_json,
                           &r.owner_key_id, &r.registered_at, &r.updated_at})
      *f = text(i++);
    r.deleted = integer(i) != 0;
    return r;
  }

 private:
  sqlite3_stmt* s_;
  int n_ = 0;
};

class SqliteStore final : public Store {
 public:
  SqliteStore(sqlite3* db, StoreOptions o) : db_(db), opts_(std::move(o)) {}
  ~SqliteStore() override {
    for (auto& [sql, s] : cache_) sqlite3_finalize(s);
    sqlite3_close_v2(db_);
  }

  // Applies the pragmas and creates the schema when missing. synchronous = FULL: in WAL mode
  // NORMAL may lose the last commits on a power cut, and a lost counter row would mint an RRN
  // that a robot already holds; reads do not pay for it.
  // Two processes opening a fresh file at once can see SQLITE_BUSY without the busy handler
  // (the switch to WAL, the first WAL recovery): every step is idempotent, so it is retried.
  Status init() {
    auto deadline = steady_now() + std::chrono::seconds(10);
    for (;;) {
      busy_ = false;
      Status s = init_once();
      if (s.ok() || !busy_ || steady_now() > deadline) return s;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  Status init_once() {
    if (auto s = exec_script("PRAGMA busy_timeout = 10000; PRAGMA journal_mode = WAL; "
                             "PRAGMA synchronous = FULL; PRAGMA foreign_keys = OFF;");
        !s)
      return s;
    if (auto s = exec_script("BEGIN IMMEDIATE"); !s) return s;
    Status s = exec_script(kSchema);
    if (!s) {
      (void)exec_script("ROLLBACK");
      return s;
    }
    if (auto c = exec_script("COMMIT"); !c) return c;
    std::lock_guard lock(mu_);
    auto st = prepare("SELECT value FROM registry_meta WHERE key = 'schema_version'");
    if (!st) return st.error();
    Stmt q(*st);
    if (q.step() != SQLITE_ROW) return db_error("SQLite schema", "no schema version");
    if (std::stoll(q.text(0)) > kSchemaVersion)
      return db_error("SQLite schema", "version " + q.text(0) + " is newer than this program's");
    return Status::Ok();
  }

  std::string_view backend() const override { return "sqlite"; }

  Result<Registered> register_robot(const NewRobot& r) override;
  Result<std::optional<Robot>> get_robot(std::string_view rrn) override {
    return one_robot("SELECT " ROBOT_COLUMNS " FROM robots WHERE rrn = ? AND deleted = 0",
                     ascii_upper(rrn));
  }
  Result<std::optional<Robot>> find_robot_by_uri(std::string_view uri) override {
    return one_robot(
        "SELECT " ROBOT_COLUMNS
        " FROM robots WHERE rcan_uri = ? AND deleted = 0 ORDER BY synced, seq DESC LIMIT 1",
        uri);
  }
  Result<RobotPage> list_robots(const RobotQuery& q) override;
  Result<std::optional<Robot>> update_robot(std::string_view rrn, const RobotUpdate& u) override {
    std::lock_guard lock(mu_);
    auto st = prepare(
        "UPDATE robots SET description = coalesce(?, description), "
        "contact_email = coalesce(?, contact_email), metadata_json = coalesce(?, metadata_json), "
        "endpoints_json = coalesce(?, endpoints_json), ed25519_pub = coalesce(?, ed25519_pub), "
        "mldsa65_pub = coalesce(?, mldsa65_pub), "
        "verification_tier = coalesce(?, verification_tier), updated_at = ? "
        "WHERE rrn = ? AND deleted = 0 RETURNING " ROBOT_COLUMNS);
    if (!st) return st.error();
    Stmt q(*st);
    q.bind_all(u.description, u.contact_email, u.metadata_json, u.endpoints_json, u.ed25519_pub,
               u.mldsa65_pub, u.verification_tier, u.now, ascii_upper(rrn));
    int rc = q.step();
    if (rc == SQLITE_DONE) return std::optional<Robot>();
    if (rc != SQLITE_ROW) return error("update_robot");
    Robot robot = q.robot();
    if (q.finish() != SQLITE_DONE) return error("update_robot");
    return std::optional<Robot>(std::move(robot));
  }
  Result<bool> delete_robot(std::string_view rrn, std::string_view now) override {
    return changed("UPDATE robots SET deleted = 1, updated_at = ? WHERE rrn = ? AND deleted = 0",
                   now, ascii_upper(rrn));
  }
  Result<std::vector<Robot>> robots_changed_since(std::string_view since, int limit) override {
    std::lock_guard lock(mu_);
    auto st = prepare("SELECT " ROBOT_COLUMNS
                      " FROM robots WHERE updated_at > ? ORDER BY updated_at, seq LIMIT ?");
    if (!st) return st.error();
    Stmt q(*st);
    q.bind_all(since, limit);
    std::vector<Robot> out;
    int rc;
    while ((rc = q.step()) == SQLITE_ROW) out.push_back(q.robot());
    if (rc != SQLITE_DONE) return error("robots_changed_since");
    return out;
  }
  Status upsert_synced_robot(const Robot& r) override {
    auto n = changed(
        "INSERT INTO robots (" ROBOT_COLUMNS ", synced) VALUES (" ROBOT_VALUES
        ", 1) "
        "ON CONFLICT (rrn) DO UPDATE SET manufacturer = excluded.manufacturer, "
        "model = excluded.model, version = excluded.version, device_id = excluded.device_id, "
        "rcan_uri = excluded.rcan_uri, verification_tier = excluded.verification_tier, "
        "description = excluded.description, contact_email = excluded.contact_email, "
        "source = excluded.source, metadata_json = excluded.metadata_json, "
        "ed25519_pub = excluded.ed25519_pub, mldsa65_pub = excluded.mldsa65_pub, "
        "endpoints_json = excluded.endpoints_json, owner_key_id = excluded.owner_key_id, "
        "registered_at = excluded.registered_at, updated_at = excluded.updated_at, "
        "deleted = excluded.deleted, synced = 1",
        ascii_upper(r.rrn), r.manufacturer, r.model, r.version, r.device_id, r.rcan_uri,
        r.verification_tier, r.description, r.contact_email, r.source, r.metadata_json,
        r.ed25519_pub, r.mldsa65_pub, r.endpoints_json, r.owner_key_id, r.registered_at,
        r.updated_at, r.deleted);
    if (!n) return n.error();
    return Status::Ok();
  }

  Status put_api_key(const ApiKey& k) override {
    auto n = changed(
        "INSERT INTO api_keys (id, salt, hash, role, rrn, label, created_at, revoked_at) "
        "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
        k.id, k.salt, k.hash, k.role, k.rrn, k.label, k.created_at, k.revoked_at);
    if (!n) return n.error();
    return Status::Ok();
  }
  Result<bool> put_first_admin_key(const ApiKey& k) override {
    // One statement: SQLite takes the database's write lock for it whole.
    return changed(
        "INSERT INTO api_keys (id, salt, hash, role, rrn, label, created_at, revoked_at) "
        "SELECT ?, ?, ?, 'admin', ?, ?, ?, ? WHERE NOT EXISTS "
        "(SELECT 1 FROM api_keys WHERE role = 'admin' AND revoked_at = '')",
        k.id, k.salt, k.hash, k.rrn, k.label, k.created_at, k.revoked_at);
  }
  Result<std::optional<ApiKey>> get_api_key(std::string_view id) override {
    auto v = api_keys(
        "SELECT id, salt, hash, role, rrn, label, created_at, revoked_at "
        "FROM api_keys WHERE id = ?",
        id);
    if (!v) return v.error();
    if (v->empty()) return std::optional<ApiKey>();
    return std::optional<ApiKey>(std::move(v->front()));
  }
  Result<bool> revoke_api_key(std::string_view id, std::string_view now) override {
    return changed("UPDATE api_keys SET revoked_at = ? WHERE id = ? AND revoked_at = ''", now, id);
  }
  Result<std::vector<ApiKey>> list_api_keys() override {
    return api_keys(
        "SELECT id, salt, hash, role, rrn, label, created_at, revoked_at FROM api_keys "
        "ORDER BY created_at, id");
  }

  Result<bool> add_delegation(const Delegation& d) override {
    return changed(
        "INSERT INTO delegations (prefix, operator_name, node_url, node_pubkey, contact, "
        "delegated_at, expires_at) VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING",
        ascii_upper(d.prefix), d.operator_name, d.node_url, d.node_pubkey, d.contact,
        d.delegated_at, d.expires_at);
  }
  Result<std::optional<Delegation>> get_delegation(std::string_view prefix) override {
    auto v = delegations(
        "SELECT prefix, operator_name, node_url, node_pubkey, contact, delegated_at, expires_at "
        "FROM delegations WHERE prefix = ?",
        ascii_upper(prefix));
    if (!v) return v.error();
    if (v->empty()) return std::optional<Delegation>();
    return std::optional<Delegation>(std::move(v->front()));
  }
  Result<std::vector<Delegation>> list_delegations() override {
    return delegations(
        "SELECT prefix, operator_name, node_url, node_pubkey, contact, delegated_at, expires_at "
        "FROM delegations ORDER BY prefix");
  }

  Result<int64_t> add_webhook(const Webhook& w) override {
    std::lock_guard lock(mu_);
    auto st = prepare(
        "INSERT INTO webhooks (prefix, url, secret, created_at, last_delivered_at, "
        "failure_count) VALUES (?, ?, ?, ?, ?, ?) RETURNING id");
    if (!st) return st.error();
    Stmt q(*st);
    q.bind_all(w.prefix, w.url, w.secret, w.created_at, w.last_delivered_at, w.failure_count);
    if (q.step() != SQLITE_ROW) return error("add_webhook");
    int64_t id = q.integer(0);
    if (q.finish() != SQLITE_DONE) return error("add_webhook");
    return id;
  }
  Result<std::vector<Webhook>> webhooks_for(std::string_view prefix) override {
    std::lock_guard lock(mu_);
    auto st = prepare(
        "SELECT id, prefix, url, secret, created_at, last_delivered_at, failure_count "
        "FROM webhooks WHERE prefix = ? ORDER BY id");
    if (!st) return st.error();
    Stmt q(*st);
    q.bind(prefix);
    std::vector<Webhook> out;
    int rc;
    while ((rc = q.step()) == SQLITE_ROW) {
      Webhook w;
      w.id = q.integer(0);
      w.prefix = q.text(1);
      w.url = q.text(2);
      w.secret = q.text(3);
      w.created_at = q.text(4);
      w.last_delivered_at = q.text(5);
      w.failure_count = static_cast<int>(q.integer(6));
      out.push_back(std::move(w));
    }
    if (rc != SQLITE_DONE) return error("webhooks_for");
    return out;
  }
  Result<bool> delete_webhook(int64_t id) override {
    return changed("DELETE FROM webhooks WHERE id = ?", id);
  }
  Status record_delivery(int64_t id, bool ok, std::string_view now) override {
    auto n = ok ? changed(
                      "UPDATE webhooks SET failure_count = 0, last_delivered_at = ? "
                      "WHERE id = ?",
                      now, id)
                : changed("UPDATE webhooks SET failure_count = failure_count + 1 WHERE id = ?", id);
    if (!n) return n.error();
    return Status::Ok();
  }

  Status put_challenge(const Challenge& c) override {
    auto n = changed("INSERT INTO challenges (id, nonce, purpose, expires_at) VALUES (?, ?, ?, ?)",
                     c.id, c.nonce, c.purpose, c.expires_at);
    if (!n) return n.error();
    return Status::Ok();
  }
  Result<std::optional<Challenge>> take_challenge(std::string_view id) override {
    std::lock_guard lock(mu_);
    auto st =
        prepare("DELETE FROM challenges WHERE id = ? RETURNING id, nonce, purpose, expires_at");
    if (!st) return st.error();
    Stmt q(*st);
    q.bind(id);
    int rc = q.step();
    if (rc == SQLITE_DONE) return std::optional<Challenge>();
    if (rc != SQLITE_ROW) return error("take_challenge");
    Challenge c{q.text(0), q.text(1), q.text(2), q.text(3)};
    if (q.finish() != SQLITE_DONE) return error("take_challenge");
    return std::optional<Challenge>(std::move(c));
  }
  Result<int64_t> expire_challenges(std::string_view now) override {
    auto n = changes("DELETE FROM challenges WHERE expires_at < ?", now);
    if (!n) return n.error();
    return *n;
  }

  Result<std::vector<Row>> query(const std::string& sql, const Args& args) override {
    std::string q = sql;
    for (char& c : q)
      if (c == '$') c = '?';  // $1 → ?1 (no '$' elsewhere in the authority's SQL)
    std::lock_guard lock(mu_);
    auto st = prepare(q);
    if (!st) return st.error();
    Stmt s(*st);
    for (const auto& a : args) s.bind(a);
    int cols = sqlite3_column_count(*st);
    std::vector<Row> out;
    int rc;
    while ((rc = s.step()) == SQLITE_ROW) {
      Row r;
      for (int i = 0; i < cols; ++i) r.push_back(s.text(i));
      out.push_back(std::move(r));
    }
    if (rc != SQLITE_DONE) return error("authority");
    return out;
  }

 private:
  Error error(std::string_view what) const {
    Error e = db_error(std::string("SQLite ") + std::string(what), sqlite3_errmsg(db_));
    int code = sqlite3_extended_errcode(db_);
    if (code == SQLITE_CONSTRAINT_UNIQUE || code == SQLITE_CONSTRAINT_PRIMARYKEY)
      e.reason = detail::kUniqueViolation;
    return e;
  }

  // The cached statement for `sql` (prepared on first use). Call with mu_ held.
  Result<sqlite3_stmt*> prepare(const std::string& sql) {
    auto it = cache_.find(sql);
    if (it != cache_.end()) return it->second;
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v3(db_, sql.c_str(), static_cast<int>(sql.size()),
                           SQLITE_PREPARE_PERSISTENT, &s, nullptr) != SQLITE_OK)
      return error("prepare");
    cache_.emplace(sql, s);
    return s;
  }

  Status exec_script(const char* sql) {
    std::lock_guard lock(mu_);
    char* msg = nullptr;
    if (int rc = sqlite3_exec(db_, sql, nullptr, nullptr, &msg); rc != SQLITE_OK) {
      busy_ = busy_ || (rc & 0xff) == SQLITE_BUSY || (rc & 0xff) == SQLITE_LOCKED;
      Error e = db_error("SQLite", msg != nullptr ? msg : sqlite3_errmsg(db_));
      sqlite3_free(msg);
      return e;
    }
    return Status::Ok();
  }

  // Runs a statement without result rows; the number of rows it changed.
  template <typename... A>
  Result<int64_t> changes(const std::string& sql, const A&... a) {
    std::lock_guard lock(mu_);
    return changes_locked(sql, a...);
  }
  template <typename... A>
  Result<int64_t> changes_locked(const std::string& sql, const A&... a) {
    auto st = prepare(sql);
    if (!st) return st.error();
    Stmt q(*st);
    q.bind_all(a...);
    if (q.finish() != SQLITE_DONE) return error("statement");
    return static_cast<int64_t>(sqlite3_changes(db_));
  }
  template <typename... A>
  Result<bool> changed(const std::string& sql, const A&... a) {
    auto n = changes(sql, a...);
    if (!n) return n.error();
    return *n > 0;
  }

  template <typename A>
  Result<std::optional<Robot>> one_robot(const std::string& sql, const A& arg) {
    std::lock_guard lock(mu_);
    auto st = prepare(sql);
    if (!st) return st.error();
    Stmt q(*st);
    q.bind(arg);
    int rc = q.step();
    if (rc == SQLITE_DONE) return std::optional<Robot>();
    if (rc != SQLITE_ROW) return error("robot lookup");
    return std::optional<Robot>(q.robot());
  }

  template <typename... A>
  Result<std::vector<ApiKey>> api_keys(const std::string& sql, const A&... a) {
    std::lock_guard lock(mu_);
    auto st = prepare(sql);
    if (!st) return st.error();
    Stmt q(*st);
    q.bind_all(a...);
    std::vector<ApiKey> out;
    int rc;
    while ((rc = q.step()) == SQLITE_ROW)
      out.push_back(ApiKey{q.text(0), q.text(1), q.text(2), q.text(3), q.text(4), q.text(5),
                           q.text(6), q.text(7)});
    if (rc != SQLITE_DONE) return error("api keys");
    return out;
  }

  template <typename... A>
  Result<std::vector<Delegation>> delegations(const std::string& sql, const A&... a) {
    std::lock_guard lock(mu_);
    auto st = prepare(sql);
    if (!st) return st.error();
    Stmt q(*st);
    q.bind_all(a...);
    std::vector<Delegation> out;
    int rc;
    while ((rc = q.step()) == SQLITE_ROW)
      out.push_back(
          Delegation{q.text(0), q.text(1), q.text(2), q.text(3), q.text(4), q.text(5), q.text(6)});
    if (rc != SQLITE_DONE) return error("delegations");
    return out;
  }

  // BEGIN IMMEDIATE … COMMIT, rolled back unless committed. Call with mu_ held.
  class Txn {
   public:
    explicit Txn(SqliteStore& s) : s_(s) { ok_ = s_.changes_locked("BEGIN IMMEDIATE").ok(); }
    ~Txn() {
      if (ok_ && !done_) (void)s_.changes_locked("ROLLBACK");
    }
    bool ok() const { return ok_; }
    bool commit() {
      done_ = true;
      return s_.changes_locked("COMMIT").ok();
    }

   private:
    SqliteStore& s_;
    bool ok_ = false, done_ = false;
  };

  Result<std::optional<Robot>> live_by_slugs(const NewRobot& r);

  sqlite3* db_;
  StoreOptions opts_;
  std::mutex mu_;
  std::unordered_map<std::string, sqlite3_stmt*> cache_;
  bool busy_ = false;  // init: a step failed with SQLITE_BUSY or SQLITE_LOCKED
};

Result<std::optional<Robot>> SqliteStore::live_by_slugs(const NewRobot& r) {
  auto st = prepare("SELECT " ROBOT_COLUMNS
                    " FROM robots WHERE manufacturer = ? AND model = ? AND version = ? "
                    "AND device_id = ? AND deleted = 0 AND synced = 0");
  if (!st) return st.error();
  Stmt q(*st);
  q.bind_all(r.manufacturer, r.model, r.version, r.device_id);
  int rc = q.step();
  if (rc == SQLITE_DONE) return std::optional<Robot>();
  if (rc != SQLITE_ROW) return error("register_robot");
  return std::optional<Robot>(q.robot());
}

Result<Registered> SqliteStore::register_robot(const NewRobot& r) {
  std::lock_guard lock(mu_);
  Txn txn(*this);
  if (!txn.ok()) return error("register_robot: BEGIN");
  // The live robot with these slugs, if any; else a new number. An INSERT that still meets a
  // unique constraint met an RRN that a synced robot holds: the next number is tried.
  for (int attempt = 0; attempt < 100; ++attempt) {
    auto existing = live_by_slugs(r);
    if (!existing) return existing.error();
    if (*existing) {
      if (!txn.commit()) return error("register_robot: COMMIT");
      return Registered{std::move(**existing), false};
    }
    auto st = prepare("UPDATE rrn_counter SET last = last + 1 WHERE id = 1 RETURNING last");
    if (!st) return st.error();
    int64_t n = 0;
    {
      Stmt q(*st);
      if (q.step() != SQLITE_ROW) return error("register_robot: counter");
      n = q.integer(0);
      if (q.finish() != SQLITE_DONE) return error("register_robot: counter");
    }
    Robot robot = robot_of(r);
    robot.rrn = format_rrn(n, opts_.rrn_prefix);  // rcan/ruri.h
    auto ins = prepare("INSERT INTO robots (" ROBOT_COLUMNS ") VALUES (" ROBOT_VALUES ")");
    if (!ins) return ins.error();
    int rc;
    {
      Stmt q(*ins);
      q.bind_all(robot.rrn, robot.manufacturer, robot.model, robot.version, robot.device_id,
                 robot.rcan_uri, robot.verification_tier, robot.description, robot.contact_email,
                 robot.source, robot.metadata_json, robot.ed25519_pub, robot.mldsa65_pub,
                 robot.endpoints_json, robot.owner_key_id, robot.registered_at, robot.updated_at,
                 robot.deleted);
      rc = q.finish();
    }
    if (rc == SQLITE_DONE) {
      if (!txn.commit()) return error("register_robot: COMMIT");
      return Registered{std::move(robot), true};
    }
    if ((rc & 0xff) != SQLITE_CONSTRAINT) return error("register_robot");
  }
  return db_error("SQLite register_robot", "no free RRN after 100 attempts");
}

Result<RobotPage> SqliteStore::list_robots(const RobotQuery& q) {
  std::vector<std::string> values;
  std::string where = detail::robot_filter(
      q, "deleted = 0", [](size_t i) { return "?" + std::to_string(i); }, values);
  std::lock_guard lock(mu_);
  RobotPage page;
  {
    auto st = prepare("SELECT count(*) FROM robots WHERE " + where);
    if (!st) return st.error();
    Stmt c(*st);
    for (const auto& v : values) c.bind(v);
    if (c.step() != SQLITE_ROW) return error("list_robots");
    page.total = c.integer(0);
  }
  auto st =
      prepare("SELECT " ROBOT_COLUMNS " FROM robots WHERE " + where +
              " ORDER BY registered_at DESC, seq DESC LIMIT ?" + std::to_string(values.size() + 1) +
              " OFFSET ?" + std::to_string(values.size() + 2));
  if (!st) return st.error();
  Stmt s(*st);
  for (const auto& v : values) s.bind(v);
  s.bind(static_cast<int64_t>(q.limit)).bind(q.offset);
  int rc;
  while ((rc = s.step()) == SQLITE_ROW) page.robots.push_back(s.robot());
  if (rc != SQLITE_DONE) return error("list_robots");
  return page;
}

}  // namespace

Result<std::unique_ptr<Store>> open_sqlite(const std::string& path, const StoreOptions& o) {
  // The file holds API key hashes and webhook secrets: created 0600 (SQLite gives its -wal and
  // -shm files the database file's mode).
  if (path != ":memory:") {
    int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0)
      return Error(ErrorCode::kInternal, "SQLite: cannot open " + path + ": " + strerror(errno));
    ::close(fd);
  }
  sqlite3* db = nullptr;
  int rc = sqlite3_open_v2(
      path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    Error e =
        db_error("SQLite open " + path, db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc));
    sqlite3_close_v2(db);
    return e;
  }
  auto store = std::make_unique<SqliteStore>(db, o);
  if (auto s = store->init(); !s) return s.error();
  return std::unique_ptr<Store>(std::move(store));
}

}  // namespace rcan::registry
