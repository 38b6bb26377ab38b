// The audit log's segment files (docs/AUDIT.md: format, rotation, retention, durability).
//
// Rotation (writer, commit turn): the full active segment is sealed — readers see it as sealed
// at once, with its index in memory — and the chain continues in the next segment, opened by a
// checkpoint. The indexer thread ("audit-index") then writes the sealed segment's .idx and
// publishes its header in sealed_; a crash before that is repaired at open() (rebuild_index).
// The preallocator thread ("audit-prealloc") zero-fills the spare segment once the active one is
// half full, so that a rotation renames a preallocated file instead of growing a new one.
// Retention removes the oldest sealed segments (never the newest: it anchors the active one)
// after saying so in the chain, and never while a reader is at work.
#include <pthread.h>

#include <algorithm>

#include "audit/audit_log_impl.h"

namespace rcan::audit {

using internal::IndexEntry;

Segment AuditLog::Impl::seal_active_locked(uint64_t id, uint64_t bytes) {
  Segment done;
  done.id = id;
  done.bytes = bytes;
  done.first_seq = active_index_.front().seq;
  done.last_seq = active_index_.back().seq;
  done.min_ts = done.max_ts = active_index_.front().ts;
  for (const auto& e : active_index_) {
    done.min_ts = std::min(done.min_ts, e.ts);
    done.max_ts = std::max(done.max_ts, e.ts);
  }
  done.mem = std::make_shared<const std::vector<IndexEntry>>(std::move(active_index_));
  sealed_.push_back(done);
  active_index_.clear();
  durable_offset_ = 0;
  return done;
}

// Writes segment `id`'s .idx (on the indexer thread with background_index, else here), then
// points its entry in sealed_ at the file instead of the in-memory entries. The previous
// indexer is joined first: one runs at a time.
void AuditLog::Impl::start_indexer(uint64_t id,
                                   std::shared_ptr<const std::vector<IndexEntry>> entries) {
  if (indexer_.joinable()) indexer_.join();
  auto work = [this, id, entries] {
    std::string data = internal::build_index(*entries);
    Status s = env_->write_file_synced(idx_path(id) + ".tmp", data);
    if (s.ok()) s = env_->rename_file(idx_path(id) + ".tmp", idx_path(id));
    if (s.ok()) s = env_->sync_dir(dir_);
    if (!s.ok()) return;  // rebuilt from the segment at the next open()
    auto h = internal::read_index_header(env_, idx_path(id));
    if (!h) return;
    MutexLock l(state_mu_);
    for (auto& seg : sealed_) {
      if (seg.id == id) {
        seg.header = h;
        seg.mem.reset();
      }
    }
  };
  if (opts_.background_index) {
    indexer_ = std::thread([work = std::move(work)] {
      pthread_setname_np(pthread_self(), "audit-index");
      work();
    });
  } else {
    work();
  }
}

Status AuditLog::Impl::rotate() {
  Segment done;
  {
    MutexLock l(state_mu_);
    if (active_index_.empty()) return Status::Ok();
    // Readers see the segment as sealed from now on (its bytes are all durable), and an
    // empty active segment until the checkpoint of the next one is.
    done = seal_active_locked(active_id_, active_bytes_);
  }
  Status s = file_->close();
  if (!s.ok()) return s;
  uint64_t new_id = done.id + 1;
  if (preallocer_.joinable() && spare_ready_.load()) preallocer_.join();
  if (spare_ready_.load()) {
    // The spare is zero-filled and synced: renaming it makes a preallocated segment.
    spare_ready_ = false;
    s = env_->rename_file(spare_path(), seg_path(new_id));
    if (!s.ok()) return s;
  }
  auto f = env_->open_writable_at(seg_path(new_id), 0);
  if (!f.ok()) return f.error();
  s = env_->sync_dir(dir_);
  if (!s.ok()) return s;
  file_ = std::move(*f);
  uint64_t prev_last = next_seq_ - 1;
  std::string prev_hash = last_hash_;
  {
    MutexLock l(state_mu_);
    active_id_ = new_id;
  }
  active_bytes_ = 0;
  start_indexer(done.id, done.mem);

  AuditEntry cp;
  cp.kind = "checkpoint";
  cp.event = "AUDIT_CHECKPOINT";
  cp.segment = new_id;
  cp.detail.set("prev_segment", static_cast<int64_t>(done.id));
  cp.detail.set("prev_last_seq", static_cast<int64_t>(prev_last));
  cp.detail.set("prev_last_hash", prev_hash);
  s = write_records({cp});
  if (!s.ok()) return s;
  s = apply_retention();
  if (!s.ok()) return s;
  spare_wanted_ = true;
  return Status::Ok();
}

// Zero-fills the next segment ahead of time, once the active one is half full. If it is not
// ready at the next rotation, that segment is simply not preallocated (slower syncs, same
// correctness).
void AuditLog::Impl::prepare_spare() {
  if (!opts_.preallocate || spare_ready_.load()) return;
  if (preallocer_.joinable()) {
    if (opts_.background_index && prealloc_busy_.load()) return;  // still working on it
    preallocer_.join();  // done (and failed, or the spare would be ready): try again
  }
  prealloc_busy_ = true;
  auto work = [this] {
    if (env_->write_zeros_synced(spare_path(), opts_.max_segment_bytes).ok()) {
      spare_ready_ = true;
    } else {
      (void)env_->remove_file(spare_path());  // a full disk: give the space back
    }
    prealloc_busy_ = false;
  };
  if (opts_.background_index) {
    preallocer_ = std::thread([work] {
      pthread_setname_np(pthread_self(), "audit-prealloc");
      work();
    });
  } else {
    work();
  }
}

Status AuditLog::Impl::apply_retention() {
  if (opts_.retention_max_bytes == 0 && opts_.retention_max_age_ms == 0) return Status::Ok();
  std::vector<Segment> victims;
  {
    // Readers count themselves before taking a snapshot under this lock, so checking the
    // count and dropping the segments in one critical section never pulls a file from
    // under an export.
    MutexLock l(state_mu_);
    if (readers_.load() > 0) return Status::Ok();  // an export is reading; next rotation
    uint64_t total = active_bytes_;
    for (const auto& s : sealed_) total += s.bytes;
    int64_t now = env_->now_ms();
    // Never remove the newest sealed segment: it anchors the active one after a crash.
    for (size_t i = 0; i + 1 < sealed_.size(); ++i) {
      const Segment& s = sealed_[i];
      bool too_big = opts_.retention_max_bytes != 0 && total > opts_.retention_max_bytes;
      bool too_old = opts_.retention_max_age_ms != 0 && s.max_ts < now - opts_.retention_max_age_ms;
      if (!too_big && !too_old) break;
      victims.push_back(s);
      total -= s.bytes;
    }
    sealed_.erase(sealed_.begin(), sealed_.begin() + static_cast<long>(victims.size()));
  }
  if (victims.empty()) return Status::Ok();
  // The chain says what goes before the files go (a crash in between leaves the files,
  // which the next open() and retention pass handle).
  AuditEntry rec;
  rec.kind = "retention";
  rec.event = "AUDIT_RETENTION";
  json::Array removed;
  for (const auto& v : victims) removed.emplace_back(static_cast<int64_t>(v.id));
  rec.detail.set("removed_segments", json::Value(std::move(removed)));
  rec.detail.set("removed_through_seq", static_cast<int64_t>(victims.back().last_seq));
  rec.detail.set("first_kept_seq", static_cast<int64_t>(victims.back().last_seq + 1));
  if (opts_.retention_max_bytes)
    rec.detail.set("max_bytes", static_cast<int64_t>(opts_.retention_max_bytes));
  if (opts_.retention_max_age_ms) rec.detail.set("max_age_ms", opts_.retention_max_age_ms);
  Status s = write_records({rec});
  if (!s.ok()) return s;
  if (indexer_.joinable()) indexer_.join();
  for (const auto& v : victims) {
    s = env_->remove_file(seg_path(v.id));
    if (!s.ok()) return s;
    if (env_->exists(idx_path(v.id))) {
      s = env_->remove_file(idx_path(v.id));
      if (!s.ok()) return s;
    }
  }
  return env_->sync_dir(dir_);
}

}  // namespace rcan::audit
