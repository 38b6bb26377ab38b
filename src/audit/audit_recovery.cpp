// Recovery of the audit chain (include/rcan/audit/audit_log.h, docs/AUDIT.md §3).
//
// At open(), before any thread runs: every sealed segment must continue the chain (its index
// is rebuilt from the segment when missing or damaged); the active segment is verified record
// by record from the previous segment's last record (ActiveRecovery). A well-formed record that
// fails its link or HMAC is corruption and refuses the open; anything after the last good
// record is a torn write: its bytes are kept in `<segment>.torn-<offset>` and cut, and a
// `recovery` record says what was found.
//
// After a failed write or sync, on the writer's probe (FailureRecovery): the chain continues
// from the last acknowledged record in a fresh segment; nothing written after that record is
// trusted. Both run inside the commit turn (writer state is theirs).
#include <algorithm>
#include <cstring>

#include "audit/audit_log_impl.h"

namespace rcan::audit {

using internal::IndexEntry;

namespace {

// One past the last non-zero byte of `s` (0 when it is all zeros), eight bytes at a time: the
// preallocated tail of the active segment is zeros, scanned on every start.
size_t end_of_data(std::string_view s) {
  size_t n = s.size();
  while (n % 8 != 0) {
    if (s[n - 1] != '\0') return n;
    --n;
  }
  while (n >= 8) {
    uint64_t w;
    std::memcpy(&w, s.data() + n - 8, 8);
    if (w != 0) break;
    n -= 8;
  }
  while (n > 0 && s[n - 1] == '\0') --n;
  return n;
}

}  // namespace

// ---------------------------------------------------------------- sealed segments

Status AuditLog::Impl::load_segments(const std::vector<uint64_t>& ids, bool clean) {
  for (size_t i = 0; i + 1 < ids.size(); ++i) {
    Segment seg;
    Status s = load_sealed(ids[i], &seg);
    if (!s.ok()) return s;
    MutexLock l(state_mu_);
    if (!sealed_.empty() && seg.first_seq != sealed_.back().last_seq + 1)
      return unavailable("audit log: segment " + internal::segment_file_name(seg.id) +
                         " does not continue the chain (wrong segment link at seq " +
                         std::to_string(seg.first_seq) + ")");
    sealed_.push_back(std::move(seg));
  }
  return recover_active(ids.back(), clean);
}

Status AuditLog::Impl::load_sealed(uint64_t id, Segment* seg) {
  seg->id = id;
  auto size = env_->file_size(seg_path(id));
  if (!size.ok()) return size.error();
  seg->bytes = *size;
  auto h = internal::read_index_header(env_, idx_path(id));
  if (!h) return rebuild_index(id, seg);
  seg->header = h;
  seg->first_seq = h->first_seq;
  seg->last_seq = h->last_seq;
  seg->min_ts = h->min_ts;
  seg->max_ts = h->max_ts;
  return Status::Ok();
}

// Rebuilds a sealed segment's index by reading it (after a crash between rotation and
// the index write, or when the index file is damaged). The segment's chain is verified
// on the way: a sealed segment was fully synced, so any defect is corruption.
Status AuditLog::Impl::rebuild_index(uint64_t id, Segment* seg) {
  std::vector<IndexEntry> entries;
  Error err;
  bool bad = false;
  Status s = internal::for_each_line(
      env_, seg_path(id), UINT64_MAX,
      [&](uint64_t off, std::string_view line) {
        auto v = json::parse(line, internal::record_parse_options());
        auto k = v.ok() ? internal::record_keys(*v) : std::nullopt;
        if (!k || (!entries.empty() && k->seq != entries.back().seq + 1)) {
          bad = true;
          err = unavailable("audit log: sealed segment " + internal::segment_file_name(id) +
                            " is damaged at offset " + std::to_string(off));
          return false;
        }
        entries.push_back(make_entry(k->seq, off, line.size(), k->ts, k->message_id, k->watermark));
        return true;
      },
      [&](uint64_t off, std::string_view) {
        bad = true;
        err = unavailable("audit log: sealed segment " + internal::segment_file_name(id) +
                          " ends with a torn line at offset " + std::to_string(off));
      });
  if (!s.ok()) return s;
  if (bad) return err;
  if (entries.empty())
    return unavailable("audit log: sealed segment " + internal::segment_file_name(id) +
                       " is empty");
  std::string data = internal::build_index(entries);
  s = env_->write_file_synced(idx_path(id) + ".tmp", data);
  if (s.ok()) s = env_->rename_file(idx_path(id) + ".tmp", idx_path(id));
  if (s.ok()) s = env_->sync_dir(dir_);
  if (!s.ok()) return s;
  auto h = internal::read_index_header(env_, idx_path(id));
  if (!h) return unavailable("audit log: cannot read back index " + idx_path(id));
  seg->header = h;
  seg->first_seq = h->first_seq;
  seg->last_seq = h->last_seq;
  seg->min_ts = h->min_ts;
  seg->max_ts = h->max_ts;
  return Status::Ok();
}

// ---------------------------------------------------------------- the active segment at open

// Recovers the active (last) segment at open(): reads the chain head the newest sealed segment
// ends with, verifies the active segment's records against it, cuts a torn tail, publishes the
// chain head and writes the checkpoint and `recovery` records the segment needs. One use.
class AuditLog::Impl::ActiveRecovery {
 public:
  ActiveRecovery(Impl& log, uint64_t id, bool clean)
      : log_(log), id_(id), clean_(clean), path_(log.seg_path(id)) {}

  Status run() EXCLUDES(log_.state_mu_) {
    {
      MutexLock l(log_.state_mu_);
      log_.active_id_ = id_;
      if (!log_.sealed_.empty()) prev_ = log_.sealed_.back();
    }
    Status s = read_previous_head();
    if (!s.ok()) return s;
    expected_ = prev_seq_ + 1;
    link_ = prev_hash_;
    s = scan();
    if (s.ok()) s = cut_torn_tail();
    if (s.ok()) s = publish();
    if (!s.ok()) return s;
    auto records = recovery_records();
    if (!records.ok()) return records.error();
    if (!records->empty()) return log_.write_records(std::move(*records));
    return Status::Ok();
  }

 private:
  // The chain head before this segment: the last record of the previous segment (verified).
  Status read_previous_head() {
    if (!prev_) return Status::Ok();
    const std::string name = internal::segment_file_name(prev_->id);
    uint64_t size = prev_->bytes;
    uint64_t from = size > (8u << 20) ? size - (8u << 20) : 0;
    auto tail =
        log_.env_->read_range(log_.seg_path(prev_->id), from, static_cast<size_t>(size - from));
    if (!tail.ok()) return tail.error();
    std::string_view t(*tail);
    while (!t.empty() && t.back() == '\0') t.remove_suffix(1);  // preallocated space
    if (t.empty() || t.back() != '\n')
      return unavailable("audit log: sealed segment " + name +
                         " does not end with a complete record");
    t.remove_suffix(1);
    size_t nl = t.rfind('\n');
    std::string_view last = nl == std::string_view::npos ? t : t.substr(nl + 1);
    auto v = json::parse(last, internal::record_parse_options());
    if (!v.ok() || !v->is_object())
      return unavailable("audit log: last record of " + name + " is malformed");
    auto chk = check_record(v->as_object(), log_.opts_.secret);
    auto k = internal::record_keys(*v);
    if (!k) return unavailable("audit log: last record of previous segment has no seq");
    if (!chk.hmac_ok)
      return unavailable("audit log: hmac mismatch at seq " + std::to_string(k->seq) +
                         " (wrong chain secret or tampering); refusing to open");
    prev_seq_ = k->seq;
    prev_hash_ = chk.record_hash;
    return Status::Ok();
  }

  // Reads the segment's records up to the first that is not well formed (a torn write).
  Status scan() {
    Status s = internal::for_each_line(
        log_.env_, path_, UINT64_MAX,
        [this](uint64_t off, std::string_view line) { return accept(off, line); },
        [this](uint64_t off, std::string_view) {
          if (torn_reason_.empty())
            torn_reason_ = "incomplete last record at offset " + std::to_string(off);
        });
    if (!s.ok()) return s;
    if (corrupt_) return *corrupt_;
    return Status::Ok();
  }

  // One line: false stops the scan (a torn line, or corruption in corrupt_).
  bool accept(uint64_t off, std::string_view line) {
    if (line.find('\0') != std::string_view::npos) {
      torn_reason_ = "NUL bytes in record at offset " + std::to_string(off);
      return false;
    }
    auto v = json::parse(line, internal::record_parse_options());
    if (!v.ok() || !v->is_object()) {
      torn_reason_ = "unparseable record at offset " + std::to_string(off);
      return false;
    }
    auto k = internal::record_keys(*v);
    if (!k) {
      torn_reason_ = "record without seq at offset " + std::to_string(off);
      return false;
    }
    // From here on the line is well formed: a defect is corruption, not a torn write.
    if (good_count_ == 0) {
      const json::Value* seg = v->get("segment");
      if (k->kind != "checkpoint" || !seg || !seg->is_int() ||
          seg->as_int() != static_cast<int64_t>(id_))
        return refuse(k->seq, "wrong segment link (segment does not open with its checkpoint)");
      if (prev_seq_ == 0 && id_ != 1) {
        // Earlier segments removed by retention: the checkpoint anchors the chain.
        expected_ = k->seq;
        const json::Value* ph = v->get("prev_hash");
        link_ = ph && ph->is_string() ? ph->as_string() : std::string();
      }
    }
    if (k->seq != expected_)
      return refuse(k->seq, "seq gap (expected " + std::to_string(expected_) + ")");
    const json::Value* ph = v->get("prev_hash");
    bool link_ok =
        link_.empty() ? (ph && ph->is_null()) : (ph && ph->is_string() && ph->as_string() == link_);
    if (!link_ok) return refuse(k->seq, "prev_hash mismatch");
    auto chk = check_record(v->as_object(), log_.opts_.secret);
    if (!chk.hmac_ok) return refuse(k->seq, "hmac mismatch");
    entries_.push_back(make_entry(k->seq, off, line.size(), k->ts, k->message_id, k->watermark));
    link_ = chk.record_hash;
    expected_ = k->seq + 1;
    good_end_ = off + line.size() + 1;
    ++good_count_;
    return true;
  }

  bool refuse(uint64_t seq, const std::string& why) {
    corrupt_ = unavailable("audit log: " + why + " at seq " + std::to_string(seq) + " in " +
                           internal::segment_file_name(id_) +
                           " (wrong chain secret or tampering); refusing to open — run "
                           "`rcan audit verify --data-dir`");
    return false;
  }

  // Whatever follows the last good record is either preallocated zeros (nothing to do)
  // or a torn tail: keep its bytes in a quarantine file, then cut it.
  Status cut_torn_tail() {
    auto size = log_.env_->file_size(path_);
    if (!size.ok()) return size.error();
    uint64_t data_end = good_end_;  // one past the last non-zero byte
    for (uint64_t pos = good_end_; pos < *size;) {
      // Small chunks: a 64 MiB preallocated segment is scanned on every start, and 4 MiB
      // buffers stayed in the heap (glibc's raised mmap/trim thresholds) for the node's life.
      size_t n = static_cast<size_t>(std::min<uint64_t>(256u << 10, *size - pos));
      auto chunk = log_.env_->read_range(path_, pos, n);
      if (!chunk.ok()) return chunk.error();
      if (chunk->empty()) break;
      if (size_t e = end_of_data(*chunk); e > 0) data_end = pos + e;
      pos += chunk->size();
    }
    cut_ = data_end - good_end_;
    if (cut_ > 0) {
      auto tail = log_.env_->read_range(path_, good_end_, static_cast<size_t>(cut_));
      if (!tail.ok()) return tail.error();
      quarantine_ = internal::segment_file_name(id_) + ".torn-" + std::to_string(good_end_);
      Status s = log_.env_->write_file_synced(log_.path(quarantine_), *tail);
      if (s.ok()) s = log_.env_->truncate_file(path_, good_end_);
      if (s.ok()) s = log_.env_->sync_dir(log_.dir_);
      if (!s.ok()) return s;
    }
    if (torn_reason_.empty()) torn_reason_ = "garbage after the last record";
    return Status::Ok();
  }

  // The chain head after the last good record: the writer's state, what readers see, and the
  // segment opened for appending there.
  Status publish() EXCLUDES(log_.state_mu_) {
    log_.next_seq_ = expected_;
    log_.last_hash_ = link_;
    log_.active_bytes_ = good_end_;
    {
      MutexLock l(log_.state_mu_);
      log_.active_index_ = std::move(entries_);
      log_.durable_offset_ = good_end_;
      log_.durable_seq_ = expected_ - 1;
      log_.head_seg_ = id_;
      log_.head_end_ = good_end_;
      log_.durable_hash_ = link_;
    }
    auto f = log_.env_->open_writable_at(path_, good_end_);
    if (!f.ok()) return f.error();
    log_.file_ = std::move(*f);
    return Status::Ok();
  }

  // The segment's opening checkpoint when it lost (or never got) it, and a `recovery` record
  // after a torn tail or an unclean shutdown.
  Result<std::vector<AuditEntry>> recovery_records() const {
    std::vector<AuditEntry> records;
    if (good_count_ == 0) {
      if (id_ != 1 && prev_seq_ == 0)
        return unavailable("audit log: active segment " + internal::segment_file_name(id_) +
                           " is empty and no earlier segment anchors the chain");
      AuditEntry cp;
      cp.kind = "checkpoint";
      cp.event = "AUDIT_CHECKPOINT";
      cp.segment = id_;
      if (id_ == 1) {
        cp.detail.set("genesis", true);
      } else {
        cp.detail.set("prev_segment", static_cast<int64_t>(prev_->id));
        cp.detail.set("prev_last_seq", static_cast<int64_t>(prev_seq_));
        cp.detail.set("prev_last_hash", prev_hash_);
      }
      records.push_back(std::move(cp));
    }
    if (cut_ > 0 || !clean_) {
      AuditEntry rec;
      rec.kind = "recovery";
      rec.event = "AUDIT_RECOVERY";
      rec.outcome = cut_ > 0 ? "repaired" : "ok";
      rec.reason =
          cut_ > 0 ? "torn tail cut after unclean shutdown" : "unclean shutdown; log intact";
      rec.detail.set("unclean_shutdown", !clean_);
      rec.detail.set("segment", static_cast<int64_t>(id_));
      rec.detail.set("last_good_seq", static_cast<int64_t>(expected_ - 1));
      rec.detail.set("bytes_cut", static_cast<int64_t>(cut_));
      if (cut_ > 0) {
        rec.detail.set("cut_at_offset", static_cast<int64_t>(good_end_));
        rec.detail.set("torn_reason", torn_reason_);
        rec.detail.set("quarantine_file", quarantine_);
      }
      records.push_back(std::move(rec));
    }
    return records;
  }

  Impl& log_;
  const uint64_t id_;
  const bool clean_;
  const std::string path_;
  std::optional<Segment> prev_;  // the newest sealed segment, if any
  uint64_t prev_seq_ = 0;        // its last record
  std::string prev_hash_;
  uint64_t expected_ = 0;  // the seq the next good record must have
  std::string link_;       // the prev_hash it must carry
  uint64_t good_end_ = 0;  // one past the last good record's newline
  uint64_t good_count_ = 0;
  std::string torn_reason_;
  std::optional<Error> corrupt_;
  std::vector<IndexEntry> entries_;
  uint64_t cut_ = 0;  // bytes cut after good_end_
  std::string quarantine_;
};

Status AuditLog::Impl::recover_active(uint64_t id, bool clean) {
  return ActiveRecovery(*this, id, clean).run();
}

// ---------------------------------------------------------------- after a failure

// After a failed write or sync (disk full, I/O error, read-only file system): once the disk
// takes writes again, continue the chain from the last ACKNOWLEDGED record in a fresh
// segment. Nothing written after that record is trusted (after a failed fsync the page
// cache may hold bytes that never reached the disk, "fsyncgate"): the failed segment is cut
// back to the end of that record and synced, segments a failed rotation began are removed,
// and the new segment opens with a checkpoint followed by a `recovery` record saying what
// happened. Every step is retried from scratch at the next probe if any fails.
class AuditLog::Impl::FailureRecovery {
 public:
  explicit FailureRecovery(Impl& log) : log_(log) {}

  // Whether the log is writable again.
  bool run() EXCLUDES(log_.mu_, log_.state_mu_) {
    if (log_.pipelined_) log_.wait_synced();  // no sync in flight on file_
    {
      MutexLock l(log_.state_mu_);
      head_seg_ = log_.head_seg_;
      head_end_ = log_.head_end_;
      head_seq_ = log_.durable_seq_;
      head_hash_ = log_.durable_hash_;
    }
    if (head_seg_ == 0) return false;
    if (log_.failed_next_seq_ == 0) log_.failed_next_seq_ = log_.next_seq_;
    if (log_.file_) {
      (void)log_.file_->close();
      log_.file_.reset();
    }
    if (!cut_back() || !seal_head() || !open_fresh_segment() || !append_records()) return false;
    {
      MutexLock l(log_.mu_);
      log_.failed_.store(false);
      log_.fail_error_ = Error();
    }
    log_.failed_next_seq_ = 0;
    ++log_.recoveries_;
    log_.prepare_spare();
    return true;
  }

 private:
  // 1. Cut the head segment back to the last acknowledged record (this also frees its
  //    preallocated tail, which a sealed segment does not need).
  // 2. Segments after it hold no acknowledged record: a rotation that failed half-way.
  bool cut_back() {
    Env* env = log_.env_;
    if (!env->truncate_file(log_.seg_path(head_seg_), head_end_).ok()) return false;
    auto ids = internal::segment_ids(env, log_.dir_);
    if (!ids.ok()) return false;
    for (uint64_t id : *ids) {
      if (id <= head_seg_) continue;
      if (env->exists(log_.idx_path(id)) && !env->remove_file(log_.idx_path(id)).ok()) return false;
      if (!env->remove_file(log_.seg_path(id)).ok()) return false;
    }
    return true;
  }

  // 3. The head segment is sealed as it now is.
  bool seal_head() EXCLUDES(log_.state_mu_) {
    std::shared_ptr<const std::vector<IndexEntry>> to_index;
    {
      MutexLock l(log_.state_mu_);
      if (log_.sealed_.empty() || log_.sealed_.back().id != head_seg_) {
        if (log_.active_index_.empty()) return false;  // cannot happen: the head lives here
        to_index = log_.seal_active_locked(head_seg_, head_end_).mem;
      } else {
        log_.sealed_.back().bytes = head_end_;
      }
    }
    if (to_index) log_.start_indexer(head_seg_, to_index);
    return true;
  }

  // 4. A fresh segment, preallocated when there is room for it (otherwise it grows).
  bool open_fresh_segment() EXCLUDES(log_.state_mu_) {
    Env* env = log_.env_;
    const uint64_t new_id = head_seg_ + 1;
    bool have_file = false;
    if (log_.opts_.preallocate) {
      if (log_.preallocer_.joinable() && !log_.prealloc_busy_.load()) log_.preallocer_.join();
      if (log_.spare_ready_.load() && !log_.preallocer_.joinable()) {
        log_.spare_ready_ = false;
        have_file = env->rename_file(log_.spare_path(), log_.seg_path(new_id)).ok();
      }
      if (!have_file) {
        have_file =
            env->write_zeros_synced(log_.seg_path(new_id), log_.opts_.max_segment_bytes).ok();
        if (!have_file) (void)env->remove_file(log_.seg_path(new_id));
      }
    }
    auto f = env->open_writable_at(log_.seg_path(new_id), 0);
    if (!f.ok()) return false;
    if (!env->sync_dir(log_.dir_).ok()) return false;
    log_.file_ = std::move(*f);
    {
      MutexLock l(log_.state_mu_);
      log_.active_id_ = new_id;
      log_.active_index_.clear();
      log_.durable_offset_ = 0;
    }
    log_.active_bytes_ = 0;
    log_.next_seq_ = head_seq_ + 1;
    log_.last_hash_ = head_hash_;
    return true;
  }

  // The new segment's checkpoint and the `recovery` record.
  bool append_records() EXCLUDES(log_.mu_) {
    const std::string why = log_.failure().message;
    AuditEntry cp;
    cp.kind = "checkpoint";
    cp.event = "AUDIT_CHECKPOINT";
    cp.segment = head_seg_ + 1;
    cp.detail.set("prev_segment", static_cast<int64_t>(head_seg_));
    cp.detail.set("prev_last_seq", static_cast<int64_t>(head_seq_));
    cp.detail.set("prev_last_hash", head_hash_);
    AuditEntry rec;
    rec.kind = "recovery";
    rec.event = "AUDIT_RECOVERY";
    rec.outcome = "repaired";
    rec.reason = "the audit store takes writes again after a failure";
    rec.detail.set("failure", why);
    rec.detail.set("last_good_seq", static_cast<int64_t>(head_seq_));
    // Sealed but never acknowledged (their appenders were told the log failed): not in the
    // chain.
    const uint64_t failed_next = log_.failed_next_seq_;
    rec.detail.set(
        "unacknowledged_discarded",
        static_cast<int64_t>(failed_next > head_seq_ + 1 ? failed_next - head_seq_ - 1 : 0));
    rec.detail.set("cut_segment", static_cast<int64_t>(head_seg_));
    rec.detail.set("cut_at_offset", static_cast<int64_t>(head_end_));
    return log_.write_records({cp, rec}).ok();
  }

  Impl& log_;
  // The chain head: the last acknowledged record, its segment and the end of its line.
  uint64_t head_seg_ = 0;
  uint64_t head_end_ = 0;
  uint64_t head_seq_ = 0;
  std::string head_hash_;
};

bool AuditLog::Impl::try_recover() { return FailureRecovery(*this).run(); }

}  // namespace rcan::audit
