#include "node/vocabulary/audit_trail.h"

#include <optional>
#include <utility>
#include <vector>

#include "rcan/errors.h"

namespace rcan::node {

AuditTrail::AuditTrail(std::string ruri, Clock& clock, audit::AuditLog& log, Metrics& metrics,
                       const std::string& state_dir)
    : stop_backlog(state_dir.empty() ? std::string() : state_dir + "/stops-unrecorded.jsonl"),
      ruri_(std::move(ruri)),
      clock_(clock),
      log_(log),
      metrics_(metrics) {}

AuditRecord AuditTrail::record(const std::string& event, const std::string& outcome) {
  audit::AuditEntry e;
  e.principal = "anonymous";
  e.ruri = ruri_;
  e.timestamp_ms = clock_.wall_ms();
  e.message_id = new_uuid_v4();
  e.event = event;
  e.outcome = outcome;
  return AuditRecord(*this, std::move(e));
}

void AuditRecord::write(std::function<void(Result<audit::Receipt>)> cb) {
  trail_.write(std::move(e_), std::move(cb));
}

void AuditTrail::write(audit::AuditEntry e, std::function<void(Result<audit::Receipt>)> cb,
                       audit::Commit commit) {
  if (sync_mode_) {
    if (std::string mode = sync_mode_(); !mode.empty()) {  // seed §6.1 log_for_sync()
      e.detail.set("partition_mode", mode);
      e.detail.set("sync_pending", true);
    }
  }
  metrics_.count_audit(e.event);
  std::vector<audit::AuditEntry> late;
  if (!stop_backlog.empty() && log_.available()) late = stop_backlog.take();
  for (auto& d : late) {  // stops the log could not record while it was failed: recorded now
    d.detail.set("recorded_after_audit_outage", true);
    write(std::move(d));
  }
  std::optional<audit::AuditEntry> stop_copy;
  if (e.event == "ESTOP" || e.event == "STOP") stop_copy = e;
  inflight.fetch_add(1, std::memory_order_relaxed);
  log_.append_async(
      std::move(e),
      [this, cb = std::move(cb),
       stop_copy = std::move(stop_copy)](Result<audit::Receipt> r) mutable {
        if (!r.ok()) {
          failures.fetch_add(1, std::memory_order_relaxed);
          if (r.error().code == ErrorCode::kAuditUnavailable) {
            unavailable.store(true);
            if (stop_copy) stop_backlog.keep(*stop_copy);
          }
        } else {
          unavailable.store(false);  // the log recovered (AuditLog::available() is the live state)
        }
        // Out of flight only once a failed stop is in the backlog: whoever waits for no write in
        // flight then finds every stop either recorded or kept.
        inflight.fetch_sub(1, std::memory_order_release);
        if (cb) cb(std::move(r));
      },
      commit);
}

bool AuditTrail::record_refusal(const std::string& source, const std::string& event, ErrorCode code,
                                const std::string& route) {
  return refusals.admit(RefusalKey{source, event, std::string(error_name(code)), route},
                        clock_.wall_ms());
}

void AuditTrail::flush_refusals(bool all) {
  for (const RefusalSummary& s : refusals.due(clock_.wall_ms(), all)) {
    record("REFUSALS_SUMMARY", "blocked")
        .by_system()
        .reason(s.key.code)
        .detail("source", s.key.source)
        .detail("event", s.key.event)
        .detail("error_code", s.key.code)
        .detail("route", s.key.route)
        .detail("count", static_cast<int64_t>(s.suppressed))
        .detail("first_ms", s.first_ms)
        .detail("last_ms", s.last_ms)
        .write();
  }
}

}  // namespace rcan::node
