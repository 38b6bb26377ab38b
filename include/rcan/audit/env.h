// rcan::audit::Env — the audit log's view of a file system (rcan::base::Env): the same
// operations, with every failure reported as AUDIT_UNAVAILABLE (message naming the step, the
// path and errno text). A log whose storage fails is an audit log that is unavailable; what the
// failure means to other writers of files (the ESTOP latch, state files) is theirs to say.
//
//   FaultInjectionEnv fs(base::Env::posix());  // tests: a file system that fails on purpose
//   audit::Env env(&fs);
//   AuditLog::Options opts{.env = &env};
//
// Thread-safe as its base::Env is.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/base/env.h"
#include "rcan/result.h"

namespace rcan::audit {

// A file opened for appending. Not thread-safe; one writer at a time.
class WritableFile {
 public:
  explicit WritableFile(std::unique_ptr<base::WritableFile> file) : file_(std::move(file)) {}
  // Appends all of `data` at the end of the file (may sit in the page cache).
  Status append(std::string_view data);
  // Makes everything appended so far durable (fdatasync).
  Status sync();
  Status close();

 private:
  std::unique_ptr<base::WritableFile> file_;
};

// The operations of base::Env (see there for each one's contract).
class Env {
 public:
  // `fs` must outlive this object.
  explicit Env(base::Env* fs) : fs_(fs) {}

  Result<std::unique_ptr<WritableFile>> open_appendable(const std::string& path);
  Result<std::unique_ptr<WritableFile>> open_writable_at(const std::string& path, uint64_t offset);
  Result<std::unique_ptr<WritableFile>> open_existing_at(const std::string& path, uint64_t offset);
  Status write_zeros_synced(const std::string& path, uint64_t bytes);
  Result<std::string> read_file(const std::string& path);
  Result<std::string> read_range(const std::string& path, uint64_t offset, size_t n);
  Result<uint64_t> file_size(const std::string& path);
  bool exists(const std::string& path);
  Result<std::vector<std::string>> children(const std::string& dir);
  Status create_dir(const std::string& dir);
  Status sync_dir(const std::string& dir);
  Status remove_file(const std::string& path);
  Status rename_file(const std::string& from, const std::string& to);
  Status truncate_file(const std::string& path, uint64_t size);
  Status write_file_synced(const std::string& path, std::string_view data);
  Status write_private_file_synced(const std::string& path, std::string_view data);
  Status write_file_atomic(const std::string& path, std::string_view data);
  Result<int> lock_file(const std::string& path);
  void unlock_file(int handle);
  int64_t now_ms();

  base::Env* fs() const { return fs_; }
  // The audit log's view of base::Env::posix() (never deleted).
  static Env* posix();

 private:
  base::Env* fs_;
};

}  // namespace rcan::audit
