#include "rcan/audit/audit_log.h"

#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>

#include "audit/fast_seal.h"
#include "audit/segment.h"
#include "rcan/audit/secret.h"
#include "rcan/hash.h"

namespace rcan::audit {

using internal::IndexEntry;
using internal::IndexHeader;

namespace {

Error unavailable(std::string msg) { return Error(ErrorCode::kAuditUnavailable, std::move(msg)); }

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

// A segment the log knows about. Sealed segments have either `mem` (index not yet on
// disk) or `header` (index file loaded).
struct Segment {
  uint64_t id = 0;
  uint64_t first_seq = 0;
  uint64_t last_seq = 0;
  int64_t min_ts = 0;
  int64_t max_ts = 0;
  uint64_t bytes = 0;
  std::optional<IndexHeader> header;
  std::shared_ptr<const std::vector<IndexEntry>> mem;
};

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
  std::vector<IndexEntry> index;
  uint64_t end_offset = 0;
  uint64_t last_seq = 0;
  std::string last_hash;
};

IndexEntry make_entry(uint64_t seq, uint64_t offset, uint64_t len, int64_t ts,
                      const std::string& mid, const std::optional<std::string>& wm) {
  IndexEntry e;
  e.seq = seq;
  e.offset = offset;
  e.len = len;
  e.ts = ts;
  e.mid_hash = internal::fnv1a64(mid);
  if (wm) {
    e.has_wm = true;
    e.wm_hash = internal::fnv1a64(*wm);
  }
  return e;
}

}  // namespace

class AuditLog::Impl {
 public:
  Impl(std::string dir, AuditOptions opts) : dir_(std::move(dir)), opts_(std::move(opts)) {
    env_ = opts_.env ? opts_.env : Env::posix();
    pipelined_ = opts_.background_index &&
                 (opts_.pipelined_sync || opts_.sync_policy == SyncPolicy::kInterval);
  }

  ~Impl() {
    if (writer_.joinable()) {
      {
        std::lock_guard<std::mutex> l(mu_);
        stop_ = true;
      }
      cv_.notify_all();
      writer_.join();
    }
    if (syncer_.joinable()) {
      {
        std::lock_guard<std::mutex> l(sync_mu_);
        sync_stop_ = true;
      }
      sync_cv_.notify_all();
      syncer_.join();
    }
    if (indexer_.joinable()) indexer_.join();
    if (preallocer_.joinable()) preallocer_.join();
    if (file_) {
      (void)file_->close();
      if (!failed_.load() && opened_) {
        // Clean shutdown marker: the next open() skips the unclean-shutdown record.
        if (env_->write_file_synced(path("CLEAN"), std::to_string(next_seq_ - 1)).ok())
          (void)env_->sync_dir(dir_);
      }
    }
    if (lock_ >= 0) env_->unlock_file(lock_);
    secure_wipe(opts_.secret.data(), opts_.secret.size());
  }

  std::string path(const std::string& name) const { return dir_ + "/" + name; }
  std::string seg_path(uint64_t id) const { return path(internal::segment_file_name(id)); }
  std::string idx_path(uint64_t id) const { return path(internal::index_file_name(id)); }

  Status open();
  void submit(AuditEntry entry, Callback done, Commit commit);
  Status export_range(int64_t from, int64_t to, const LineSink& sink) const;
  Result<std::vector<std::string>> find(bool watermark, std::string_view key) const;
  Result<std::string> get(uint64_t seq) const;
  AuditStats stats() const;
  const std::string& dir() const { return dir_; }
  bool available() const { return !failed_.load(); }

 private:
  struct Snapshot {
    std::vector<Segment> sealed;
    uint64_t active_id = 0;
    uint64_t active_durable = 0;
    std::vector<IndexEntry> active;  // entries up to active_durable
  };

  Status load_sealed(uint64_t id, Segment* seg);
  Status rebuild_index(uint64_t id, Segment* seg);
  Status recover_active(uint64_t id, bool clean);
  Status write_records(std::vector<AuditEntry> entries);
  json::Object system_object(AuditEntry e);
  Status rotate();
  Status apply_retention();
  void writer_loop();
  void commit(std::vector<Pending>& batch, std::string& buf);
  void syncer_loop();
  void wait_synced();
  void sync_and_ack(std::vector<Ticket>& tickets);
  void set_failed(const std::string& why);
  bool try_recover();
  void fail_all(std::vector<Pending>& items, const Error& err);
  Snapshot snapshot() const;
  Result<std::string> read_line(uint64_t seg_id, const IndexEntry& e) const;
  enum class LineCheck { kOk, kOtherLine, kBadHmac };
  LineCheck check_line(std::string_view line, uint64_t seq, bool verify_hmac) const;
  Result<std::string> exact_line(Result<std::string> line, uint64_t seq) const;
  static Error hmac_refusal(uint64_t seq);
  Result<std::string> sealed_line(uint64_t seg_id, Result<IndexEntry> e, uint64_t seq,
                                  bool verify_hmac) const;
  Result<std::vector<IndexEntry>> entries_of(const Segment& s) const;
  void start_indexer(uint64_t id, std::shared_ptr<const std::vector<IndexEntry>> entries);
  void prepare_spare();
  std::string spare_path() const { return path("prealloc.tmp"); }

  std::string dir_;
  AuditOptions opts_;
  bool pipelined_ = false;  // a syncer thread runs the fdatasyncs (AuditOptions::pipelined_sync)
  Env* env_ = nullptr;
  int lock_ = -1;
  bool opened_ = false;

  // Writer state (writer thread only, or open() before the thread starts).
  std::unique_ptr<internal::Hasher> hasher_;
  std::unique_ptr<WritableFile> file_;
  uint64_t next_seq_ = 1;
  std::string last_hash_;
  uint64_t active_bytes_ = 0;
  std::atomic<int64_t> last_sync_ms_{0};
  std::atomic<uint64_t> groups_{0};
  std::atomic<uint64_t> syncs_{0};

  // Queue.
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Pending> queue_;
  bool stop_ = false;
  // A group is being committed, by the writer or by an appender (Commit::kHereIfIdle): the
  // writer-side state (file_, next_seq_, last_hash_, active_bytes_, rotation) is theirs alone.
  bool committing_ = false;
  std::atomic<bool> failed_{false};
  Error fail_error_;
  std::thread writer_;
  // Pipelined sync (background work on): tickets written by the writer, synced here.
  std::mutex sync_mu_;
  std::condition_variable sync_cv_;
  std::vector<Ticket> tickets_;
  bool sync_busy_ = false;
  bool sync_stop_ = false;
  std::thread syncer_;
  std::thread indexer_;
  std::thread preallocer_;
  std::atomic<bool> spare_ready_{false};
  std::atomic<bool> prealloc_busy_{false};
  // Writer: the active segment has no spare prepared yet; it is made once the segment is half
  // full (not at open or rotation), so a fresh log holds one segment, not two.
  bool spare_wanted_ = false;
  std::atomic<uint64_t> recoveries_{0};
  mutable std::atomic<uint64_t> index_fallbacks_{0};
  uint64_t failed_next_seq_ = 0;  // writer: next_seq_ when the failure was first seen

  // Published (durable) state, read by queries. Guarded by state_mu_.
  mutable std::mutex state_mu_;
  std::vector<Segment> sealed_;
  uint64_t active_id_ = 0;
  uint64_t durable_offset_ = 0;
  uint64_t durable_seq_ = 0;
  std::string durable_hash_;
  // Where the chain head (durable_seq_) lives: its segment and the end of its line there.
  // Unlike durable_offset_ these do not move at a rotation until the next record is durable.
  uint64_t head_seg_ = 0;
  uint64_t head_end_ = 0;
  std::vector<IndexEntry> active_index_;
  mutable std::atomic<int> readers_{0};
};

// ---------------------------------------------------------------- open / recovery

Status AuditLog::Impl::open() {
  if (opts_.secret.size() < kMinSecretBytes)
    return unavailable("audit chain secret missing or shorter than 16 bytes");
  hasher_ = std::make_unique<internal::Hasher>(opts_.secret);
  Status s = env_->create_dir(dir_);
  if (!s.ok()) return s;
  auto lock = env_->lock_file(path("LOCK"));
  if (!lock.ok()) return lock.error();
  lock_ = *lock;

  bool clean = false;
  if (env_->exists(path("CLEAN"))) {
    clean = true;
    s = env_->remove_file(path("CLEAN"));
    if (!s.ok()) return s;
    s = env_->sync_dir(dir_);
    if (!s.ok()) return s;
  }

  if (env_->exists(spare_path())) {  // a spare from an earlier run: rebuild it
    s = env_->remove_file(spare_path());
    if (!s.ok()) return s;
  }
  auto ids = internal::segment_ids(env_, dir_);
  if (!ids.ok()) return ids.error();
  if (ids->empty()) {
    active_id_ = 1;
    if (opts_.preallocate) {
      s = env_->write_zeros_synced(seg_path(1), opts_.max_segment_bytes);
      if (!s.ok()) return s;
    }
    auto f = env_->open_writable_at(seg_path(1), 0);
    if (!f.ok()) return f.error();
    file_ = std::move(*f);
    s = env_->sync_dir(dir_);
    if (!s.ok()) return s;
    AuditEntry genesis;
    genesis.kind = "checkpoint";
    genesis.event = "AUDIT_CHECKPOINT";
    genesis.segment = 1;
    genesis.detail.set("genesis", true);
    s = write_records({genesis});
    if (!s.ok()) return s;
  } else {
    for (size_t i = 0; i + 1 < ids->size(); ++i) {
      Segment seg;
      s = load_sealed((*ids)[i], &seg);
      if (!s.ok()) return s;
      if (!sealed_.empty() && seg.first_seq != sealed_.back().last_seq + 1)
        return unavailable("audit log: segment " + internal::segment_file_name(seg.id) +
                           " does not continue the chain (wrong segment link at seq " +
                           std::to_string(seg.first_seq) + ")");
      sealed_.push_back(std::move(seg));
    }
    s = recover_active(ids->back(), clean);
    if (!s.ok()) return s;
  }
  opened_ = true;
  spare_wanted_ = true;
  if (pipelined_)
    syncer_ = std::thread([this] {
      pthread_setname_np(pthread_self(), "audit-sync");
      syncer_loop();
    });
  writer_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "audit-writer");
    writer_loop();
  });
  return Status::Ok();
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

Status AuditLog::Impl::recover_active(uint64_t id, bool clean) {
  const std::string p = seg_path(id);
  active_id_ = id;

  // The chain head before this segment: the last record of the previous segment.
  uint64_t prev_seq = 0;
  std::string prev_hash;
  if (!sealed_.empty()) {
    const Segment& prev = sealed_.back();
    uint64_t size = prev.bytes;
    uint64_t from = size > (8u << 20) ? size - (8u << 20) : 0;
    auto tail = env_->read_range(seg_path(prev.id), from, static_cast<size_t>(size - from));
    if (!tail.ok()) return tail.error();
    std::string_view t(*tail);
    while (!t.empty() && t.back() == '\0') t.remove_suffix(1);  // preallocated space
    if (t.empty() || t.back() != '\n')
      return unavailable("audit log: sealed segment " + internal::segment_file_name(prev.id) +
                         " does not end with a complete record");
    t.remove_suffix(1);
    size_t nl = t.rfind('\n');
    std::string_view last = nl == std::string_view::npos ? t : t.substr(nl + 1);
    auto v = json::parse(last, internal::record_parse_options());
    if (!v.ok() || !v->is_object())
      return unavailable("audit log: last record of " + internal::segment_file_name(prev.id) +
                         " is malformed");
    auto chk = check_record(v->as_object(), opts_.secret);
    auto k = internal::record_keys(*v);
    if (!k) return unavailable("audit log: last record of previous segment has no seq");
    if (!chk.hmac_ok)
      return unavailable("audit log: hmac mismatch at seq " + std::to_string(k->seq) +
                         " (wrong chain secret or tampering); refusing to open");
    prev_seq = k->seq;
    prev_hash = chk.record_hash;
  }

  uint64_t expected = prev_seq + 1;
  std::string link = prev_hash;
  uint64_t good_end = 0;
  uint64_t good_count = 0;
  std::string torn_reason;
  Error corrupt;
  bool is_corrupt = false;
  std::vector<IndexEntry> entries;

  Status s = internal::for_each_line(
      env_, p, UINT64_MAX,
      [&](uint64_t off, std::string_view line) {
        if (line.find('\0') != std::string_view::npos) {
          torn_reason = "NUL bytes in record at offset " + std::to_string(off);
          return false;
        }
        auto v = json::parse(line, internal::record_parse_options());
        if (!v.ok() || !v->is_object()) {
          torn_reason = "unparseable record at offset " + std::to_string(off);
          return false;
        }
        auto k = internal::record_keys(*v);
        if (!k) {
          torn_reason = "record without seq at offset " + std::to_string(off);
          return false;
        }
        // From here on the line is well formed: a defect is corruption, not a torn write.
        auto fail = [&](const std::string& why) {
          is_corrupt = true;
          corrupt = unavailable("audit log: " + why + " at seq " + std::to_string(k->seq) + " in " +
                                internal::segment_file_name(id) +
                                " (wrong chain secret or tampering); refusing to open — run "
                                "`rcan audit verify --data-dir`");
          return false;
        };
        if (good_count == 0) {
          const json::Value* seg = v->get("segment");
          if (k->kind != "checkpoint" || !seg || !seg->is_int() ||
              seg->as_int() != static_cast<int64_t>(id))
            return fail("wrong segment link (segment does not open with its checkpoint)");
          if (prev_seq == 0 && id != 1) {
            // Earlier segments removed by retention: the checkpoint anchors the chain.
            expected = k->seq;
            const json::Value* ph = v->get("prev_hash");
            link = ph && ph->is_string() ? ph->as_string() : std::string();
          }
        }
        if (k->seq != expected) return fail("seq gap (expected " + std::to_string(expected) + ")");
        const json::Value* ph = v->get("prev_hash");
        bool link_ok = link.empty() ? (ph && ph->is_null())
                                    : (ph && ph->is_string() && ph->as_string() == link);
        if (!link_ok) return fail("prev_hash mismatch");
        auto chk = check_record(v->as_object(), opts_.secret);
        if (!chk.hmac_ok) return fail("hmac mismatch");
        entries.push_back(make_entry(k->seq, off, line.size(), k->ts, k->message_id, k->watermark));
        link = chk.record_hash;
        expected = k->seq + 1;
        good_end = off + line.size() + 1;
        ++good_count;
        return true;
      },
      [&](uint64_t off, std::string_view) {
        if (torn_reason.empty())
          torn_reason = "incomplete last record at offset " + std::to_string(off);
      });
  if (!s.ok()) return s;
  if (is_corrupt) return corrupt;

  // Whatever follows the last good record is either preallocated zeros (nothing to do)
  // or a torn tail: keep its bytes in a quarantine file, then cut it.
  auto size = env_->file_size(p);
  if (!size.ok()) return size.error();
  uint64_t data_end = good_end;  // one past the last non-zero byte
  for (uint64_t pos = good_end; pos < *size;) {
    // Small chunks: a 64 MiB preallocated segment is scanned on every start, and 4 MiB
    // buffers stayed in the heap (glibc's raised mmap/trim thresholds) for the node's life.
    size_t n = static_cast<size_t>(std::min<uint64_t>(256u << 10, *size - pos));
    auto chunk = env_->read_range(p, pos, n);
    if (!chunk.ok()) return chunk.error();
    if (chunk->empty()) break;
    if (size_t e = end_of_data(*chunk); e > 0) data_end = pos + e;
    pos += chunk->size();
  }
  uint64_t cut = data_end - good_end;
  std::string quarantine;
  if (cut > 0) {
    auto tail = env_->read_range(p, good_end, static_cast<size_t>(cut));
    if (!tail.ok()) return tail.error();
    quarantine = internal::segment_file_name(id) + ".torn-" + std::to_string(good_end);
    s = env_->write_file_synced(path(quarantine), *tail);
    if (s.ok()) s = env_->truncate_file(p, good_end);
    if (s.ok()) s = env_->sync_dir(dir_);
    if (!s.ok()) return s;
  }
  if (torn_reason.empty()) torn_reason = "garbage after the last record";

  next_seq_ = expected;
  last_hash_ = link;
  active_bytes_ = good_end;
  {
    std::lock_guard<std::mutex> l(state_mu_);
    active_index_ = std::move(entries);
    durable_offset_ = good_end;
    durable_seq_ = expected - 1;
    head_seg_ = id;
    head_end_ = good_end;
    durable_hash_ = link;
  }
  auto f = env_->open_writable_at(p, good_end);
  if (!f.ok()) return f.error();
  file_ = std::move(*f);

  std::vector<AuditEntry> records;
  if (good_count == 0) {
    // The segment lost (or never got) its opening checkpoint.
    if (id != 1 && prev_seq == 0)
      return unavailable("audit log: active segment " + internal::segment_file_name(id) +
                         " is empty and no earlier segment anchors the chain");
    AuditEntry cp;
    cp.kind = "checkpoint";
    cp.event = "AUDIT_CHECKPOINT";
    cp.segment = id;
    if (id == 1) {
      cp.detail.set("genesis", true);
    } else {
      cp.detail.set("prev_segment", static_cast<int64_t>(sealed_.back().id));
      cp.detail.set("prev_last_seq", static_cast<int64_t>(prev_seq));
      cp.detail.set("prev_last_hash", prev_hash);
    }
    records.push_back(std::move(cp));
  }
  if (cut > 0 || !clean) {
    AuditEntry rec;
    rec.kind = "recovery";
    rec.event = "AUDIT_RECOVERY";
    rec.outcome = cut > 0 ? "repaired" : "ok";
    rec.reason = cut > 0 ? "torn tail cut after unclean shutdown" : "unclean shutdown; log intact";
    rec.detail.set("unclean_shutdown", !clean);
    rec.detail.set("segment", static_cast<int64_t>(id));
    rec.detail.set("last_good_seq", static_cast<int64_t>(next_seq_ - 1));
    rec.detail.set("bytes_cut", static_cast<int64_t>(cut));
    if (cut > 0) {
      rec.detail.set("cut_at_offset", static_cast<int64_t>(good_end));
      rec.detail.set("torn_reason", torn_reason);
      rec.detail.set("quarantine_file", quarantine);
    }
    records.push_back(std::move(rec));
  }
  if (!records.empty()) return write_records(std::move(records));
  return Status::Ok();
}

// ---------------------------------------------------------------- writing

json::Object AuditLog::Impl::system_object(AuditEntry e) {
  e.principal = opts_.system_principal;
  e.ruri = opts_.robot_ruri;
  e.sender_type = "system";
  if (e.timestamp_ms == 0) e.timestamp_ms = env_->now_ms();
  if (e.message_id.empty()) e.message_id = new_uuid();
  if (e.outcome.empty()) e.outcome = "ok";
  return to_object(e);
}

// Seals, writes and syncs records synchronously (open(), rotation; writer context).
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
  std::lock_guard<std::mutex> l(state_mu_);
  active_index_.insert(active_index_.end(), idx.begin(), idx.end());
  durable_offset_ = active_bytes_;
  durable_seq_ = next_seq_ - 1;
  head_seg_ = active_id_;
  head_end_ = active_bytes_;
  durable_hash_ = last_hash_;
  return Status::Ok();
}

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
    std::unique_lock<std::mutex> l(mu_);
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

void AuditLog::Impl::fail_all(std::vector<Pending>& items, const Error& err) {
  for (auto& p : items) p.done(err);
  items.clear();
}

void AuditLog::Impl::set_failed(const std::string& why) {
  std::lock_guard<std::mutex> l(mu_);
  if (!failed_.load()) {
    fail_error_ = unavailable("audit log failed: " + why);
    failed_.store(true);
  }
}

// After a failed write or sync (disk full, I/O error, read-only file system): once the disk
// takes writes again, continue the chain from the last ACKNOWLEDGED record in a fresh
// segment. Nothing written after that record is trusted (after a failed fsync the page
// cache may hold bytes that never reached the disk, "fsyncgate"): the failed segment is cut
// back to the end of that record and synced, segments a failed rotation began are removed,
// and the new segment opens with a checkpoint followed by a `recovery` record saying what
// happened. Every step is retried from scratch at the next probe if any fails.
// Writer thread only. Returns whether the log is writable again.
bool AuditLog::Impl::try_recover() {
  if (pipelined_) wait_synced();  // no sync in flight on file_
  uint64_t head_seg = 0, head_end = 0, head_seq = 0;
  std::string head_hash;
  {
    std::lock_guard<std::mutex> l(state_mu_);
    head_seg = head_seg_;
    head_end = head_end_;
    head_seq = durable_seq_;
    head_hash = durable_hash_;
  }
  if (head_seg == 0) return false;
  if (failed_next_seq_ == 0) failed_next_seq_ = next_seq_;
  if (file_) {
    (void)file_->close();
    file_.reset();
  }
  // 1. Cut the head segment back to the last acknowledged record (this also frees its
  //    preallocated tail, which a sealed segment does not need).
  Status s = env_->truncate_file(seg_path(head_seg), head_end);
  if (!s.ok()) return false;
  // 2. Segments after it hold no acknowledged record: a rotation that failed half-way.
  auto ids = internal::segment_ids(env_, dir_);
  if (!ids.ok()) return false;
  for (uint64_t id : *ids) {
    if (id <= head_seg) continue;
    if (env_->exists(idx_path(id)) && !env_->remove_file(idx_path(id)).ok()) return false;
    if (!env_->remove_file(seg_path(id)).ok()) return false;
  }
  // 3. The head segment is sealed as it now is.
  std::shared_ptr<const std::vector<IndexEntry>> to_index;
  {
    std::lock_guard<std::mutex> l(state_mu_);
    if (sealed_.empty() || sealed_.back().id != head_seg) {
      if (active_index_.empty()) return false;  // cannot happen: the head lives here
      Segment done;
      done.id = head_seg;
      done.bytes = head_end;
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
      to_index = done.mem;
    } else {
      sealed_.back().bytes = head_end;
    }
  }
  if (to_index) start_indexer(head_seg, to_index);
  // 4. A fresh segment, preallocated when there is room for it (otherwise it grows).
  const uint64_t new_id = head_seg + 1;
  bool have_file = false;
  if (opts_.preallocate) {
    if (preallocer_.joinable() && !prealloc_busy_.load()) preallocer_.join();
    if (spare_ready_.load() && !preallocer_.joinable()) {
      spare_ready_ = false;
      have_file = env_->rename_file(spare_path(), seg_path(new_id)).ok();
    }
    if (!have_file) {
      have_file = env_->write_zeros_synced(seg_path(new_id), opts_.max_segment_bytes).ok();
      if (!have_file) (void)env_->remove_file(seg_path(new_id));
    }
  }
  auto f = env_->open_writable_at(seg_path(new_id), 0);
  if (!f.ok()) return false;
  if (!env_->sync_dir(dir_).ok()) return false;
  file_ = std::move(*f);
  {
    std::lock_guard<std::mutex> l(state_mu_);
    active_id_ = new_id;
    active_index_.clear();
    durable_offset_ = 0;
  }
  active_bytes_ = 0;
  next_seq_ = head_seq + 1;
  last_hash_ = head_hash;
  std::string why;
  {
    std::lock_guard<std::mutex> l(mu_);
    why = fail_error_.message;
  }
  AuditEntry cp;
  cp.kind = "checkpoint";
  cp.event = "AUDIT_CHECKPOINT";
  cp.segment = new_id;
  cp.detail.set("prev_segment", static_cast<int64_t>(head_seg));
  cp.detail.set("prev_last_seq", static_cast<int64_t>(head_seq));
  cp.detail.set("prev_last_hash", head_hash);
  AuditEntry rec;
  rec.kind = "recovery";
  rec.event = "AUDIT_RECOVERY";
  rec.outcome = "repaired";
  rec.reason = "the audit store takes writes again after a failure";
  rec.detail.set("failure", why);
  rec.detail.set("last_good_seq", static_cast<int64_t>(head_seq));
  // Sealed but never acknowledged (their appenders were told the log failed): not in the chain.
  rec.detail.set(
      "unacknowledged_discarded",
      static_cast<int64_t>(failed_next_seq_ > head_seq + 1 ? failed_next_seq_ - head_seq - 1 : 0));
  rec.detail.set("cut_segment", static_cast<int64_t>(head_seg));
  rec.detail.set("cut_at_offset", static_cast<int64_t>(head_end));
  if (!write_records({cp, rec}).ok()) return false;
  {
    std::lock_guard<std::mutex> l(mu_);
    failed_.store(false);
    fail_error_ = Error();
  }
  failed_next_seq_ = 0;
  ++recoveries_;
  prepare_spare();
  return true;
}

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
    for (auto& t : tickets) fail_all(t.items, fail_error_);
    tickets.clear();
    return;
  }
  {
    std::lock_guard<std::mutex> l(state_mu_);
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

// The writer: seals records in arrival order and writes each group with one write().
// With pipelined_sync (or the interval policy), a syncer thread runs the fdatasync of group N while
// the writer seals and writes group N+1 (both only ever append; acks follow the sync).
void AuditLog::Impl::writer_loop() {
  std::vector<Pending> batch;
  std::string buf;
  const bool pipelined = pipelined_;
  for (;;) {
    bool stopping = false;
    {
      std::unique_lock<std::mutex> l(mu_);
      cv_.wait(l, [&] { return !committing_; });  // an appender's commit (Commit::kHereIfIdle)
      if (failed_.load() && opts_.recovery_interval_ms > 0) {
        // Failed: nothing is queued (submit() refuses); probe the disk once per interval.
        bool woken = cv_.wait_for(l, std::chrono::milliseconds(opts_.recovery_interval_ms),
                                  [&] { return !queue_.empty() || stop_; });
        if (!woken) {
          // Recovery owns the writer's state as a commit does: once it clears failed_, an
          // appender's commit (Commit::kHereIfIdle) waits for it to end.
          committing_ = true;
          l.unlock();
          try_recover();
          l.lock();
          committing_ = false;
          continue;
        }
      } else {
        // An appender's commit may fail the log: the writer then probes for recovery.
        const bool probe = opts_.recovery_interval_ms > 0;
        cv_.wait(l, [&] {
          return !committing_ && (!queue_.empty() || stop_ || (probe && failed_.load()));
        });
        if (queue_.empty() && !stop_) continue;
      }
      stopping = stop_;
      size_t n = std::min(queue_.size(), opts_.max_group_records);
      for (size_t i = 0; i < n; ++i) {
        batch.push_back(std::move(queue_.front()));
        queue_.pop_front();
      }
      if (batch.empty() && stopping) break;
      committing_ = true;
    }
    commit(batch, buf);
    std::lock_guard<std::mutex> l(mu_);
    committing_ = false;
  }
  if (pipelined) wait_synced();
}

// Seals `batch` in order, writes it with one write() and syncs it (or hands it to the syncer),
// then rotates if the segment is full. By whoever holds committing_.
void AuditLog::Impl::commit(std::vector<Pending>& batch, std::string& buf) {
  const bool pipelined = pipelined_;
  {
    if (failed_.load()) {
      fail_all(batch, fail_error_);
      return;
    }
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
      fail_all(batch, fail_error_);
      return;
    }
    active_bytes_ += buf.size();
    t.items = std::move(batch);
    batch.clear();
    t.end_offset = active_bytes_;
    t.last_seq = next_seq_ - 1;
    t.last_hash = last_hash_;
    if (pipelined) {
      // Nothing to overlap with (no record waiting to be written, the syncer idle): sync
      // here and save the hand-off — one thread wake-up less per record on a quiet log.
      // Under load the syncer takes the group and the writer goes on with the next one.
      bool here = false;
      if (opts_.sync_policy == SyncPolicy::kPerGroup) {
        std::lock_guard<std::mutex> lq(mu_);
        here = queue_.empty();
      }
      {
        std::lock_guard<std::mutex> l(sync_mu_);
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
        std::lock_guard<std::mutex> l(sync_mu_);
        sync_busy_ = false;
      } else {
        sync_cv_.notify_one();
      }
    } else {
      std::vector<Ticket> one;
      one.push_back(std::move(t));
      sync_and_ack(one);
    }
    if (spare_wanted_ && active_bytes_ >= opts_.max_segment_bytes / 2) {
      spare_wanted_ = false;
      prepare_spare();
    }
    if (active_bytes_ >= opts_.max_segment_bytes) {
      if (pipelined) wait_synced();
      if (!failed_.load()) {
        Status r = rotate();
        if (!r.ok()) set_failed("rotation: " + r.error().message);
      }
    }
  }
}

void AuditLog::Impl::wait_synced() {
  std::unique_lock<std::mutex> l(sync_mu_);
  sync_cv_.wait(l, [&] { return tickets_.empty() && !sync_busy_; });
}

void AuditLog::Impl::syncer_loop() {
  std::vector<Ticket> mine;
  for (;;) {
    {
      std::unique_lock<std::mutex> l(sync_mu_);
      sync_busy_ = false;
      sync_cv_.notify_all();  // wakes wait_synced()
      sync_cv_.wait(l, [&] { return !tickets_.empty() || sync_stop_; });
      if (tickets_.empty() && sync_stop_) return;
      if (opts_.sync_policy == SyncPolicy::kInterval && !sync_stop_) {
        // Let more groups join until the interval since the last sync has passed.
        auto wait_ms = opts_.sync_interval_ms - (env_->now_ms() - last_sync_ms_);
        if (wait_ms > 0)
          sync_cv_.wait_for(l, std::chrono::milliseconds(wait_ms), [&] { return sync_stop_; });
      }
      mine.swap(tickets_);
      sync_busy_ = true;
    }
    sync_and_ack(mine);
  }
}

// ---------------------------------------------------------------- rotation / retention

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
    std::lock_guard<std::mutex> l(state_mu_);
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
  std::shared_ptr<const std::vector<IndexEntry>> entries;
  {
    std::lock_guard<std::mutex> l(state_mu_);
    done.id = active_id_;
    done.bytes = active_bytes_;
    if (active_index_.empty()) return Status::Ok();
    done.first_seq = active_index_.front().seq;
    done.last_seq = active_index_.back().seq;
    done.min_ts = done.max_ts = active_index_.front().ts;
    for (const auto& e : active_index_) {
      done.min_ts = std::min(done.min_ts, e.ts);
      done.max_ts = std::max(done.max_ts, e.ts);
    }
    entries = std::make_shared<const std::vector<IndexEntry>>(std::move(active_index_));
    done.mem = entries;
    // Readers see the segment as sealed from now on (its bytes are all durable), and an
    // empty active segment until the checkpoint of the next one is.
    sealed_.push_back(done);
    active_index_.clear();
    durable_offset_ = 0;
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
    std::lock_guard<std::mutex> l(state_mu_);
    active_id_ = new_id;
  }
  active_bytes_ = 0;
  start_indexer(done.id, entries);

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
    std::lock_guard<std::mutex> l(state_mu_);
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

// ---------------------------------------------------------------- queries

AuditLog::Impl::Snapshot AuditLog::Impl::snapshot() const {
  Snapshot s;
  std::lock_guard<std::mutex> l(state_mu_);
  s.sealed = sealed_;
  s.active_id = active_id_;
  s.active_durable = durable_offset_;
  s.active = active_index_;
  return s;
}

Result<std::vector<IndexEntry>> AuditLog::Impl::entries_of(const Segment& s) const {
  if (s.mem) return *s.mem;
  if (s.header) return internal::read_index_entries(env_, idx_path(s.id), *s.header);
  return unavailable("audit log: no index for segment " + std::to_string(s.id));
}

Result<std::string> AuditLog::Impl::read_line(uint64_t seg_id, const IndexEntry& e) const {
  auto r = env_->read_range(seg_path(seg_id), e.offset, static_cast<size_t>(e.len));
  if (!r.ok()) return r.error();
  if (r->size() != e.len) return unavailable("audit log: short read in segment");
  return std::move(*r);
}

namespace {
struct ReaderGuard {
  explicit ReaderGuard(std::atomic<int>& c) : c_(c) { ++c_; }
  ~ReaderGuard() { --c_; }
  std::atomic<int>& c_;
};
}  // namespace

// A ranged export is a contiguous slice of the chain: from the first record whose
// timestamp is in [from, to] to the last such record, including whatever lies between
// (e.g. checkpoints), so that it verifies with allow_partial_start.
namespace {
class SliceEmitter {
 public:
  SliceEmitter(int64_t from, int64_t to, const AuditLog::LineSink& sink)
      : from_(from), to_(to), sink_(sink) {}
  bool started() const { return started_; }
  bool stopped() const { return stopped_; }
  // Returns false to stop reading.
  bool line(std::string_view l, int64_t ts) {
    bool in = ts >= from_ && ts <= to_;
    if (!started_) {
      if (!in) return true;
      started_ = true;
    }
    if (!in) {
      held_.emplace_back(l);
      return true;
    }
    for (const auto& h : held_) {
      if (!sink_(h)) return stop();
    }
    held_.clear();
    if (!sink_(l)) return stop();
    return true;
  }

 private:
  bool stop() {
    stopped_ = true;
    return false;
  }
  int64_t from_, to_;
  const AuditLog::LineSink& sink_;
  bool started_ = false;
  bool stopped_ = false;
  std::vector<std::string> held_;
};
}  // namespace

Status AuditLog::Impl::export_range(int64_t from, int64_t to, const LineSink& sink) const {
  ReaderGuard guard(readers_);
  Snapshot snap = snapshot();
  struct Part {
    uint64_t id;
    uint64_t limit;
    int64_t min_ts, max_ts;
    const Segment* seg;  // null for the active segment
  };
  std::vector<Part> parts;
  for (const auto& seg : snap.sealed)
    parts.push_back({seg.id, UINT64_MAX, seg.min_ts, seg.max_ts, &seg});
  if (!snap.active.empty()) {
    int64_t mn = snap.active.front().ts, mx = mn;
    for (const auto& e : snap.active) {
      mn = std::min(mn, e.ts);
      mx = std::max(mx, e.ts);
    }
    parts.push_back({snap.active_id, snap.active_durable, mn, mx, nullptr});
  }
  // later_overlap[i]: some part at index >= i has a record in range.
  std::vector<bool> later_overlap(parts.size() + 1, false);
  for (size_t i = parts.size(); i-- > 0;)
    later_overlap[i] = later_overlap[i + 1] || !(parts[i].max_ts < from || parts[i].min_ts > to);
  SliceEmitter out(from, to, sink);
  for (size_t i = 0; i < parts.size() && !out.stopped(); ++i) {
    if (!later_overlap[i]) break;
    const Part& p = parts[i];
    bool overlap = !(p.max_ts < from || p.min_ts > to);
    if (!out.started() && !overlap) continue;
    bool all_in = p.min_ts >= from && p.max_ts <= to;
    std::vector<IndexEntry> loaded;
    const std::vector<IndexEntry>* entries = nullptr;
    if (!all_in) {
      if (p.seg) {
        auto e = entries_of(*p.seg);
        if (!e.ok()) return e.error();
        loaded = std::move(*e);
        entries = &loaded;
      } else {
        entries = &snap.active;
      }
    }
    size_t k = 0;
    Status s = internal::for_each_line(
        env_, seg_path(p.id), p.limit, [&](uint64_t, std::string_view line) {
          int64_t ts = all_in ? from : (k < entries->size() ? (*entries)[k].ts : INT64_MIN);
          ++k;
          return out.line(line, ts);
        });
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

Result<std::vector<std::string>> AuditLog::Impl::find(bool watermark, std::string_view key) const {
  ReaderGuard guard(readers_);
  Snapshot snap = snapshot();
  uint64_t h = internal::fnv1a64(key);
  std::vector<std::string> out;
  auto consider_line = [&](uint64_t seq, Result<std::string> line) -> Status {
    if (!line.ok()) return line.error();
    auto v = json::parse(*line, internal::record_parse_options());
    if (!v.ok() || !v->is_object()) return Status::Ok();
    const json::Value* f = v->get(watermark ? "watermark_token" : "message_id");
    if (!f || !f->is_string() || f->as_string() != key) return Status::Ok();  // hash collision
    if (!check_record(v->as_object(), opts_.secret).hmac_ok)
      return unavailable("audit log: record at seq " + std::to_string(seq) + " fails its hmac");
    out.push_back(std::move(*line));
    return Status::Ok();
  };
  auto consider = [&](uint64_t seg_id, const IndexEntry& e) {
    return consider_line(e.seq, read_line(seg_id, e));
  };
  auto scan_mem = [&](uint64_t seg_id, const std::vector<IndexEntry>& entries) -> Status {
    for (const auto& e : entries) {
      if (watermark ? (e.has_wm && e.wm_hash == h) : e.mid_hash == h) {
        Status s = consider(seg_id, e);
        if (!s.ok()) return s;
      }
    }
    return Status::Ok();
  };
  for (const auto& seg : snap.sealed) {
    Status s;
    if (seg.mem) {
      s = scan_mem(seg.id, *seg.mem);
    } else if (seg.header) {
      auto seqs = internal::index_lookup(env_, idx_path(seg.id), *seg.header, watermark, h);
      if (!seqs.ok()) return seqs.error();
      for (uint64_t seq : *seqs) {
        if (seq < seg.header->first_seq || seq > seg.header->last_seq)
          continue;  // a damaged hash table
        // A damaged entry is looked up in the segment, not trusted (the HMAC is checked below,
        // after the key: a hash collision is a miss, not an error).
        s = consider_line(
            seq, sealed_line(seg.id,
                             internal::read_index_entry(env_, idx_path(seg.id), *seg.header,
                                                        seq - seg.header->first_seq),
                             seq, false));
        if (!s.ok()) break;
      }
    }
    if (!s.ok()) return s.error();
  }
  Status s = scan_mem(snap.active_id, snap.active);
  if (!s.ok()) return s.error();
  return out;
}

Result<std::string> AuditLog::Impl::get(uint64_t seq) const {
  ReaderGuard guard(readers_);
  // Only what locates this one record is copied under the lock (not the active segment's
  // whole index, which made a page of reads quadratic in the segment's size).
  std::optional<Segment> sealed;
  std::optional<IndexEntry> active;
  uint64_t active_id = 0;
  {
    std::lock_guard<std::mutex> l(state_mu_);
    for (const auto& seg : sealed_) {
      if (seq < seg.first_seq || seq > seg.last_seq) continue;
      if (seg.mem || seg.header) {
        sealed = seg;
        break;
      }
    }
    if (!sealed && !active_index_.empty() && seq >= active_index_.front().seq &&
        seq <= active_index_.back().seq) {
      active = active_index_[seq - active_index_.front().seq];
      active_id = active_id_;
    }
  }
  if (sealed && sealed->mem)
    return exact_line(read_line(sealed->id, (*sealed->mem)[seq - sealed->first_seq]), seq);
  if (sealed)
    return sealed_line(sealed->id,
                       internal::read_index_entry(env_, idx_path(sealed->id), *sealed->header,
                                                  seq - sealed->first_seq),
                       seq, true);
  if (active) return exact_line(read_line(active_id, *active), seq);
  return Error(ErrorCode::kNotFound, "no audit record with seq " + std::to_string(seq));
}

// Whether `line` is the record with this seq (and, with verify_hmac, verifies with the secret).
AuditLog::Impl::LineCheck AuditLog::Impl::check_line(std::string_view line, uint64_t seq,
                                                     bool verify_hmac) const {
  auto v = json::parse(line, internal::record_parse_options());
  if (!v.ok() || !v->is_object()) return LineCheck::kOtherLine;
  auto k = internal::record_keys(*v);
  if (!k || k->seq != seq) return LineCheck::kOtherLine;
  if (verify_hmac && !check_record(v->as_object(), opts_.secret).hmac_ok)
    return LineCheck::kBadHmac;
  return LineCheck::kOk;
}

Error AuditLog::Impl::hmac_refusal(uint64_t seq) {
  return unavailable("audit log: record at seq " + std::to_string(seq) + " fails its hmac");
}

// A line read through an in-memory entry (the active segment, or a sealed one whose .idx is
// not written yet): the entry is exact, so a line that is not the verifying record means the
// file changed under the log. Refused, never returned.
Result<std::string> AuditLog::Impl::exact_line(Result<std::string> line, uint64_t seq) const {
  if (!line.ok()) return line;
  switch (check_line(*line, seq, true)) {
    case LineCheck::kOk:
      return line;
    case LineCheck::kBadHmac:
      return hmac_refusal(seq);
    case LineCheck::kOtherLine:
      break;
  }
  return unavailable("audit log: the stored line for seq " + std::to_string(seq) +
                     " is not that record");
}

// Record `seq` of a sealed segment through its .idx entry. The index file is not covered by the
// chain, so a damaged entry (wrong offset, length or seq) must make the answer slower, never
// wrong: when the entry does not lead to the record with that seq, the record is looked for in
// the segment itself (counted in index_fallbacks). With verify_hmac, a record that fails its HMAC
// is refused, never returned (find() checks the HMAC itself, after comparing its key).
Result<std::string> AuditLog::Impl::sealed_line(uint64_t seg_id, Result<IndexEntry> e, uint64_t seq,
                                                bool verify_hmac) const {
  if (e.ok()) {
    auto line = read_line(seg_id, *e);
    if (line.ok()) {
      switch (check_line(*line, seq, verify_hmac)) {
        case LineCheck::kOk:
          return line;
        case LineCheck::kBadHmac:
          return hmac_refusal(seq);
        case LineCheck::kOtherLine:
          break;
      }
    }
  }
  index_fallbacks_.fetch_add(1, std::memory_order_relaxed);
  std::optional<std::string> found;
  Status s = internal::for_each_line(env_, seg_path(seg_id), UINT64_MAX,
                                     [&](uint64_t, std::string_view line) {
                                       // Records are in seq order: stop at the first one at or past
                                       // `seq`.
                                       auto v = json::parse(line, internal::record_parse_options());
                                       auto k = v.ok() ? internal::record_keys(*v) : std::nullopt;
                                       if (!k || k->seq < seq) return true;
                                       if (k->seq == seq) found.emplace(line);
                                       return false;
                                     });
  if (!s.ok()) return s.error();
  if (!found)
    return unavailable("audit log: seq " + std::to_string(seq) +
                       " is missing from sealed segment " + internal::segment_file_name(seg_id));
  if (check_line(*found, seq, verify_hmac) != LineCheck::kOk) return hmac_refusal(seq);
  return std::move(*found);
}

AuditStats AuditLog::Impl::stats() const {
  AuditStats st;
  {
    std::lock_guard<std::mutex> l(state_mu_);
    st.first_seq = !sealed_.empty()         ? sealed_.front().first_seq
                   : !active_index_.empty() ? active_index_.front().seq
                                            : 0;
    st.last_seq = durable_seq_;
    st.last_hash = durable_hash_;
    st.segments = sealed_.size() + 1;
    st.active_segment = active_id_;
    st.total_bytes = durable_offset_;
    for (const auto& s : sealed_) st.total_bytes += s.bytes;
  }
  std::lock_guard<std::mutex> l(mu_);
  st.groups_committed = groups_.load();
  st.syncs = syncs_.load();
  st.failed = failed_.load();
  st.recoveries = recoveries_.load();
  st.index_fallbacks = index_fallbacks_.load(std::memory_order_relaxed);
  return st;
}

// ---------------------------------------------------------------- public surface

AuditLog::AuditLog(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
AuditLog::~AuditLog() = default;

Result<std::unique_ptr<AuditLog>> AuditLog::open(const std::string& dir, AuditOptions options) {
  auto impl = std::make_unique<Impl>(dir, std::move(options));
  Status s = impl->open();
  if (!s.ok()) return s.error();
  return std::unique_ptr<AuditLog>(new AuditLog(std::move(impl)));
}

Result<Receipt> AuditLog::append(AuditEntry entry) {
  // Shared: the writer may still be inside notify_one() when this thread wakes up.
  struct Slot {
    std::atomic<int> done{0};
    std::optional<Result<Receipt>> result;
  };
  auto slot = std::make_shared<Slot>();
  impl_->submit(
      std::move(entry),
      [slot](Result<Receipt> r) {
        slot->result.emplace(std::move(r));
        slot->done.store(1, std::memory_order_release);
        slot->done.notify_one();
      },
      Commit::kWriter);
  slot->done.wait(0, std::memory_order_acquire);
  return std::move(*slot->result);
}

void AuditLog::append_async(AuditEntry entry, Callback done, Commit commit) {
  impl_->submit(std::move(entry), std::move(done), commit);
}

Status AuditLog::export_range(int64_t from_ms, int64_t to_ms, const LineSink& sink) const {
  return impl_->export_range(from_ms, to_ms, sink);
}

Result<std::string> AuditLog::export_jsonl(int64_t from_ms, int64_t to_ms) const {
  std::string out;
  Status s = impl_->export_range(from_ms, to_ms, [&](std::string_view line) {
    out.append(line);
    out.push_back('\n');
    return true;
  });
  if (!s.ok()) return s.error();
  return out;
}

Result<std::vector<std::string>> AuditLog::find_by_message_id(std::string_view id) const {
  return impl_->find(false, id);
}
Result<std::vector<std::string>> AuditLog::find_by_watermark(std::string_view token) const {
  return impl_->find(true, token);
}
Result<std::string> AuditLog::get(uint64_t seq) const { return impl_->get(seq); }
AuditStats AuditLog::stats() const { return impl_->stats(); }
bool AuditLog::available() const { return impl_->available(); }
const std::string& AuditLog::dir() const { return impl_->dir(); }

// ---------------------------------------------------------------- offline

Result<std::vector<std::string>> list_segments(const std::string& dir, Env* env) {
  if (!env) env = Env::posix();
  auto ids = internal::segment_ids(env, dir);
  if (!ids.ok()) return ids.error();
  std::vector<std::string> out;
  for (uint64_t id : *ids) out.push_back(dir + "/" + internal::segment_file_name(id));
  return out;
}

Status export_dir(const std::string& dir, int64_t from_ms, int64_t to_ms,
                  const AuditLog::LineSink& sink, Env* env) {
  if (!env) env = Env::posix();
  auto segs = list_segments(dir, env);
  if (!segs.ok()) return segs.error();
  if (segs->empty()) return Error(ErrorCode::kNotFound, "no audit segments in " + dir);
  bool everything = from_ms == INT64_MIN && to_ms == INT64_MAX;
  SliceEmitter out(from_ms, to_ms, sink);
  for (const auto& p : *segs) {
    if (out.stopped()) break;
    Status s = internal::for_each_line(env, p, UINT64_MAX, [&](uint64_t, std::string_view line) {
      int64_t ts = from_ms;
      if (!everything) {
        auto v = json::parse(line, internal::record_parse_options());
        const json::Value* t = v.ok() ? v->get("timestamp_ms") : nullptr;
        ts = t && t->is_int() ? t->as_int() : INT64_MIN;
      }
      return out.line(line, ts);
    });
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

}  // namespace rcan::audit
