// AuditLog::Impl — the log's parts, their threads and their locks (private to src/audit; the
// contract is include/rcan/audit/audit_log.h, the format docs/AUDIT.md).
//
// The units:
//   audit_log.cpp       the public surface, start (open) and shutdown (the destructor);
//   audit_recovery.cpp  open-time recovery of the chain (sealed segments, the active segment's
//                       torn tail) and recovery after a failed write or sync (try_recover);
//   audit_writer.cpp    appenders, the writer thread and the syncer thread: sealing records in
//                       arrival order, group commit, fdatasync, acknowledgement, failure;
//   audit_segments.cpp  rotation, retention, the indexer thread (a sealed segment's .idx) and
//                       the preallocator thread (the zero-filled spare segment);
//   audit_reader.cpp    queries on a snapshot of what is durable, and offline export.
//
// Threads and what each owns:
//   * the writer ("audit-writer", writer_loop) — or an appender committing in its place
//     (Commit::kHereIfIdle) — owns the writer state below while it holds the commit turn
//     (committing_ set under mu_); recovery and rotation run inside a turn;
//   * the syncer ("audit-sync", syncer_loop; pipelined sync only) takes tickets from tickets_
//     and fdatasyncs file_, which the writer neither closes nor replaces while a ticket is in
//     flight (wait_synced() first);
//   * the indexer ("audit-index") writes one sealed segment's .idx and then publishes its
//     header in sealed_ (under state_mu_); the writer joins it before starting the next;
//   * the preallocator ("audit-prealloc") zero-fills the spare segment and says so through
//     spare_ready_ / prealloc_busy_ (atomics); the writer joins it before using the spare.
// Locks, never nested: mu_ (the queue and the commit turn), sync_mu_ (the syncer's tickets),
// state_mu_ (the durable state readers see).
#pragma once

#include <atomic>
#include <chrono>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "audit/fast_seal.h"
#include "audit/segment.h"
#include "base/thread_annotations.h"
#include "rcan/audit/audit_log.h"

namespace rcan::audit {

inline Error unavailable(std::string msg) {
  return Error(ErrorCode::kAuditUnavailable, std::move(msg));
}

// An index entry for a record written by the log itself (open, rotation, recovery).
internal::IndexEntry make_entry(uint64_t seq, uint64_t offset, uint64_t len, int64_t ts,
                                const std::string& mid, const std::optional<std::string>& wm);

// A segment the log knows about. Sealed segments have either `mem` (index not yet on
// disk) or `header` (index file loaded).
struct Segment {
  uint64_t id = 0;
  uint64_t first_seq = 0;
  uint64_t last_seq = 0;
  int64_t min_ts = 0;
  int64_t max_ts = 0;
  uint64_t bytes = 0;
  std::optional<internal::IndexHeader> header;
  std::shared_ptr<const std::vector<internal::IndexEntry>> mem;
};

// One appended record on its way to the disk.
struct Pending {
  internal::PreparedRecord prep;
  int64_t ts = 0;
  uint64_t mid_hash = 0;
  uint64_t wm_hash = 0;
  bool has_wm = false;
  AuditLog::Callback done;
  Receipt receipt;
};

// Records written by one group commit, waiting for the fdatasync that covers them.
struct Ticket {
  std::vector<Pending> items;
  std::vector<internal::IndexEntry> index;
  uint64_t end_offset = 0;
  uint64_t last_seq = 0;
  std::string last_hash;
};

class AuditLog::Impl {
 public:
  Impl(std::string dir, AuditOptions opts);
  ~Impl();

  Status open();                                                              // audit_log.cpp
  void submit(AuditEntry entry, Callback done, Commit commit) EXCLUDES(mu_);  // audit_writer.cpp
  // audit_reader.cpp
  Status export_range(int64_t from, int64_t to, const LineSink& sink) const;
  Result<std::vector<std::string>> find(bool watermark, std::string_view key) const;
  Result<std::string> get(uint64_t seq) const;
  AuditStats stats() const;
  const std::string& dir() const { return dir_; }
  bool available() const { return !failed_.load(); }

 private:
  class ActiveRecovery;
  class FailureRecovery;

  struct Snapshot {
    std::vector<Segment> sealed;
    uint64_t active_id = 0;
    uint64_t active_durable = 0;
    std::vector<internal::IndexEntry> active;  // entries up to active_durable
  };

  std::string path(const std::string& name) const { return dir_ + "/" + name; }
  std::string seg_path(uint64_t id) const { return path(internal::segment_file_name(id)); }
  std::string idx_path(uint64_t id) const { return path(internal::index_file_name(id)); }
  std::string spare_path() const { return path("prealloc.tmp"); }

  Status start_new_log() EXCLUDES(state_mu_);  // audit_log.cpp

  // Open-time recovery and recovery after a failure (audit_recovery.cpp).
  Status load_segments(const std::vector<uint64_t>& ids, bool clean) EXCLUDES(state_mu_);
  Status load_sealed(uint64_t id, Segment* seg);
  Status rebuild_index(uint64_t id, Segment* seg);
  Status recover_active(uint64_t id, bool clean) EXCLUDES(state_mu_);
  bool try_recover() EXCLUDES(mu_, state_mu_);

  // The writer and the syncer (audit_writer.cpp).
  Status write_records(std::vector<AuditEntry> entries) EXCLUDES(state_mu_);
  json::Object system_object(AuditEntry e);
  void writer_loop() EXCLUDES(mu_);
  // What the writer does next: commit a group (taken into `batch`), probe the disk and recover,
  // look again, or stop. kCommit and kRecover take the commit turn.
  enum class WriterStep { kCommit, kRecover, kAgain, kStop };
  WriterStep next_step_locked(std::vector<Pending>& batch) REQUIRES(mu_);
  void commit(std::vector<Pending>& batch, std::string& buf) EXCLUDES(mu_, sync_mu_);
  std::optional<Ticket> write_group(std::vector<Pending>& batch, std::string& buf) EXCLUDES(mu_);
  void hand_to_sync(Ticket t) EXCLUDES(mu_, sync_mu_);
  void syncer_loop() EXCLUDES(sync_mu_);
  void wait_synced() EXCLUDES(sync_mu_);
  void sync_and_ack(std::vector<Ticket>& tickets) EXCLUDES(mu_, state_mu_);
  void set_failed(const std::string& why) EXCLUDES(mu_);
  Error failure() const EXCLUDES(mu_);
  void fail_all(std::vector<Pending>& items, const Error& err);

  // Segments: rotation, retention, the indexer and the preallocator (audit_segments.cpp).
  Status rotate() EXCLUDES(state_mu_);
  // Moves the active segment's index into sealed_ as segment `id` of `bytes` bytes; readers
  // then see an empty active segment until the next record is durable.
  Segment seal_active_locked(uint64_t id, uint64_t bytes) REQUIRES(state_mu_);
  Status apply_retention() EXCLUDES(state_mu_);
  void start_indexer(uint64_t id, std::shared_ptr<const std::vector<internal::IndexEntry>> entries)
      EXCLUDES(state_mu_);
  void prepare_spare();

  // Queries (audit_reader.cpp).
  Snapshot snapshot() const EXCLUDES(state_mu_);
  Result<std::string> read_line(uint64_t seg_id, const internal::IndexEntry& e) const;
  enum class LineCheck { kOk, kOtherLine, kBadHmac };
  LineCheck check_line(std::string_view line, uint64_t seq, bool verify_hmac) const;
  Result<std::string> exact_line(Result<std::string> line, uint64_t seq) const;
  static Error hmac_refusal(uint64_t seq);
  Result<std::string> sealed_line(uint64_t seg_id, Result<internal::IndexEntry> e, uint64_t seq,
                                  bool verify_hmac) const;
  Result<std::vector<internal::IndexEntry>> entries_of(const Segment& s) const;

  // Fixed once open() returns.
  std::string dir_;
  AuditOptions opts_;
  bool pipelined_ = false;  // a syncer thread runs the fdatasyncs (AuditOptions::pipelined_sync)
  Env* env_ = nullptr;
  int lock_ = -1;
  bool opened_ = false;

  // Writer state: touched only by whoever holds the commit turn (committing_, under mu_), or by
  // open() and the destructor while no other thread runs. The syncer uses file_ (sync only).
  std::unique_ptr<internal::Hasher> hasher_;
  std::unique_ptr<WritableFile> file_;
  uint64_t next_seq_ = 1;
  std::string last_hash_;
  uint64_t active_bytes_ = 0;
  // The active segment has no spare prepared yet; it is made once the segment is half full
  // (not at open or rotation), so a fresh log holds one segment, not two.
  bool spare_wanted_ = false;
  uint64_t failed_next_seq_ = 0;  // next_seq_ when the failure was first seen
  std::atomic<int64_t> last_sync_ms_{0};
  std::atomic<uint64_t> groups_{0};
  std::atomic<uint64_t> syncs_{0};
  std::atomic<uint64_t> recoveries_{0};

  // The queue and the commit turn. failed_ is also read without the lock (available(), the
  // writer's fast path); it is written under mu_ with fail_error_.
  mutable Mutex mu_;
  CondVar cv_;
  std::deque<Pending> queue_ GUARDED_BY(mu_);
  bool stop_ GUARDED_BY(mu_) = false;
  // A group is being committed, by the writer or by an appender (Commit::kHereIfIdle): the
  // writer state above is theirs alone.
  bool committing_ GUARDED_BY(mu_) = false;
  std::atomic<bool> failed_{false};
  Error fail_error_ GUARDED_BY(mu_);
  std::thread writer_;

  // Pipelined sync (background work on): tickets written by the writer, synced by the syncer.
  Mutex sync_mu_;
  CondVar sync_cv_;
  std::vector<Ticket> tickets_ GUARDED_BY(sync_mu_);
  bool sync_busy_ GUARDED_BY(sync_mu_) = false;
  bool sync_stop_ GUARDED_BY(sync_mu_) = false;
  std::thread syncer_;

  // Background segment work, started and joined by the writer.
  std::thread indexer_;
  std::thread preallocer_;
  std::atomic<bool> spare_ready_{false};
  std::atomic<bool> prealloc_busy_{false};

  // Published (durable) state, read by queries.
  mutable Mutex state_mu_;
  std::vector<Segment> sealed_ GUARDED_BY(state_mu_);
  uint64_t active_id_ GUARDED_BY(state_mu_) = 0;
  uint64_t durable_offset_ GUARDED_BY(state_mu_) = 0;
  uint64_t durable_seq_ GUARDED_BY(state_mu_) = 0;
  std::string durable_hash_ GUARDED_BY(state_mu_);
  // Where the chain head (durable_seq_) lives: its segment and the end of its line there.
  // Unlike durable_offset_ these do not move at a rotation until the next record is durable.
  uint64_t head_seg_ GUARDED_BY(state_mu_) = 0;
  uint64_t head_end_ GUARDED_BY(state_mu_) = 0;
  std::vector<internal::IndexEntry> active_index_ GUARDED_BY(state_mu_);
  // Readers at work: retention removes no file while one is (see apply_retention()).
  mutable std::atomic<int> readers_{0};
  mutable std::atomic<uint64_t> index_fallbacks_{0};
};

}  // namespace rcan::audit
