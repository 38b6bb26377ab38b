// audit::Env — base::Env with its failures as AUDIT_UNAVAILABLE.
#include "rcan/audit/env.h"

namespace rcan::audit {
namespace {

Error unavailable(const base::IoError& e) {
  // A lock held by another process names the log, as the log's own refusal.
  if (e.code == base::IoCode::kLocked)
    return Error(ErrorCode::kAuditUnavailable, "audit log " + e.message);
  return Error(ErrorCode::kAuditUnavailable, e.message);
}

Status mapped(const base::IoStatus& s) {
  if (s.ok()) return Status::Ok();
  return unavailable(s.error());
}

template <typename T>
Result<T> mapped(base::IoResult<T>&& r) {
  if (!r.ok()) return unavailable(r.error());
  return std::move(r).value();
}

Result<std::unique_ptr<WritableFile>> wrapped(
    base::IoResult<std::unique_ptr<base::WritableFile>>&& r) {
  if (!r.ok()) return unavailable(r.error());
  return std::make_unique<WritableFile>(std::move(r).value());
}

}  // namespace

Status WritableFile::append(std::string_view data) { return mapped(file_->append(data)); }
Status WritableFile::sync() { return mapped(file_->sync()); }
Status WritableFile::close() { return mapped(file_->close()); }

Result<std::unique_ptr<WritableFile>> Env::open_appendable(const std::string& path) {
  return wrapped(fs_->open_appendable(path));
}
Result<std::unique_ptr<WritableFile>> Env::open_writable_at(const std::string& path,
                                                            uint64_t offset) {
  return wrapped(fs_->open_writable_at(path, offset));
}
Result<std::unique_ptr<WritableFile>> Env::open_existing_at(const std::string& path,
                                                            uint64_t offset) {
  return wrapped(fs_->open_existing_at(path, offset));
}
Status Env::write_zeros_synced(const std::string& path, uint64_t bytes) {
  return mapped(fs_->write_zeros_synced(path, bytes));
}
Result<std::string> Env::read_file(const std::string& path) { return mapped(fs_->read_file(path)); }
Result<std::string> Env::read_range(const std::string& path, uint64_t offset, size_t n) {
  return mapped(fs_->read_range(path, offset, n));
}
Result<uint64_t> Env::file_size(const std::string& path) { return mapped(fs_->file_size(path)); }
bool Env::exists(const std::string& path) { return fs_->exists(path); }
Result<std::vector<std::string>> Env::children(const std::string& dir) {
  return mapped(fs_->children(dir));
}
Status Env::create_dir(const std::string& dir) { return mapped(fs_->create_dir(dir)); }
Status Env::sync_dir(const std::string& dir) { return mapped(fs_->sync_dir(dir)); }
Status Env::remove_file(const std::string& path) { return mapped(fs_->remove_file(path)); }
Status Env::rename_file(const std::string& from, const std::string& to) {
  return mapped(fs_->rename_file(from, to));
}
Status Env::truncate_file(const std::string& path, uint64_t size) {
  return mapped(fs_->truncate_file(path, size));
}
Status Env::write_file_synced(const std::string& path, std::string_view data) {
  return mapped(fs_->write_file_synced(path, data));
}
Status Env::write_private_file_synced(const std::string& path, std::string_view data) {
  return mapped(fs_->write_private_file_synced(path, data));
}
Status Env::write_file_atomic(const std::string& path, std::string_view data) {
  return mapped(fs_->write_file_atomic(path, data));
}
Result<int> Env::lock_file(const std::string& path) { return mapped(fs_->lock_file(path)); }
void Env::unlock_file(int handle) { fs_->unlock_file(handle); }
int64_t Env::now_ms() { return fs_->now_ms(); }

Env* Env::posix() {
  static Env* env = new Env(base::Env::posix());  // never deleted: used by static destructors
  return env;
}

}  // namespace rcan::audit
