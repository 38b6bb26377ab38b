// AuditTrail: how the node writes its audit records. Every service takes one (NodeServices
// holds the node's): it starts a record (AuditRecord, audit_record.h), appends it to the
// AuditLog asynchronously, keeps the ESTOP/STOP records the log could not write (StopBacklog)
// and coalesces refusals without a verified principal into summary records (RefusalLedger).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>

#include "base/clock.h"
#include "base/metrics.h"
#include "node/vocabulary/audit_record.h"
#include "node/vocabulary/refusal_ledger.h"
#include "node/vocabulary/stop_backlog.h"
#include "rcan/audit/audit_log.h"
#include "rcan/errors.h"

namespace rcan::node {

class AuditTrail {
 public:
  // Records name `ruri`; their times come from `clock`; each write is counted in `metrics`.
  // `state_dir` keeps the stop backlog's spill file ("" = memory only).
  AuditTrail(std::string ruri, Clock& clock, audit::AuditLog& log, Metrics& metrics,
             const std::string& state_dir);
  AuditTrail(const AuditTrail&) = delete;
  AuditTrail& operator=(const AuditTrail&) = delete;

  // A new audit record of `event` (audit_record.h): anonymous until `by…` says who.
  AuditRecord record(const std::string& event, const std::string& outcome = "ok");
  // Appends asynchronously; `cb` (optional) runs once the record is durable or failed (with
  // Commit::kHereIfIdle possibly on this thread, before this returns: audit::Commit).
  void write(audit::AuditEntry e, std::function<void(Result<audit::Receipt>)> cb = {},
             audit::Commit commit = audit::Commit::kWriter);

  // Whether a refusal from `source` (an address, or a principal's key) of this kind gets a
  // record of its own now; false: it is counted into a REFUSALS_SUMMARY record instead.
  bool record_refusal(const std::string& source, const std::string& event, ErrorCode code,
                      const std::string& route);
  // Writes the summaries of closed windows (all of them with `all`, at shutdown).
  void flush_refusals(bool all = false);

  // While records wait for a sync (a network partition, seed §6.1 log_for_sync()), the mode's
  // name: each record then carries `partition_mode` and `sync_pending`. Set once, before
  // records are written, by whoever knows the mode (ControlService); empty: never pending.
  void set_sync_mode(std::function<std::string()> mode) { sync_mode_ = std::move(mode); }

  audit::AuditLog& log() { return log_; }

  // ESTOP/STOP records that could not be written while the audit log was failed (the stop
  // itself happened): spilled to `<state_dir>/stops-unrecorded.jsonl` (else memory) and
  // written, marked `recorded_after_audit_outage`, by the first write once the log is back —
  // also after a restart. Never dropped silently (stop_backlog.h).
  StopBacklog stop_backlog;
  // Refusals without a verified principal (and rate-limit refusals), coalesced per source and
  // kind into summary records (refusal_ledger.h).
  RefusalLedger refusals;
  std::atomic<uint64_t> inflight{0};
  std::atomic<uint64_t> failures{0};
  std::atomic<bool> unavailable{false};

 private:
  const std::string ruri_;
  Clock& clock_;
  audit::AuditLog& log_;
  Metrics& metrics_;
  std::function<std::string()> sync_mode_;
};

}  // namespace rcan::node
