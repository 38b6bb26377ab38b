// The registry's storage in PostgreSQL (store.h), for several stateless registry instances on
// one database: RRNs from a SEQUENCE (gaps allowed, never a duplicate), one live row per robot
// by a partial unique index and INSERT … ON CONFLICT DO NOTHING, the schema created under an
// advisory lock. A small pool of connections, each used by one thread at a time, each with its
// statements prepared once; a broken connection is dropped and the call tried once more on a
// fresh one.
#include <libpq-fe.h>

#include <condition_variable>
#include <mutex>
#include <unordered_map>

#include "base/strings.h"
#include "rcan/ruri.h"
#include "registry/store.h"
#include "registry/store_internal.h"

namespace rcan::registry {
namespace {

using detail::db_error;

constexpr int kSchemaVersion = 1;
constexpr size_t kPoolSize = 8;
constexpr long long kSchemaLock = 0x7263616e72656769;  // "rcanregi": serialises schema creation
constexpr long long kAdminLock = 0x7263616e61646d6e;   // "rcanadmn": the first admin key

const char* const kSchema = R"SQL(
CREATE TABLE IF NOT EXISTS registry_meta (
  key   text PRIMARY KEY,
  value text NOT NULL
);
INSERT INTO registry_meta (key, value) VALUES ('schema_version', '1') ON CONFLICT DO NOTHING;
CREATE SEQUENCE IF NOT EXISTS rrn_seq;
CREATE TABLE IF NOT EXISTS robots (
  seq               bigserial PRIMARY KEY,
  rrn               text    NOT NULL UNIQUE,
  manufacturer      text    NOT NULL,
  model             text    NOT NULL,
  version           text    NOT NULL,
  device_id         text    NOT NULL,
  rcan_uri          text    NOT NULL,
  verification_tier text    NOT NULL,
  description       text    NOT NULL,
  contact_email     text    NOT NULL,
  source            text    NOT NULL,
  metadata_json     text    NOT NULL,
  ed25519_pub       text    NOT NULL,
  mldsa65_pub       text    NOT NULL,
  endpoints_json    text    NOT NULL,
  owner_key_id      text    NOT NULL,
  registered_at     text    NOT NULL,
  updated_at        text    NOT NULL,
  deleted           boolean NOT NULL DEFAULT false,
  synced            boolean NOT NULL DEFAULT false  -- pulled from an authoritative node
);
CREATE UNIQUE INDEX IF NOT EXISTS robots_live_slugs
  ON robots (manufacturer, model, version, device_id) WHERE NOT deleted AND NOT synced;
CREATE INDEX IF NOT EXISTS robots_uri ON robots (rcan_uri);
CREATE INDEX IF NOT EXISTS robots_registered ON robots (registered_at, seq);
CREATE INDEX IF NOT EXISTS robots_updated ON robots (updated_at, seq);
CREATE TABLE IF NOT EXISTS api_keys (
  id         text PRIMARY KEY,
  salt       text NOT NULL,
  hash       text NOT NULL,
  role       text NOT NULL,
  rrn        text NOT NULL,
  label      text NOT NULL,
  created_at text NOT NULL,
  revoked_at text NOT NULL DEFAULT ''
);
CREATE TABLE IF NOT EXISTS delegations (
  prefix        text PRIMARY KEY,
  operator_name text NOT NULL,
  node_url      text NOT NULL,
  node_pubkey   text NOT NULL,
  contact       text NOT NULL,
  delegated_at  text NOT NULL,
  expires_at    text NOT NULL
);
CREATE TABLE IF NOT EXISTS webhooks (
  id                bigserial PRIMARY KEY,
  prefix            text    NOT NULL,
  url               text    NOT NULL,
  secret            text    NOT NULL,
  created_at        text    NOT NULL,
  last_delivered_at text    NOT NULL DEFAULT '',
  failure_count     integer NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS webhooks_prefix ON webhooks (prefix);
CREATE TABLE IF NOT EXISTS challenges (
  id         text PRIMARY KEY,
  nonce      text NOT NULL,
  purpose    text NOT NULL,
  expires_at text NOT NULL
);
CREATE INDEX IF NOT EXISTS challenges_expiry ON challenges (expires_at);
CREATE TABLE IF NOT EXISTS authority_keys (
  kid          text PRIMARY KEY,
  seed         text NOT NULL,
  created_ms   bigint NOT NULL,
  sign_from_ms bigint NOT NULL
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
  id         bigserial PRIMARY KEY,
  principal  text NOT NULL,
  rrn        text NOT NULL,
  fleet      text NOT NULL,
  role       text NOT NULL,
  scope      text NOT NULL,
  max_ttl_s  bigint NOT NULL,
  created_by text NOT NULL,
  created_at text NOT NULL
);
CREATE INDEX IF NOT EXISTS authority_grants_principal ON authority_grants (principal);
CREATE TABLE IF NOT EXISTS authority_revocations (
  seq        bigserial PRIMARY KEY,
  jti        text,
  sub        text,
  exp        bigint,
  revoked_at text NOT NULL,
  revoked_ms bigint NOT NULL,
  reason     text NOT NULL,
  revoked_by text NOT NULL
);
CREATE INDEX IF NOT EXISTS authority_revocations_jti ON authority_revocations (jti);
CREATE INDEX IF NOT EXISTS authority_revocations_sub ON authority_revocations (sub);
CREATE TABLE IF NOT EXISTS authority_used_jtis (
  jti    text PRIMARY KEY,
  exp_ms bigint NOT NULL
);
CREATE TABLE IF NOT EXISTS authority_device_codes (
  device_hash  text PRIMARY KEY,
  user_code    text NOT NULL UNIQUE,
  client_id    text NOT NULL,
  resource     text NOT NULL,
  scope        text NOT NULL,
  expires_ms   bigint NOT NULL,
  interval_s   bigint NOT NULL,
  last_poll_ms bigint NOT NULL,
  status       text NOT NULL,
  subject      text NOT NULL
);
)SQL";

#define ROBOT_COLUMNS                                                                        \
  "rrn, manufacturer, model, version, device_id, rcan_uri, verification_tier, description, " \
  "contact_email, source, metadata_json, ed25519_pub, mldsa65_pub, endpoints_json, "         \
  "owner_key_id, registered_at, updated_at, deleted"

using Params = std::vector<std::optional<std::string>>;

std::optional<std::string> param(std::string_view v) { return std::string(v); }
std::optional<std::string> param(const std::string& v) { return v; }
std::optional<std::string> param(const std::optional<std::string>& v) { return v; }
std::optional<std::string> param(int64_t v) { return std::to_string(v); }
std::optional<std::string> param(int v) { return std::to_string(v); }
std::optional<std::string> param(bool v) { return std::string(v ? "true" : "false"); }
template <typename... A>
Params params(const A&... a) {
  return Params{param(a)...};
}

// A query's result (owned; cleared on destruction).
class Rows {
 public:
  explicit Rows(PGresult* r) : r_(r) {}
  ~Rows() {
    if (r_ != nullptr) PQclear(r_);
  }
  Rows(Rows&& o) noexcept : r_(o.r_) { o.r_ = nullptr; }
  Rows& operator=(Rows&&) = delete;
  Rows(const Rows&) = delete;

  PGresult* get() const { return r_; }
  int size() const { return PQntuples(r_); }
  std::string text(int row, int col) const {
    return std::string(PQgetvalue(r_, row, col), PQgetlength(r_, row, col));
  }
  int64_t integer(int row, int col) const { return std::stoll(text(row, col)); }
  int64_t affected() const {
    const char* n = PQcmdTuples(r_);
    return n == nullptr || *n == '\0' ? 0 : std::stoll(n);
  }
  Robot robot(int row) const {
    Robot r;
    int i = 0;
    for (std::string* f : {&r.rrn, &r.manufacturer, &r.model, &r.version, &r.device_id, &r.rcan_uri,
                           &r.verification_tier, &r.description, &r.contact_email, &r.source,
                           &r.metadata_json, &r.ed25519_pub, &r.mldsa65_pub, &r.endpoints_json,
                           &r.owner_key_id, &r.registered_at, &r.updated_at})
      *f = text(row, i++);
    r.deleted = text(row, i) == "t";
    return r;
  }
  std::vector<Robot> robots() const {
    std::vector<Robot> out;
    out.reserve(size());
    for (int i = 0; i < size(); ++i) out.push_back(robot(i));
    return out;
  }

 private:
  PGresult* r_;
};

// One connection and the statements prepared on it (by SQL text).
struct Conn {
  PGconn* pg = nullptr;
  std::unordered_map<std::string, std::string> prepared;
  ~Conn() {
    if (pg != nullptr) PQfinish(pg);
  }
  bool broken() const { return PQstatus(pg) != CONNECTION_OK; }

  Result<Rows> exec(const std::string& sql, const Params& p) {
    auto it = prepared.find(sql);
    if (it == prepared.end()) {
      std::string name = "s" + std::to_string(prepared.size());
      Rows prep(PQprepare(pg, name.c_str(), sql.c_str(), static_cast<int>(p.size()), nullptr));
      if (PQresultStatus(prep.get()) != PGRES_COMMAND_OK)
        return db_error("PostgreSQL prepare", PQerrorMessage(pg));
      it = prepared.emplace(sql, name).first;
    }
    std::vector<const char*> values;
    values.reserve(p.size());
    for (const auto& v : p) values.push_back(v ? v->c_str() : nullptr);
    PGresult* r = PQexecPrepared(pg, it->second.c_str(), static_cast<int>(values.size()),
                                 values.data(), nullptr, nullptr, 0);
    Rows rows(r);
    ExecStatusType st = PQresultStatus(r);
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) {
      const char* state = PQresultErrorField(r, PG_DIAG_SQLSTATE);
      Error e = db_error("PostgreSQL", r != nullptr ? PQresultErrorMessage(r) : PQerrorMessage(pg));
      if (state != nullptr && std::string_view(state) == "23505")
        e.reason = detail::kUniqueViolation;
      return e;
    }
    return rows;
  }
  // A script without parameters (simple query protocol: several statements at once).
  Status script(const char* sql) {
    Rows r(PQexec(pg, sql));
    ExecStatusType st = PQresultStatus(r.get());
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK)
      return db_error("PostgreSQL", PQerrorMessage(pg));
    return Status::Ok();
  }
};

// Up to kPoolSize connections, opened on demand; a thread borrows one for a call.
class Pool {
 public:
  explicit Pool(std::string conninfo) : conninfo_(std::move(conninfo)) {}

  class Lease {
   public:
    Lease(Pool* p, std::unique_ptr<Conn> c) : pool_(p), conn_(std::move(c)) {}
    Lease(Lease&&) = default;
    Lease& operator=(Lease&&) = delete;
    ~Lease() {
      if (pool_ != nullptr && conn_ != nullptr) pool_->give_back(std::move(conn_));
    }
    Conn* operator->() { return conn_.get(); }
    Conn& operator*() { return *conn_; }

   private:
    Pool* pool_;
    std::unique_ptr<Conn> conn_;
  };

  Result<Lease> acquire() {
    std::unique_lock lock(mu_);
    cv_.wait(lock, [&] { return !idle_.empty() || open_ < kPoolSize; });
    if (!idle_.empty()) {
      auto c = std::move(idle_.back());
      idle_.pop_back();
      return Lease(this, std::move(c));
    }
    ++open_;
    lock.unlock();
    auto c = std::make_unique<Conn>();
    c->pg = PQconnectdb(conninfo_.c_str());
    if (PQstatus(c->pg) != CONNECTION_OK) {
      Error e = db_error("PostgreSQL connection", PQerrorMessage(c->pg));
      c.reset();
      lock.lock();
      --open_;
      cv_.notify_one();
      return e;
    }
    return Lease(this, std::move(c));
  }

 private:
  void give_back(std::unique_ptr<Conn> c) {
    std::lock_guard lock(mu_);
    if (c->broken() || PQtransactionStatus(c->pg) != PQTRANS_IDLE) {
      c.reset();  // a fresh connection replaces it on demand
      --open_;
    } else {
      idle_.push_back(std::move(c));
    }
    cv_.notify_one();
  }

  std::string conninfo_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<std::unique_ptr<Conn>> idle_;
  size_t open_ = 0;
};

class PgStore final : public Store {
 public:
  PgStore(const std::string& conninfo, StoreOptions o) : pool_(conninfo), opts_(std::move(o)) {}

  // Creates the schema when missing, one instance at a time (an advisory transaction lock).
  Status init() {
    auto lease = pool_.acquire();
    if (!lease) return lease.error();
    Conn& c = **lease;
    if (auto s = c.script("SET client_min_messages = warning"); !s) return s;
    std::string create = "BEGIN; SELECT pg_advisory_xact_lock(" + std::to_string(kSchemaLock) +
                         ");\n" + kSchema + "COMMIT;";
    if (auto s = c.script(create.c_str()); !s) {
      (void)c.script("ROLLBACK");
      return s;
    }
    auto v = c.exec("SELECT value FROM registry_meta WHERE key = 'schema_version'", {});
    if (!v) return v.error();
    if (v->size() != 1) return db_error("PostgreSQL schema", "no schema version");
    if (v->integer(0, 0) > kSchemaVersion)
      return db_error("PostgreSQL schema",
                      "version " + v->text(0, 0) + " is newer than this program's");
    return Status::Ok();
  }

  std::string_view backend() const override { return "postgresql"; }

  Result<Registered> register_robot(const NewRobot& r) override;
  Result<std::optional<Robot>> get_robot(std::string_view rrn) override {
    return one_robot("SELECT " ROBOT_COLUMNS " FROM robots WHERE rrn = $1 AND NOT deleted",
                     params(ascii_upper(rrn)));
  }
  Result<std::optional<Robot>> find_robot_by_uri(std::string_view uri) override {
    return one_robot(
        "SELECT " ROBOT_COLUMNS
        " FROM robots WHERE rcan_uri = $1 AND NOT deleted ORDER BY synced, seq DESC LIMIT 1",
        params(uri));
  }
  Result<RobotPage> list_robots(const RobotQuery& q) override;
  Result<std::optional<Robot>> update_robot(std::string_view rrn, const RobotUpdate& u) override {
    return one_robot(
        "UPDATE robots SET description = coalesce($1, description), "
        "contact_email = coalesce($2, contact_email), metadata_json = coalesce($3, metadata_json), "
        "endpoints_json = coalesce($4, endpoints_json), ed25519_pub = coalesce($5, ed25519_pub), "
        "mldsa65_pub = coalesce($6, mldsa65_pub), "
        "verification_tier = coalesce($7, verification_tier), updated_at = $8 "
        "WHERE rrn = $9 AND NOT deleted RETURNING " ROBOT_COLUMNS,
        params(u.description, u.contact_email, u.metadata_json, u.endpoints_json, u.ed25519_pub,
               u.mldsa65_pub, u.verification_tier, u.now, ascii_upper(rrn)));
  }
  Result<bool> delete_robot(std::string_view rrn, std::string_view now) override {
    return changed(
        "UPDATE robots SET deleted = true, updated_at = $1 WHERE rrn = $2 AND NOT deleted",
        params(now, ascii_upper(rrn)));
  }
  Result<std::vector<Robot>> robots_changed_since(std::string_view since, int limit) override {
    auto rows = run("SELECT " ROBOT_COLUMNS
                    " FROM robots WHERE updated_at > $1 ORDER BY updated_at, seq LIMIT $2",
                    params(since, limit));
    if (!rows) return rows.error();
    return rows->robots();
  }
  Status upsert_synced_robot(const Robot& r) override {
    auto rows =
        run("INSERT INTO robots (" ROBOT_COLUMNS
            ", synced) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, "
            "$9, $10, $11, $12, $13, $14, $15, $16, $17, $18, true) "
            "ON CONFLICT (rrn) DO UPDATE SET manufacturer = excluded.manufacturer, "
            "model = excluded.model, version = excluded.version, device_id = excluded.device_id, "
            "rcan_uri = excluded.rcan_uri, verification_tier = excluded.verification_tier, "
            "description = excluded.description, contact_email = excluded.contact_email, "
            "source = excluded.source, metadata_json = excluded.metadata_json, "
            "ed25519_pub = excluded.ed25519_pub, mldsa65_pub = excluded.mldsa65_pub, "
            "endpoints_json = excluded.endpoints_json, owner_key_id = excluded.owner_key_id, "
            "registered_at = excluded.registered_at, updated_at = excluded.updated_at, "
            "deleted = excluded.deleted, synced = true",
            params(ascii_upper(r.rrn), r.manufacturer, r.model, r.version, r.device_id, r.rcan_uri,
                   r.verification_tier, r.description, r.contact_email, r.source, r.metadata_json,
                   r.ed25519_pub, r.mldsa65_pub, r.endpoints_json, r.owner_key_id, r.registered_at,
                   r.updated_at, r.deleted));
    if (!rows) return rows.error();
    return Status::Ok();
  }

  Status put_api_key(const ApiKey& k) override {
    auto rows =
        run("INSERT INTO api_keys (id, salt, hash, role, rrn, label, created_at, revoked_at) "
            "VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            params(k.id, k.salt, k.hash, k.role, k.rrn, k.label, k.created_at, k.revoked_at));
    if (!rows) return rows.error();
    return Status::Ok();
  }
  Result<bool> put_first_admin_key(const ApiKey& k) override {
    // The check and the insert in one transaction under an advisory lock: the insert's
    // statement sees every admin key an instance that held the lock before committed.
    auto lease = pool_.acquire();
    if (!lease) return lease.error();
    Conn& c = **lease;
    if (Status s = c.script("BEGIN"); !s.ok()) return s.error();
    auto lock = c.exec("SELECT pg_advisory_xact_lock(" + std::to_string(kAdminLock) + ")", {});
    auto ins = lock ? c.exec(
                          "INSERT INTO api_keys (id, salt, hash, role, rrn, label, created_at, "
                          "revoked_at) SELECT $1, $2, $3, 'admin', $4, $5, $6, $7 WHERE NOT "
                          "EXISTS (SELECT 1 FROM api_keys WHERE role = 'admin' AND "
                          "revoked_at = '')",
                          params(k.id, k.salt, k.hash, k.rrn, k.label, k.created_at, k.revoked_at))
                    : Result<Rows>(lock.error());
    if (!ins) {
      (void)c.script("ROLLBACK");
      return ins.error();
    }
    if (Status s = c.script("COMMIT"); !s.ok()) return s.error();
    return ins->affected() > 0;
  }
  Result<std::optional<ApiKey>> get_api_key(std::string_view id) override {
    auto v = api_keys(
        "SELECT id, salt, hash, role, rrn, label, created_at, revoked_at "
        "FROM api_keys WHERE id = $1",
        params(id));
    if (!v) return v.error();
    if (v->empty()) return std::optional<ApiKey>();
    return std::optional<ApiKey>(std::move(v->front()));
  }
  Result<bool> revoke_api_key(std::string_view id, std::string_view now) override {
    return changed("UPDATE api_keys SET revoked_at = $1 WHERE id = $2 AND revoked_at = ''",
                   params(now, id));
  }
  Result<std::vector<ApiKey>> list_api_keys() override {
    return api_keys(
        "SELECT id, salt, hash, role, rrn, label, created_at, revoked_at FROM api_keys "
        "ORDER BY created_at, id",
        {});
  }

  Result<bool> add_delegation(const Delegation& d) override {
    return changed(
        "INSERT INTO delegations (prefix, operator_name, node_url, node_pubkey, contact, "
        "delegated_at, expires_at) VALUES ($1, $2, $3, $4, $5, $6, $7) ON CONFLICT DO NOTHING",
        params(ascii_upper(d.prefix), d.operator_name, d.node_url, d.node_pubkey, d.contact,
               d.delegated_at, d.expires_at));
  }
  Result<std::optional<Delegation>> get_delegation(std::string_view prefix) override {
    auto v = delegations(
        "SELECT prefix, operator_name, node_url, node_pubkey, contact, delegated_at, expires_at "
        "FROM delegations WHERE prefix = $1",
        params(ascii_upper(prefix)));
    if (!v) return v.error();
    if (v->empty()) return std::optional<Delegation>();
    return std::optional<Delegation>(std::move(v->front()));
  }
  Result<std::vector<Delegation>> list_delegations() override {
    return delegations(
        "SELECT prefix, operator_name, node_url, node_pubkey, contact, delegated_at, expires_at "
        "FROM delegations ORDER BY prefix",
        {});
  }

  Result<int64_t> add_webhook(const Webhook& w) override {
    auto rows =
        run("INSERT INTO webhooks (prefix, url, secret, created_at, last_delivered_at, "
            "failure_count) VALUES ($1, $2, $3, $4, $5, $6) RETURNING id",
            params(w.prefix, w.url, w.secret, w.created_at, w.last_delivered_at, w.failure_count));
    if (!rows) return rows.error();
    return rows->integer(0, 0);
  }
  Result<std::vector<Webhook>> webhooks_for(std::string_view prefix) override {
    auto rows =
        run("SELECT id, prefix, url, secret, created_at, last_delivered_at, failure_count "
            "FROM webhooks WHERE prefix = $1 ORDER BY id",
            params(prefix));
    if (!rows) return rows.error();
    std::vector<Webhook> out;
    for (int i = 0; i < rows->size(); ++i) {
      Webhook w;
      w.id = rows->integer(i, 0);
      w.prefix = rows->text(i, 1);
      w.url = rows->text(i, 2);
      w.secret = rows->text(i, 3);
      w.created_at = rows->text(i, 4);
      w.last_delivered_at = rows->text(i, 5);
      w.failure_count = static_cast<int>(rows->integer(i, 6));
      out.push_back(std::move(w));
    }
    return out;
  }
  Result<bool> delete_webhook(int64_t id) override {
    return changed("DELETE FROM webhooks WHERE id = $1", params(id));
  }
  Status record_delivery(int64_t id, bool ok, std::string_view now) override {
    auto n =
        ok ? run("UPDATE webhooks SET failure_count = 0, last_delivered_at = $1 "
                 "WHERE id = $2",
                 params(now, id))
           : run("UPDATE webhooks SET failure_count = failure_count + 1 WHERE id = $1", params(id));
    if (!n) return n.error();
    return Status::Ok();
  }

  Status put_challenge(const Challenge& c) override {
    auto rows =
        run("INSERT INTO challenges (id, nonce, purpose, expires_at) VALUES ($1, $2, $3, $4)",
            params(c.id, c.nonce, c.purpose, c.expires_at));
    if (!rows) return rows.error();
    return Status::Ok();
  }
  Result<std::optional<Challenge>> take_challenge(std::string_view id) override {
    auto rows = run("DELETE FROM challenges WHERE id = $1 RETURNING id, nonce, purpose, expires_at",
                    params(id));
    if (!rows) return rows.error();
    if (rows->size() == 0) return std::optional<Challenge>();
    return std::optional<Challenge>(
        Challenge{rows->text(0, 0), rows->text(0, 1), rows->text(0, 2), rows->text(0, 3)});
  }
  Result<int64_t> expire_challenges(std::string_view now) override {
    auto rows = run("DELETE FROM challenges WHERE expires_at < $1", params(now));
    if (!rows) return rows.error();
    return rows->affected();
  }

  Result<std::vector<Row>> query(const std::string& sql, const Args& args) override {
    auto rows = run(sql, args);
    if (!rows) return rows.error();
    std::vector<Row> out;
    int cols = PQnfields(rows->get());
    for (int i = 0; i < rows->size(); ++i) {
      Row r;
      for (int c = 0; c < cols; ++c) r.push_back(rows->text(i, c));
      out.push_back(std::move(r));
    }
    return out;
  }

 private:
  // Runs one statement on a pooled connection. A connection that turns out broken (the server
  // restarted, the network dropped it) is dropped and the statement runs on the next one: the
  // idle ones may all be broken, so up to one more than the pool holds, the last a fresh one.
  Result<Rows> run(const std::string& sql, const Params& p) {
    for (size_t attempt = 0;; ++attempt) {
      auto lease = pool_.acquire();
      if (!lease) return lease.error();
      auto rows = (*lease)->exec(sql, p);
      if (rows.ok() || !(*lease)->broken() || attempt >= kPoolSize) return rows;
    }
  }
  Result<bool> changed(const std::string& sql, const Params& p) {
    auto rows = run(sql, p);
    if (!rows) return rows.error();
    return rows->affected() > 0;
  }
  Result<std::optional<Robot>> one_robot(const std::string& sql, const Params& p) {
    auto rows = run(sql, p);
    if (!rows) return rows.error();
    if (rows->size() == 0) return std::optional<Robot>();
    return std::optional<Robot>(rows->robot(0));
  }
  Result<std::vector<ApiKey>> api_keys(const std::string& sql, const Params& p) {
    auto rows = run(sql, p);
    if (!rows) return rows.error();
    std::vector<ApiKey> out;
    for (int i = 0; i < rows->size(); ++i)
      out.push_back(ApiKey{rows->text(i, 0), rows->text(i, 1), rows->text(i, 2), rows->text(i, 3),
                           rows->text(i, 4), rows->text(i, 5), rows->text(i, 6), rows->text(i, 7)});
    return out;
  }
  Result<std::vector<Delegation>> delegations(const std::string& sql, const Params& p) {
    auto rows = run(sql, p);
    if (!rows) return rows.error();
    std::vector<Delegation> out;
    for (int i = 0; i < rows->size(); ++i)
      out.push_back(Delegation{rows->text(i, 0), rows->text(i, 1), rows->text(i, 2),
                               rows->text(i, 3), rows->text(i, 4), rows->text(i, 5),
                               rows->text(i, 6)});
    return out;
  }

  Pool pool_;
  StoreOptions opts_;
};

Result<Registered> PgStore::register_robot(const NewRobot& r) {
  const std::string uri = detail::robot_uri(r);
  // Insert with a fresh number unless any unique constraint objects (the live robot with these
  // slugs exists, or a synced robot holds that RRN); then return the live robot. Nothing live
  // and nothing inserted: it was deleted meanwhile, or the RRN was taken: try again (each
  // attempt takes a number of its own, as the SQLite store's does).
  for (int attempt = 0; attempt < 100; ++attempt) {
    auto seq = run("SELECT nextval('rrn_seq')", Params{});
    if (!seq) return seq.error();
    const std::string rrn = format_rrn(seq->integer(0, 0), opts_.rrn_prefix);  // rcan/ruri.h
    auto ins = run("INSERT INTO robots (" ROBOT_COLUMNS
                   ") VALUES ("
                   "$1, $2, $3, $4, $5, $6, "
                   "'community', $7, $8, $9, $10, $11, $12, $13, $14, $15, $15, false) "
                   "ON CONFLICT DO NOTHING RETURNING " ROBOT_COLUMNS,
                   params(rrn, r.manufacturer, r.model, r.version, r.device_id, uri, r.description,
                          r.contact_email, r.source, r.metadata_json, r.ed25519_pub, r.mldsa65_pub,
                          r.endpoints_json, r.owner_key_id, r.now));
    if (!ins) return ins.error();
    if (ins->size() == 1) return Registered{ins->robot(0), true};
    auto live = one_robot("SELECT " ROBOT_COLUMNS
                          " FROM robots WHERE manufacturer = $1 AND model = $2 AND version = $3 "
                          "AND device_id = $4 AND NOT deleted AND NOT synced",
                          params(r.manufacturer, r.model, r.version, r.device_id));
    if (!live) return live.error();
    if (*live) return Registered{std::move(**live), false};
  }
  return db_error("PostgreSQL register_robot", "no free RRN after 100 attempts");
}

Result<RobotPage> PgStore::list_robots(const RobotQuery& q) {
  Params values;
  std::string where = detail::robot_filter(
      q, "NOT deleted", [](size_t i) { return "$" + std::to_string(i); }, values);
  auto count = run("SELECT count(*) FROM robots WHERE " + where, values);
  if (!count) return count.error();
  RobotPage page;
  page.total = count->integer(0, 0);
  std::string sql = "SELECT " ROBOT_COLUMNS " FROM robots WHERE " + where +
                    " ORDER BY registered_at DESC, seq DESC LIMIT $" +
                    std::to_string(values.size() + 1) + " OFFSET $" +
                    std::to_string(values.size() + 2);
  values.push_back(std::to_string(q.limit));
  values.push_back(std::to_string(q.offset));
  auto rows = run(sql, values);
  if (!rows) return rows.error();
  page.robots = rows->robots();
  return page;
}

}  // namespace

Result<std::unique_ptr<Store>> open_postgres(const std::string& conninfo, const StoreOptions& o) {
  auto store = std::make_unique<PgStore>(conninfo, o);
  if (auto s = store->init(); !s) return s.error();
  return std::unique_ptr<Store>(std::move(store));
}

}  // namespace rcan::registry
