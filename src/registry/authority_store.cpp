// The token authority's storage (store.h), one implementation for both backends on
// Store::query(): portable SQL with $n placeholders, values bound as text.
#include <string>

#include "base/strings.h"
#include "registry/store.h"
#include "registry/store_internal.h"

namespace rcan::registry {
namespace {

std::optional<std::string> t(std::string_view s) { return std::string(s); }
std::optional<std::string> n(int64_t v) { return std::to_string(v); }
std::optional<std::string> opt(std::string_view s) {
  if (s.empty()) return std::nullopt;
  return std::string(s);
}
int64_t num(const std::string& s) { return s.empty() ? 0 : std::stoll(s); }

constexpr const char* kGrantColumns =
    "id, principal, rrn, fleet, role, scope, max_ttl_s, created_by, created_at";
constexpr const char* kClientColumns = "id, name, auth, salt, hash, jwk, owner_key_id, created_at";
constexpr const char* kDeviceColumns =
    "device_hash, user_code, client_id, resource, scope, expires_ms, interval_s, last_poll_ms, "
    "status, subject";

Grant grant_of(const std::vector<std::string>& r) {
  Grant g;
  g.id = num(r[0]);
  g.principal = r[1];
  g.rrn = r[2];
  g.fleet = r[3];
  g.role = r[4];
  g.scope = r[5];
  g.max_ttl_s = num(r[6]);
  g.created_by = r[7];
  g.created_at = r[8];
  return g;
}

Client client_of(const std::vector<std::string>& r) {
  return Client{r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7]};
}

DeviceCode device_of(const std::vector<std::string>& r) {
  DeviceCode d;
  d.device_hash = r[0];
  d.user_code = r[1];
  d.client_id = r[2];
  d.resource = r[3];
  d.scope = r[4];
  d.expires_ms = num(r[5]);
  d.interval_s = num(r[6]);
  d.last_poll_ms = num(r[7]);
  d.status = r[8];
  d.subject = r[9];
  return d;
}

Status ok_or(const Result<std::vector<std::vector<std::string>>>& r) {
  if (!r) return r.error();
  return Status::Ok();
}

}  // namespace

Status Store::put_signing_key(const SigningKeyRecord& k) {
  return ok_or(query(
      "INSERT INTO authority_keys (kid, seed, created_ms, sign_from_ms) VALUES ($1, $2, $3, $4)",
      {t(k.kid), t(k.seed), n(k.created_ms), n(k.sign_from_ms)}));
}

Result<std::vector<SigningKeyRecord>> Store::signing_keys() {
  auto rows = query(
      "SELECT kid, seed, created_ms, sign_from_ms FROM authority_keys ORDER BY sign_from_ms, kid",
      {});
  if (!rows) return rows.error();
  std::vector<SigningKeyRecord> out;
  for (const auto& r : *rows) out.push_back({r[0], r[1], num(r[2]), num(r[3])});
  return out;
}

Result<bool> Store::delete_signing_key(std::string_view kid) {
  auto rows = query("DELETE FROM authority_keys WHERE kid = $1 RETURNING kid", {t(kid)});
  if (!rows) return rows.error();
  return !rows->empty();
}

Status Store::put_client(const Client& c) {
  return ok_or(query(std::string("INSERT INTO authority_clients (") + kClientColumns +
                         ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
                     {t(c.id), t(c.name), t(c.auth), t(c.salt), t(c.hash), t(c.jwk),
                      t(c.owner_key_id), t(c.created_at)}));
}

Result<std::optional<Client>> Store::get_client(std::string_view id) {
  auto rows = query(
      std::string("SELECT ") + kClientColumns + " FROM authority_clients WHERE id = $1", {t(id)});
  if (!rows) return rows.error();
  if (rows->empty()) return std::optional<Client>();
  return std::optional<Client>(client_of(rows->front()));
}

Result<std::vector<Client>> Store::list_clients() {
  auto rows = query(
      std::string("SELECT ") + kClientColumns + " FROM authority_clients ORDER BY created_at, id",
      {});
  if (!rows) return rows.error();
  std::vector<Client> out;
  for (const auto& r : *rows) out.push_back(client_of(r));
  return out;
}

Result<bool> Store::delete_client(std::string_view id) {
  auto rows = query("DELETE FROM authority_clients WHERE id = $1 RETURNING id", {t(id)});
  if (!rows) return rows.error();
  return !rows->empty();
}

Result<int64_t> Store::add_grant(const Grant& g) {
  auto rows = query(
      "INSERT INTO authority_grants (principal, rrn, fleet, role, scope, max_ttl_s, created_by, "
      "created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8) RETURNING id",
      {t(g.principal), t(ascii_upper(g.rrn)), t(g.fleet), t(g.role), t(g.scope), n(g.max_ttl_s),
       t(g.created_by), t(g.created_at)});
  if (!rows) return rows.error();
  if (rows->empty()) return detail::db_error("add_grant", "no id");
  return num(rows->front()[0]);
}

Result<std::vector<Grant>> Store::grants_of(std::string_view principal) {
  auto rows = query(std::string("SELECT ") + kGrantColumns +
                        " FROM authority_grants WHERE principal = $1 ORDER BY id",
                    {t(principal)});
  if (!rows) return rows.error();
  std::vector<Grant> out;
  for (const auto& r : *rows) out.push_back(grant_of(r));
  return out;
}

Result<std::optional<Grant>> Store::get_grant(int64_t id) {
  auto rows = query(std::string("SELECT ") + kGrantColumns + " FROM authority_grants WHERE id = $1",
                    {n(id)});
  if (!rows) return rows.error();
  if (rows->empty()) return std::optional<Grant>();
  return std::optional<Grant>(grant_of(rows->front()));
}

Result<std::vector<Grant>> Store::list_grants() {
  auto rows =
      query(std::string("SELECT ") + kGrantColumns + " FROM authority_grants ORDER BY id", {});
  if (!rows) return rows.error();
  std::vector<Grant> out;
  for (const auto& r : *rows) out.push_back(grant_of(r));
  return out;
}

Result<bool> Store::delete_grant(int64_t id) {
  auto rows = query("DELETE FROM authority_grants WHERE id = $1 RETURNING id", {n(id)});
  if (!rows) return rows.error();
  return !rows->empty();
}

Result<int64_t> Store::add_revocation(const Revocation& r) {
  auto rows = query(
      "INSERT INTO authority_revocations (jti, sub, exp, revoked_at, revoked_ms, reason, "
      "revoked_by) VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING seq",
      {opt(r.jti), opt(r.sub), r.exp ? n(*r.exp) : std::nullopt, t(r.revoked_at), n(r.revoked_ms),
       t(r.reason), t(r.revoked_by)});
  if (!rows) return rows.error();
  if (rows->empty()) return detail::db_error("add_revocation", "no seq");
  return num(rows->front()[0]);
}

Result<std::vector<Revocation>> Store::revocations_since(int64_t since, int limit) {
  auto rows = query(
      "SELECT seq, jti, sub, exp, revoked_at, revoked_ms, reason, revoked_by, "
      "CASE WHEN exp IS NULL THEN 0 ELSE 1 END FROM authority_revocations WHERE seq > $1 "
      "ORDER BY seq LIMIT CAST($2 AS INTEGER)",
      {n(since), n(limit)});
  if (!rows) return rows.error();
  std::vector<Revocation> out;
  for (const auto& r : *rows) {
    Revocation v;
    v.seq = num(r[0]);
    v.jti = r[1];
    v.sub = r[2];
    if (r[8] == "1") v.exp = num(r[3]);
    v.revoked_at = r[4];
    v.revoked_ms = num(r[5]);
    v.reason = r[6];
    v.revoked_by = r[7];
    out.push_back(std::move(v));
  }
  return out;
}

Result<bool> Store::is_revoked(std::string_view jti, std::string_view sub, int64_t iat_ms) {
  auto rows = query(
      "SELECT seq FROM authority_revocations WHERE (jti IS NOT NULL AND jti = $1) OR "
      "(jti IS NULL AND sub = $2 AND revoked_ms >= $3) LIMIT 1",
      {t(jti), t(sub), n(iat_ms)});
  if (!rows) return rows.error();
  return !rows->empty();
}

Result<bool> Store::use_jti(std::string_view jti, int64_t exp_ms, int64_t now_ms) {
  auto gone = query("DELETE FROM authority_used_jtis WHERE exp_ms < $1 RETURNING jti", {n(now_ms)});
  if (!gone) return gone.error();
  auto rows = query(
      "INSERT INTO authority_used_jtis (jti, exp_ms) VALUES ($1, $2) ON CONFLICT DO NOTHING "
      "RETURNING jti",
      {t(jti), n(exp_ms)});
  if (!rows) return rows.error();
  return !rows->empty();
}

Status Store::put_device_code(const DeviceCode& d) {
  return ok_or(
      query(std::string("INSERT INTO authority_device_codes (") + kDeviceColumns +
                ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10)",
            {t(d.device_hash), t(d.user_code), t(d.client_id), t(d.resource), t(d.scope),
             n(d.expires_ms), n(d.interval_s), n(d.last_poll_ms), t(d.status), t(d.subject)}));
}

Result<std::optional<DeviceCode>> Store::device_by_hash(std::string_view device_hash) {
  auto rows = query(std::string("SELECT ") + kDeviceColumns +
                        " FROM authority_device_codes WHERE device_hash = $1",
                    {t(device_hash)});
  if (!rows) return rows.error();
  if (rows->empty()) return std::optional<DeviceCode>();
  return std::optional<DeviceCode>(device_of(rows->front()));
}

Result<std::optional<DeviceCode>> Store::device_by_user_code(std::string_view user_code) {
  auto rows = query(
      std::string("SELECT ") + kDeviceColumns + " FROM authority_device_codes WHERE user_code = $1",
      {t(user_code)});
  if (!rows) return rows.error();
  if (rows->empty()) return std::optional<DeviceCode>();
  return std::optional<DeviceCode>(device_of(rows->front()));
}

Result<bool> Store::decide_device(std::string_view user_code, std::string_view status,
                                  std::string_view subject) {
  auto rows = query(
      "UPDATE authority_device_codes SET status = $1, subject = $2 "
      "WHERE user_code = $3 AND status = 'pending' RETURNING device_hash",
      {t(status), t(subject), t(user_code)});
  if (!rows) return rows.error();
  return !rows->empty();
}

Status Store::touch_device(std::string_view device_hash, int64_t poll_ms, int64_t interval_s) {
  return ok_or(query(
      "UPDATE authority_device_codes SET last_poll_ms = $1, interval_s = $2 WHERE device_hash = $3 "
      "RETURNING device_hash",
      {n(poll_ms), n(interval_s), t(device_hash)}));
}

Result<bool> Store::delete_device(std::string_view device_hash) {
  auto rows = query("DELETE FROM authority_device_codes WHERE device_hash = $1 RETURNING user_code",
                    {t(device_hash)});
  if (!rows) return rows.error();
  return !rows->empty();
}

}  // namespace rcan::registry
