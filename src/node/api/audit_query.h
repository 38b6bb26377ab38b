// GET /api/audit, paged and searched on the node (docs/NODE.md §Audit listing): the query's
// parameters and the page it finds. The dashboard's audit view reads it one page at a time.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/audit/audit_log.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct AuditQuery {
  size_t limit = 50;       // 1..1000 records per page
  uint64_t before = 0;     // > 0: only records with seq < before (the next, older page)
  uint64_t after = 0;      // > 0: only records with seq > after, oldest first (auto-refresh)
  int64_t from_ms = 0;     // > 0: timestamp_ms >= from_ms
  int64_t to_ms = 0;       // > 0: timestamp_ms <= to_ms
  std::string event;       // exact event names, comma-separated (COMMAND,ESTOP)
  std::string outcome;     // ok | blocked | error | degraded …
  std::string principal;   // case-insensitive substring of principal or sub
  std::string message_id;  // exact (indexed)
  std::string text;        // case-insensitive substring of the stored line
  // Records examined per request at most; a page that runs out of it is answered incomplete
  // with the cursor to go on from, so that no search holds the node's worker for long.
  size_t scan_budget = 10'000;

  json::Object to_json() const;  // what AUDIT_READ records of the query
};

// A `limit` query parameter: absent is `default_limit`; otherwise digits only, 1..max, else
// SCHEMA_VALIDATION_FAILED "limit: must be 1..max" naming `limit`. Used by GET /api/audit and
// GET /api/node/log.
Result<size_t> parse_limit(std::optional<std::string_view> value, size_t default_limit, size_t max);

// Reads the query from the request's parameters (`param(name)` gives a value or nothing).
// Errors: SCHEMA_VALIDATION_FAILED naming the parameter.
Result<AuditQuery> parse_audit_query(
    const std::function<std::optional<std::string_view>(std::string_view)>& param,
    size_t default_limit);

struct AuditPage {
  json::Array entries;     // ascending seq
  json::Array unreadable;  // seqs in range whose record failed its check (changed on disk)
  std::string first_error;
  uint64_t next_before = 0;  // > 0: older matches may exist; ask again with before=next_before
  uint64_t scanned = 0;      // records examined
  bool complete = true;      // false: the scan budget ran out before the page was full
};

AuditPage run_audit_query(const audit::AuditLog& log, const AuditQuery& q);

}  // namespace rcan::node
