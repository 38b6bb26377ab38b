// The fleet audit store in PostgreSQL (docs/FLEET.md §Fleet audit): ingest with chain checks,
// and re-verification from the database. libpq, used by `rcan fleet audit collect --db` and
// `rcan fleet audit verify`.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::cli {

struct AuditProblem {
  std::string fleet_id;
  std::string member;
  int64_t seq = 0;
  std::string problem;  // hmac_mismatch | conflict | gap | break | malformed | record_hash_mismatch
  std::string detail;
  json::Value to_json() const;
};

class FleetAuditDb {
 public:
  // Connects (a libpq connection string, e.g. "host=127.0.0.1 port=5432 dbname=rcan user=rcan")
  // and creates the schema when missing.
  static Result<std::unique_ptr<FleetAuditDb>> open(const std::string& conninfo);
  ~FleetAuditDb();
  FleetAuditDb(const FleetAuditDb&) = delete;
  FleetAuditDb& operator=(const FleetAuditDb&) = delete;

  // Ingests one record of `member`. With `secret` (the robot's chain secret) its HMAC must
  // verify. A record that fails the HMAC or conflicts with a stored one is not stored; a gap or
  // a broken prev_hash link is stored and flagged. Problems are also written to the problems
  // table. Returns the problems found (empty: clean).
  Result<std::vector<AuditProblem>> ingest(const std::string& fleet_id, const std::string& member,
                                           const json::Value& record, const std::string* secret);

  // Re-verifies every stored record (of `fleet_id`, or all fleets when empty): each line's
  // record_hash, the prev_hash links, seq continuity and, for members in `secrets`, the HMACs.
  Result<std::vector<AuditProblem>> verify(const std::string& fleet_id,
                                           const std::map<std::string, std::string>& secrets,
                                           int64_t* records_checked);

  struct Impl;

 private:
  FleetAuditDb() = default;
  std::unique_ptr<Impl> impl_;
};

// The schema (also printed by docs/FLEET.md).
extern const char* const kFleetAuditSchema;

}  // namespace rcan::cli
