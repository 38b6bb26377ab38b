// AuditLog — the node's durable, HMAC-chained audit trail (seed §4.3, §6, §8.5, §16.2).
//
// Storage: a directory of append-only segment files `seg-<8 digits>.log`, one canonical
// JSON record per line, each segment opened by a checkpoint record that carries the
// chain across, plus a sidecar index `seg-<n>.idx` written when a segment is sealed.
// See docs/AUDIT.md for the format, durability policy, recovery and retention.
//
// Contract:
//   * Appends from any number of threads are ordered into one chain by a single writer
//     thread that seals records in arrival order and commits them in groups: one write()
//     and one fdatasync() cover every record that arrived while the previous group was
//     being synced. A record is acknowledged (append() returns, the callback runs) only
//     after the fdatasync that covers it has succeeded.
//   * Append cost is O(1) in the size of the log: the writer keeps the chain head (seq,
//     hash of the last record) in memory and never re-reads the log.
//   * After a crash (kill -9, power loss) open() recovers: it verifies the tail segment,
//     cuts a torn tail (keeping the cut bytes in `<segment>.torn-<offset>`), and appends
//     a `recovery` record saying what it found. Every acknowledged record survives.
//   * A failed write or sync makes the log fail closed: that append and every later one
//     returns ErrorCode::kAuditUnavailable (the node then refuses commands) until the
//     writer's probe (every recovery_interval_ms) finds the disk writable again. Recovery
//     never trusts what was written after the last acknowledged record (after a failed
//     fsync the page cache cannot be trusted): it cuts the segment back to that record and
//     continues the chain in a new segment, opened by a checkpoint and a `recovery` record.
//   * A well-formed record that fails its HMAC or chain link is never auto-repaired:
//     open() refuses with kAuditUnavailable naming the seq (wrong secret or tampering).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/audit/env.h"
#include "rcan/audit/record.h"
#include "rcan/result.h"

namespace rcan::audit {

// Who commits a record appended with append_async().
enum class Commit {
  kWriter,  // the writer thread (default): the caller never waits for the disk
  // The calling thread itself when no record waits and the writer is idle: it seals, writes and
  // syncs the record, and `done` runs on it before append_async() returns — no hand-off to the
  // writer and back. Otherwise as kWriter. For a caller whose thread may block for that
  // commit — one fdatasync, and a rotation when the segment is full (a transport thread
  // serving one connection, recording a stop that has already happened).
  kHereIfIdle,
};

enum class SyncPolicy {
  kPerGroup,  // fdatasync after every group (default): lowest latency under load
  kInterval,  // at most one fdatasync per `sync_interval_ms`; acks wait for it
};

struct AuditOptions {
  // Chain secret (text; the HMAC key is its UTF-8 bytes). Required, ≥ 16 bytes.
  // Load it with load_chain_secret() (secret.h). There is no default.
  std::string secret;
  Env* env = nullptr;  // nullptr → Env::posix()
  SyncPolicy sync_policy = SyncPolicy::kPerGroup;
  int sync_interval_ms = 2;
  uint64_t max_segment_bytes = 64ull << 20;  // rotate when the active segment reaches this
  // Zero-fill each segment file to max_segment_bytes before use (the next one is prepared in
  // the background once the active segment is half full), so that fdatasync after an append flushes
  // data only and needs no file-system journal commit for a size change. See docs/AUDIT.md
  // §Durability.
  bool preallocate = true;
  size_t max_group_records = 4096;    // records per group commit at most
  size_t max_record_bytes = 1 << 20;  // larger entries are rejected
  // Write a sealed segment's .idx and the spare preallocated segment on background
  // threads (false: inline in the writer,
  // which makes the sequence of file operations deterministic for fault-injection tests).
  bool background_index = true;
  // Run each group's fdatasync on a second thread ("audit-sync"), so that the writer seals
  // and writes group N+1 while group N is being synced. It costs two more thread hand-offs
  // per group; on a 2-core board with a fast disk they cost more CPU than the overlap saves
  // (docs/AUDIT.md §3), so it is off by default and the writer syncs each group itself.
  // The interval policy always uses it (the sync thread waits out the interval). Needs
  // background_index.
  bool pipelined_sync = false;
  // Retention (0 = unlimited). Applied after each rotation to sealed segments only.
  uint64_t retention_max_bytes = 0;
  int64_t retention_max_age_ms = 0;
  // After a failed write or sync, how often the writer probes whether the disk takes
  // writes again (and, if so, recovers: docs/AUDIT.md §3). 0 = stay failed until reopened.
  int recovery_interval_ms = 1000;
  // Records waiting for the writer, at most (0 = no bound). Beyond it append_async() and
  // append() refuse at once with AUDIT_UNAVAILABLE, reason `audit_queue_full`: back-pressure
  // on whoever produces records faster than the disk takes them, never unbounded memory.
  size_t max_queued_records = 65'536;
  // Identity written into the log's own (system) records.
  std::string robot_ruri = "rcan://local.rcan/unknown/unknown/unknown";
  std::string system_principal = "system:audit";
};

// What the caller learns once its record is durable.
struct Receipt {
  uint64_t seq = 0;
  int64_t timestamp_ms = 0;
  std::string hmac;
  std::string record_hash;
};

struct AuditStats {
  uint64_t first_seq = 0;  // oldest record still stored
  uint64_t last_seq = 0;   // last durable record
  std::string last_hash;
  uint64_t segments = 0;
  uint64_t active_segment = 0;
  uint64_t total_bytes = 0;
  uint64_t groups_committed = 0;
  uint64_t syncs = 0;
  bool failed = false;
  uint64_t recoveries = 0;  // times the log came back after a failure (this process)
  // Reads whose sealed-segment .idx entry did not lead to the record (a damaged index), sent to
  // the segment itself instead (docs/AUDIT.md §6).
  uint64_t index_fallbacks = 0;
};

class AuditLog {
 public:
  using Callback = std::function<void(Result<Receipt>)>;
  // Receives one stored line (no newline); return false to stop.
  using LineSink = std::function<bool(std::string_view line)>;

  // Opens (creating if needed) the log in `dir`, recovering after a crash. Takes an
  // exclusive lock on `dir/LOCK`: one process writes a log at a time.
  static Result<std::unique_ptr<AuditLog>> open(const std::string& dir, AuditOptions options);

  // Stops the writer after committing everything queued; marks a clean shutdown.
  ~AuditLog();
  AuditLog(const AuditLog&) = delete;
  AuditLog& operator=(const AuditLog&) = delete;

  // Blocks until the record is durable. Errors: kSchemaValidationFailed (bad entry,
  // nothing written), kBodyTooLarge, kAuditUnavailable (disk failed or log closed).
  Result<Receipt> append(AuditEntry entry);
  // Non-blocking: `done` runs on the writer thread once the record is durable (or
  // failed). It must be quick and must not call back into this log's append().
  // Commit::kHereIfIdle: see Commit (then `done` may run on this thread, before this returns;
  // never with pipelined sync).
  void append_async(AuditEntry entry, Callback done, Commit commit = Commit::kWriter);

  // Lines whose timestamp_ms is within [from_ms, to_ms], in seq order, from a snapshot
  // of what was durable when the call started. Safe while appends continue.
  Status export_range(int64_t from_ms, int64_t to_ms, const LineSink& sink) const;
  // The same as one JSONL string (for GET /api/v1/audit?from=&to=&format=jsonl).
  Result<std::string> export_jsonl(int64_t from_ms, int64_t to_ms) const;
  // Every record with this message_id / watermark_token (HiTL events repeat the
  // message_id), in seq order. Uses the sidecar indexes; results are re-verified.
  Result<std::vector<std::string>> find_by_message_id(std::string_view message_id) const;
  Result<std::vector<std::string>> find_by_watermark(std::string_view token) const;
  // The record with this seq (kNotFound when absent or removed by retention).
  Result<std::string> get(uint64_t seq) const;

  AuditStats stats() const;
  // False while the log is failed (appends return kAuditUnavailable). Cheap (one atomic).
  bool available() const;
  const std::string& dir() const;

  class Impl;

 private:
  explicit AuditLog(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Offline reading of a log directory (no lock, no recovery; a torn last line is
// skipped). Used by `rcan audit export`. Lines with timestamp_ms in [from, to].
Status export_dir(const std::string& dir, int64_t from_ms, int64_t to_ms,
                  const AuditLog::LineSink& sink, Env* env = nullptr);

// Segment file names, in order.
Result<std::vector<std::string>> list_segments(const std::string& dir, Env* env = nullptr);

}  // namespace rcan::audit
