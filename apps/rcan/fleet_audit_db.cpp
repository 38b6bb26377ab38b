#include "fleet_audit_db.h"

#include <libpq-fe.h>

#include <cstdlib>
#include <optional>

#include "rcan/hash.h"

namespace rcan::cli {

const char* const kFleetAuditSchema = R"SQL(
CREATE TABLE IF NOT EXISTS rcan_fleet_audit (
  fleet_id      text        NOT NULL,
  member        text        NOT NULL,
  seq           bigint      NOT NULL,
  line          text        NOT NULL,  -- the canonical record, exactly as the robot chained it
  prev_hash     text,                  -- null for the first record of a chain
  record_hash   text        NOT NULL,  -- SHA-256 (hex) of the canonical record without hmac
  hmac          text        NOT NULL,
  hmac_verified boolean,               -- null: no chain secret was given at ingest
  received_at   timestamptz NOT NULL DEFAULT now(),
  PRIMARY KEY (fleet_id, member, seq)
);
CREATE TABLE IF NOT EXISTS rcan_fleet_audit_problems (
  id        bigserial   PRIMARY KEY,
  fleet_id  text        NOT NULL,
  member    text        NOT NULL,
  seq       bigint,
  problem   text        NOT NULL,
  detail    text        NOT NULL DEFAULT '',
  line      text,                      -- the offending record as received, when not stored
  found_at  timestamptz NOT NULL DEFAULT now()
);
)SQL";

json::Value AuditProblem::to_json() const {
  return json::Value(json::Object{{"fleet_id", fleet_id},
                                  {"member", member},
                                  {"seq", seq},
                                  {"problem", problem},
                                  {"detail", detail}});
}

struct FleetAuditDb::Impl {
  PGconn* conn = nullptr;
  ~Impl() {
    if (conn != nullptr) PQfinish(conn);
  }

  // Runs a parameterised statement; rows as vectors of optional strings (null → nullopt).
  Result<std::vector<std::vector<std::optional<std::string>>>> query(
      const char* sql, const std::vector<std::string>& params) {
    std::vector<const char*> values;
    for (const auto& p : params) values.push_back(p.c_str());
    PGresult* r = PQexecParams(conn, sql, static_cast<int>(values.size()), nullptr, values.data(),
                               nullptr, nullptr, 0);
    ExecStatusType st = PQresultStatus(r);
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) {
      std::string msg = PQresultErrorMessage(r);
      PQclear(r);
      return Error(ErrorCode::kInternal, "PostgreSQL: " + msg);
    }
    std::vector<std::vector<std::optional<std::string>>> rows;
    for (int i = 0; i < PQntuples(r); ++i) {
      std::vector<std::optional<std::string>> row;
      for (int j = 0; j < PQnfields(r); ++j)
        row.push_back(PQgetisnull(r, i, j) ? std::nullopt
                                           : std::optional<std::string>(PQgetvalue(r, i, j)));
      rows.push_back(std::move(row));
    }
    PQclear(r);
    return rows;
  }

  Status record_problem(const AuditProblem& p, const std::string& line) {
    auto r = query(
        "INSERT INTO rcan_fleet_audit_problems (fleet_id, member, seq, problem, detail, line) "
        "VALUES ($1, $2, $3, $4, $5, NULLIF($6, ''))",
        {p.fleet_id, p.member, std::to_string(p.seq), p.problem, p.detail, line});
    if (!r.ok()) return r.error();
    return Status::Ok();
  }
};

FleetAuditDb::~FleetAuditDb() = default;

Result<std::unique_ptr<FleetAuditDb>> FleetAuditDb::open(const std::string& conninfo) {
  std::unique_ptr<FleetAuditDb> db(new FleetAuditDb());
  db->impl_ = std::make_unique<Impl>();
  db->impl_->conn = PQconnectdb(conninfo.c_str());
  if (PQstatus(db->impl_->conn) != CONNECTION_OK)
    return Error(ErrorCode::kInternal,
                 std::string("PostgreSQL connection: ") + PQerrorMessage(db->impl_->conn));
  PGresult* r = PQexec(db->impl_->conn, kFleetAuditSchema);
  bool ok = PQresultStatus(r) == PGRES_COMMAND_OK;
  std::string msg = PQresultErrorMessage(r);
  PQclear(r);
  if (!ok) return Error(ErrorCode::kInternal, "PostgreSQL schema: " + msg);
  return db;
}

namespace {}  // namespace

Result<std::vector<AuditProblem>> FleetAuditDb::ingest(const std::string& fleet_id,
                                                       const std::string& member,
                                                       const json::Value& record,
                                                       const std::string* secret) {
  std::vector<AuditProblem> problems;
  auto problem = [&](int64_t seq, std::string what, std::string detail) {
    problems.push_back(AuditProblem{fleet_id, member, seq, std::move(what), std::move(detail)});
  };
  const json::Value* seqv = record.is_object() ? record.get("seq") : nullptr;
  std::string hmac = json::string_field(record, "hmac");
  const json::Value* prevv = record.is_object() ? record.get("prev_hash") : nullptr;
  if (seqv == nullptr || !seqv->is_int() || seqv->as_int() < 1 || hmac.empty() ||
      prevv == nullptr || !(prevv->is_null() || prevv->is_string())) {
    problem(0, "malformed", "not a sealed audit record (seq, prev_hash, hmac)");
    for (const auto& p : problems) (void)impl_->record_problem(p, json::dump(record));
    return problems;
  }
  const int64_t seq = seqv->as_int();
  const std::string line = json::canonical(record);
  const std::string preimage = json::canonical_without(record.as_object(), "hmac");
  const std::string hash = sha256_hex(preimage);
  const std::string prev = prevv->is_string() ? prevv->as_string() : std::string();
  std::optional<bool> hmac_ok;
  if (secret != nullptr) {
    hmac_ok = hmac_sha256_hex(*secret, preimage) == hmac;
    if (!*hmac_ok) {
      problem(seq, "hmac_mismatch",
              "the record's hmac does not verify with the robot's chain secret (tampered)");
      for (const auto& p : problems)
        if (auto s = impl_->record_problem(p, line); !s.ok()) return s.error();
      return problems;
    }
  }
  auto existing =
      impl_->query("SELECT line FROM rcan_fleet_audit WHERE fleet_id=$1 AND member=$2 AND seq=$3",
                   {fleet_id, member, std::to_string(seq)});
  if (!existing.ok()) return existing.error();
  if (!existing->empty()) {
    if ((*existing)[0][0].value_or("") == line) return problems;  // a redelivery: already stored
    problem(seq, "conflict", "a different record with this seq is already stored");
    for (const auto& p : problems)
      if (auto s = impl_->record_problem(p, line); !s.ok()) return s.error();
    return problems;
  }
  auto before = impl_->query(
      "SELECT seq, record_hash FROM rcan_fleet_audit WHERE fleet_id=$1 AND member=$2 AND seq<$3 "
      "ORDER BY seq DESC LIMIT 1",
      {fleet_id, member, std::to_string(seq)});
  if (!before.ok()) return before.error();
  if (!before->empty()) {
    int64_t prev_seq = std::strtoll((*before)[0][0]->c_str(), nullptr, 10);
    if (prev_seq != seq - 1)
      problem(seq, "gap",
              "records " + std::to_string(prev_seq + 1) + ".." + std::to_string(seq - 1) +
                  " are missing");
    else if ((*before)[0][1].value_or("") != prev)
      problem(seq, "break",
              "prev_hash does not match the record_hash of seq " + std::to_string(prev_seq));
  }
  auto after =
      impl_->query("SELECT line FROM rcan_fleet_audit WHERE fleet_id=$1 AND member=$2 AND seq=$3",
                   {fleet_id, member, std::to_string(seq + 1)});
  if (!after.ok()) return after.error();
  if (!after->empty()) {
    auto next = json::parse((*after)[0][0].value_or(""));
    if (next.ok() && json::string_field(*next, "prev_hash") != hash)
      problem(seq + 1, "break",
              "prev_hash does not match the record_hash of seq " + std::to_string(seq));
  }
  auto ins = impl_->query(
      "INSERT INTO rcan_fleet_audit (fleet_id, member, seq, line, prev_hash, record_hash, hmac, "
      "hmac_verified) "
      "VALUES ($1, $2, $3, $4, NULLIF($5, ''), $6, $7, "
      "CASE $8 WHEN 'true' THEN true WHEN 'false' THEN false ELSE NULL END)",
      {fleet_id, member, std::to_string(seq), line, prev, hash, hmac,
       hmac_ok ? (*hmac_ok ? "true" : "false") : "null"});
  if (!ins.ok()) return ins.error();
  for (const auto& p : problems)
    if (auto s = impl_->record_problem(p, {}); !s.ok()) return s.error();
  return problems;
}

Result<std::vector<AuditProblem>> FleetAuditDb::verify(
    const std::string& fleet_id, const std::map<std::string, std::string>& secrets,
    int64_t* records_checked) {
  auto rows = impl_->query(
      "SELECT fleet_id, member, seq, line, record_hash FROM rcan_fleet_audit "
      "WHERE $1 = '' OR fleet_id = $1 ORDER BY fleet_id, member, seq",
      {fleet_id});
  if (!rows.ok()) return rows.error();
  std::vector<AuditProblem> problems;
  std::string cur_fleet, cur_member, last_hash;
  int64_t last_seq = 0;
  *records_checked = 0;
  for (const auto& row : *rows) {
    const std::string f = row[0].value_or(""), m = row[1].value_or(""), line = row[3].value_or("");
    const int64_t seq = std::strtoll(row[2].value_or("0").c_str(), nullptr, 10);
    auto bad = [&](std::string what, std::string detail) {
      problems.push_back(AuditProblem{f, m, seq, std::move(what), std::move(detail)});
    };
    ++*records_checked;
    bool first = f != cur_fleet || m != cur_member;
    cur_fleet = f;
    cur_member = m;
    auto rec = json::parse(line);
    if (!rec.ok() || !rec->is_object()) {
      bad("malformed", "the stored line is not a JSON object");
      last_hash.clear();
      last_seq = seq;
      continue;
    }
    std::string preimage = json::canonical_without(rec->as_object(), "hmac");
    std::string hash = sha256_hex(preimage);
    if (hash != row[4].value_or(""))
      bad("record_hash_mismatch", "the stored line was altered after ingest");
    const json::Value* s = rec->get("seq");
    if (s == nullptr || !s->is_int() || s->as_int() != seq)
      bad("malformed", "the line's seq differs from the row's");
    if (auto sec = secrets.find(m);
        sec != secrets.end() &&
        hmac_sha256_hex(sec->second, preimage) != json::string_field(*rec, "hmac"))
      bad("hmac_mismatch", "the record's hmac does not verify with the robot's chain secret");
    if (!first) {
      if (seq != last_seq + 1)
        bad("gap", "records " + std::to_string(last_seq + 1) + ".." + std::to_string(seq - 1) +
                       " are missing");
      else if (json::string_field(*rec, "prev_hash") != last_hash)
        bad("break", "prev_hash does not match the record_hash of seq " + std::to_string(last_seq));
    }
    last_hash = hash;
    last_seq = seq;
  }
  return problems;
}

}  // namespace rcan::cli
