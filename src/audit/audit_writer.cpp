// The audit log's write path (include/rcan/audit/audit_log.h: append order, group commit,
// acknowledgement after fdatasync, failing closed).
//
// Appenders (submit) validate and serialise their record on their own thread and queue it
// under mu_; the writer thread ("audit-writer") takes the commit turn, seals the queued records
// in arrival order into one group, writes it with one write() and syncs it — itself, or through
// the syncer thread ("audit-sync") with pipelined sync — and acknowledges each record only after
// the fdatasync that covers it. An appender with Commit::kHereIfIdle commits its own record when
// the queue is empty and the turn free. A failed write or sync fails the log (every later
// append is refused) until the writer's probe recovers it (audit_recovery.cpp).
#include <pthread.h>

#include <algorithm>
#include <chrono>

#include "audit/audit_log_impl.h"
#include "base/clock.h"

namespace rcan::audit {

using internal::IndexEntry;

namespace {

// The steady-clock instant `ms` from now: the deadline of a wait that notifications must not
// extend.
std::chrono::steady_clock::time_point deadline_after(std::chrono::milliseconds ms) {
  return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(steady_ns())) + ms;
}

}  // namespace

// ---------------------------------------------------------------- the log's own records

json::Object AuditLog::Impl::system_object(AuditEntry e) {
  e.principal = opts_.system_principal;
  e.ruri = opts_.robot_ruri;
  e.sender_type = "system";
  if (e.timestamp_ms == 0) e.timestamp_ms = env_->now_ms();
  if (e.message_id.empty()) e.message_id = new_uuid();
  if (e.outcome.empty()) e.outcome = "ok";
  return to_object(e);
}

// Seals, writes and syncs records synchronously (open(), rotation, recovery; commit turn).
Status AuditLog::Impl::write_records(std::vector<AuditEntry> entries) {
  std::string buf;
  std::vector<IndexEntry> idx;
  for (auto& e : entries) {
    AuditEntry copy = e;
    json::Object obj = system_object(std::move(copy));
    int64_t ts = obj.find("timestamp_ms")->as_int();
    std::string mid = obj.find("message_id")->as_string();
    SealedRecord r =
        internal::seal_prepared(internal::prepare(obj), next_seq_, last_hash_, *hasher_);
    idx.push_back(make_entry(r.seq, active_bytes_ + buf.size(), r.line.size(), ts, mid, {}));
    buf += r.line;
    buf += '\n';
    ++next_seq_;
    last_hash_ = r.record_hash;
  }
  Status s = file_->append(buf);
  ++groups_;
  if (s.ok()) s = file_->sync();
  if (!s.ok()) return s;
  active_bytes_ += buf.size();
  ++syncs_;
  MutexLock l(state_mu_);
  active_index_.insert(active_index_.end(), idx.begin(), idx.end());
  durable_offset_ = active_bytes_;
  durable_seq_ = next_seq_ - 1;
  head_seg_ = active_id_;
  head_end_ = active_bytes_;
  durable_hash_ = last_hash_;
  return Status::Ok();
}

// ---------------------------------------------------------------- appenders

void AuditLog::Impl::submit(AuditEntry entry, Callback done, Commit commit_mode) {
  if (entry.timestamp_ms == 0) entry.timestamp_ms = env_->now_ms();
  Status v = validate(entry);
  if (!v.ok()) {
    done(v.error());
    return;
  }
  if (!entry.kind.empty() || entry.segment) {
    done(Error(ErrorCode::kSchemaValidationFailed, "audit entry: kind and segment are reserved",
               "kind"));
    return;
  }
  Pending p;
  p.ts = entry.timestamp_ms;
  p.mid_hash = internal::fnv1a64(entry.message_id);
  if (entry.watermark_token) {
    p.has_wm = true;
    p.wm_hash = internal::fnv1a64(*entry.watermark_token);
  }
  p.prep = internal::prepare(entry);  // serialised here, off the writer thread
  p.done = std::move(done);
  {
    ReleasableMutexLock l(mu_);
    if (stop_ || failed_.load()) {
      Error e = failed_.load() ? fail_error_ : unavailable("audit log is closed");
      l.unlock();
      p.done(e);
      return;
    }
    if (opts_.max_queued_records > 0 && queue_.size() >= opts_.max_queued_records) {
      l.unlock();
      p.done(Error(ErrorCode::kAuditUnavailable,
                   "audit log: " + std::to_string(opts_.max_queued_records) +
                       " records already wait for the disk",
                   "", "audit_queue_full"));
      return;
    }
    if (commit_mode == Commit::kHereIfIdle && !pipelined_ && !committing_ && queue_.empty()) {
      committing_ = true;
      l.unlock();
      std::vector<Pending> batch;
      batch.push_back(std::move(p));
      std::string buf;
      commit(batch, buf);
      l.lock();
      committing_ = false;
      // The writer waits for the end of this commit only when there is work for it.
      const bool wake = !queue_.empty() || stop_ || failed_.load();
      l.unlock();
      if (wake) cv_.notify_all();
      return;
    }
    queue_.push_back(std::move(p));
  }
  cv_.notify_one();
}

// ---------------------------------------------------------------- failure

void AuditLog::Impl::fail_all(std::vector<Pending>& items, const Error& err) {
  for (auto& p : items) p.done(err);
  items.clear();
}

void AuditLog::Impl::set_failed(const std::string& why) {
  MutexLock l(mu_);
  if (!failed_.load()) {
    fail_error_ = unavailable("audit log failed: " + why);
    failed_.store(true);
  }
}

Error AuditLog::Impl::failure() const {
  MutexLock l(mu_);
  return fail_error_;
}

// ---------------------------------------------------------------- the writer thread

// The writer: seals records in arrival order and writes each group with one write().
// With pipelined_sync (or the interval policy), a syncer thread runs the fdatasync of group N while
// the writer seals and writes group N+1 (both only ever append; acks follow the sync).
void AuditLog::Impl::writer_loop() {
  std::vector<Pending> batch;
  std::string buf;
  const bool pipelined = pipelined_;
  for (;;) {
    WriterStep step;
    {
      MutexLock l(mu_);
      step = next_step_locked(batch);
    }
    if (step == WriterStep::kStop) break;
    if (step == WriterStep::kAgain) continue;
    if (step == WriterStep::kRecover) {
      try_recover();
    } else {
      commit(batch, buf);
    }
    MutexLock l(mu_);
    committing_ = false;
  }
  if (pipelined) wait_synced();
}

AuditLog::Impl::WriterStep AuditLog::Impl::next_step_locked(std::vector<Pending>& batch) {
  while (committing_) cv_.wait(mu_);  // an appender's commit (Commit::kHereIfIdle)
  if (failed_.load() && opts_.recovery_interval_ms > 0) {
    // Failed: nothing is queued (submit() refuses); probe the disk once per interval.
    const auto deadline = deadline_after(std::chrono::milliseconds(opts_.recovery_interval_ms));
    while (queue_.empty() && !stop_) {
      if (cv_.wait_until(mu_, deadline) == std::cv_status::timeout) break;
    }
    if (queue_.empty() && !stop_) {
      // Recovery owns the writer's state as a commit does: once it clears failed_, an
      // appender's commit (Commit::kHereIfIdle) waits for it to end.
      committing_ = true;
      return WriterStep::kRecover;
    }
  } else {
    // An appender's commit may fail the log: the writer then probes for recovery.
    const bool probe = opts_.recovery_interval_ms > 0;
    while (committing_ || !(!queue_.empty() || stop_ || (probe && failed_.load()))) cv_.wait(mu_);
    if (queue_.empty() && !stop_) return WriterStep::kAgain;
  }
  const bool stopping = stop_;
  size_t n = std::min(queue_.size(), opts_.max_group_records);
  for (size_t i = 0; i < n; ++i) {
    batch.push_back(std::move(queue_.front()));
    queue_.pop_front();
  }
  if (batch.empty() && stopping) return WriterStep::kStop;
  committing_ = true;
  return WriterStep::kCommit;
}

// Seals `batch` in order, writes it with one write() and syncs it (or hands it to the syncer),
// then rotates if the segment is full. By whoever holds the commit turn.
void AuditLog::Impl::commit(std::vector<Pending>& batch, std::string& buf) {
  if (failed_.load()) {
    fail_all(batch, failure());
    return;
  }
  std::optional<Ticket> t = write_group(batch, buf);
  if (!t) return;
  if (pipelined_) {
    hand_to_sync(std::move(*t));
  } else {
    std::vector<Ticket> one;
    one.push_back(std::move(*t));
    sync_and_ack(one);
  }
  if (spare_wanted_ && active_bytes_ >= opts_.max_segment_bytes / 2) {
    spare_wanted_ = false;
    prepare_spare();
  }
  if (active_bytes_ >= opts_.max_segment_bytes) {
    if (pipelined_) wait_synced();
    if (!failed_.load()) {
      Status r = rotate();
      if (!r.ok()) set_failed("rotation: " + r.error().message);
    }
  }
}

// Seals the batch onto the chain and writes it; the records move into the returned ticket.
// A failed write fails the log and the batch (nullopt).
std::optional<Ticket> AuditLog::Impl::write_group(std::vector<Pending>& batch, std::string& buf) {
  Ticket t;
  buf.clear();
  for (auto& p : batch) {
    SealedRecord r = internal::seal_prepared(p.prep, next_seq_, last_hash_, *hasher_);
    IndexEntry e;
    e.seq = r.seq;
    e.offset = active_bytes_ + buf.size();
    e.len = r.line.size();
    e.ts = p.ts;
    e.mid_hash = p.mid_hash;
    e.wm_hash = p.wm_hash;
    e.has_wm = p.has_wm;
    t.index.push_back(e);
    p.receipt.seq = r.seq;
    p.receipt.timestamp_ms = p.ts;
    p.receipt.hmac = std::move(r.hmac);
    p.receipt.record_hash = r.record_hash;
    buf += r.line;
    buf += '\n';
    ++next_seq_;
    last_hash_ = std::move(r.record_hash);
  }
  Status s = file_->append(buf);
  ++groups_;
  if (!s.ok()) {
    set_failed(s.error().message);
    fail_all(batch, failure());
    return std::nullopt;
  }
  active_bytes_ += buf.size();
  t.items = std::move(batch);
  batch.clear();
  t.end_offset = active_bytes_;
  t.last_seq = next_seq_ - 1;
  t.last_hash = last_hash_;
  return t;
}

// Pipelined sync: nothing to overlap with (no record waiting to be written, the syncer idle):
// sync here and save the hand-off — one thread wake-up less per record on a quiet log. Under
// load the syncer takes the group and the writer goes on with the next one.
void AuditLog::Impl::hand_to_sync(Ticket t) {
  bool here = false;
  if (opts_.sync_policy == SyncPolicy::kPerGroup) {
    MutexLock lq(mu_);
    here = queue_.empty();
  }
  {
    MutexLock l(sync_mu_);
    here = here && tickets_.empty() && !sync_busy_;
    if (here) {
      sync_busy_ = true;  // wait_synced() waits for us as for the syncer
    } else {
      tickets_.push_back(std::move(t));
    }
  }
  if (here) {
    std::vector<Ticket> one;
    one.push_back(std::move(t));
    sync_and_ack(one);
    MutexLock l(sync_mu_);
    sync_busy_ = false;
  } else {
    sync_cv_.notify_one();
  }
}

// ---------------------------------------------------------------- syncing

// Makes tickets durable with one fdatasync, publishes them to readers, acknowledges.
void AuditLog::Impl::sync_and_ack(std::vector<Ticket>& tickets) {
  if (tickets.empty()) return;
  Status s;
  if (!failed_.load()) {
    s = file_->sync();
    last_sync_ms_ = env_->now_ms();
    ++syncs_;
    if (!s.ok()) set_failed(s.error().message);
  }
  if (failed_.load()) {
    const Error err = failure();
    for (auto& t : tickets) fail_all(t.items, err);
    tickets.clear();
    return;
  }
  {
    MutexLock l(state_mu_);
    for (auto& t : tickets)
      active_index_.insert(active_index_.end(), t.index.begin(), t.index.end());
    durable_offset_ = tickets.back().end_offset;
    durable_seq_ = tickets.back().last_seq;
    head_seg_ = active_id_;
    head_end_ = durable_offset_;
    durable_hash_ = tickets.back().last_hash;
  }
  for (auto& t : tickets)
    for (auto& p : t.items) p.done(std::move(p.receipt));
  tickets.clear();
}

void AuditLog::Impl::wait_synced() {
  MutexLock l(sync_mu_);
  while (!tickets_.empty() || sync_busy_) sync_cv_.wait(sync_mu_);
}

// The syncer thread: takes every ticket written so far and syncs them with one fdatasync (with
// the interval policy, after letting more groups join until the interval has passed).
void AuditLog::Impl::syncer_loop() {
  std::vector<Ticket> mine;
  for (;;) {
    {
      MutexLock l(sync_mu_);
      sync_busy_ = false;
      sync_cv_.notify_all();  // wakes wait_synced()
      while (tickets_.empty() && !sync_stop_) sync_cv_.wait(sync_mu_);
      if (tickets_.empty() && sync_stop_) return;
      if (opts_.sync_policy == SyncPolicy::kInterval && !sync_stop_) {
        // Let more groups join until the interval since the last sync has passed.
        auto wait_ms = opts_.sync_interval_ms - (env_->now_ms() - last_sync_ms_);
        if (wait_ms > 0) {
          const auto deadline = deadline_after(std::chrono::milliseconds(wait_ms));
          while (!sync_stop_) {
            if (sync_cv_.wait_until(sync_mu_, deadline) == std::cv_status::timeout) break;
          }
        }
      }
      mine.swap(tickets_);
      sync_busy_ = true;
    }
    sync_and_ack(mine);
  }
}

}  // namespace rcan::audit
