// StopBacklog — the ESTOP and STOP records the audit log could not write while it was failed.
// The stop itself already happened (the safety lane never waits for the log); its record must
// not be lost. A record goes first to a spill file beside the node's state, appended and synced
// (so it survives a restart), and to memory when the spill file cannot be written either. Only
// when both are full is a record lost — and then it is counted, logged and shown in the status,
// never dropped silently. AuditTrail::write hands the backlog to the log, oldest first,
// as soon as the log writes again (marked `recorded_after_audit_outage`).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "rcan/audit/record.h"
#include "rcan/base/env.h"
#include "rcan/json.h"

namespace rcan::node {

struct StopBacklogLimits {
  size_t spill_records = 10'000;  // in the spill file
  size_t memory_records = 1'000;  // when the spill file cannot be written
};

class StopBacklog {
 public:
  using Limits = StopBacklogLimits;
  // `spill_path` "" keeps records in memory only. `env` nullptr → base::Env::posix(). A spill
  // file left by an earlier run is picked up: its records are handed over by the next take().
  explicit StopBacklog(std::string spill_path, base::Env* env = nullptr, Limits limits = {});

  void keep(const audit::AuditEntry& e) EXCLUDES(mu_);
  // Everything kept (spill file first, then memory; each oldest first); the backlog is emptied.
  // Unreadable spill lines (a line torn by a crash) are counted as lost.
  std::vector<audit::AuditEntry> take() EXCLUDES(mu_);
  bool empty() const { return pending_.load(std::memory_order_acquire) == 0; }
  uint64_t pending() const { return pending_.load(std::memory_order_acquire); }
  uint64_t lost() const { return lost_.load(std::memory_order_acquire); }
  // {"pending": n, "spilled": n, "lost": n} for the status.
  json::Value to_json() const EXCLUDES(mu_);

 private:
  bool spill_locked(const audit::AuditEntry& e) REQUIRES(mu_);
  void count_lost(uint64_t n, const char* why);

  const std::string path_;
  base::Env* const env_;
  const Limits limits_;
  mutable Mutex mu_;
  std::unique_ptr<base::WritableFile> file_ GUARDED_BY(mu_);
  size_t spilled_ GUARDED_BY(mu_) = 0;  // records in the spill file
  std::vector<audit::AuditEntry> memory_ GUARDED_BY(mu_);
  std::atomic<uint64_t> pending_{0};
  std::atomic<uint64_t> lost_{0};
};

}  // namespace rcan::node
