// AuditLog: the public surface, start and shutdown. The parts live in their own units (see
// audit_log_impl.h for the threads, what each owns and the locks): the write path
// (audit_writer.cpp), recovery (audit_recovery.cpp), segments (audit_segments.cpp) and the read
// side (audit_reader.cpp).
#include "rcan/audit/audit_log.h"

#include <pthread.h>

#include <atomic>
#include <memory>

#include "audit/audit_log_impl.h"
#include "rcan/audit/secret.h"
#include "rcan/hash.h"

namespace rcan::audit {

using internal::IndexEntry;

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

// ---------------------------------------------------------------- start and shutdown

AuditLog::Impl::Impl(std::string dir, AuditOptions opts)
    : dir_(std::move(dir)), opts_(std::move(opts)) {
  env_ = opts_.env ? opts_.env : Env::posix();
  pipelined_ = opts_.background_index &&
               (opts_.pipelined_sync || opts_.sync_policy == SyncPolicy::kInterval);
}

// Stops the writer after it has committed everything queued, then the syncer, then joins the
// background segment work; marks a clean shutdown when the log did not fail.
AuditLog::Impl::~Impl() {
  if (writer_.joinable()) {
    {
      MutexLock l(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    writer_.join();
  }
  if (syncer_.joinable()) {
    {
      MutexLock l(sync_mu_);
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

// Takes the directory's lock, recovers what an earlier run left (or starts a new chain), then
// starts the writer (and the syncer).
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
  s = ids->empty() ? start_new_log() : load_segments(*ids, clean);
  if (!s.ok()) return s;
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

// An empty directory: segment 1, opened by the genesis checkpoint.
Status AuditLog::Impl::start_new_log() {
  {
    MutexLock l(state_mu_);
    active_id_ = 1;
  }
  if (opts_.preallocate) {
    Status s = env_->write_zeros_synced(seg_path(1), opts_.max_segment_bytes);
    if (!s.ok()) return s;
  }
  auto f = env_->open_writable_at(seg_path(1), 0);
  if (!f.ok()) return f.error();
  file_ = std::move(*f);
  Status s = env_->sync_dir(dir_);
  if (!s.ok()) return s;
  AuditEntry genesis;
  genesis.kind = "checkpoint";
  genesis.event = "AUDIT_CHECKPOINT";
  genesis.segment = 1;
  genesis.detail.set("genesis", true);
  return write_records({genesis});
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

}  // namespace rcan::audit
