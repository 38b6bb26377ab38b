// rcan::audit::Env — the file-system surface the audit log uses, so tests can break it.
//
// In the spirit of LevelDB's Env: the log never calls POSIX directly. Env::posix() is
// the real thing; FaultInjectionEnv (fault_env.h) wraps it to fail at a chosen operation
// and to "crash" by dropping every byte that was not fsync'ed.
//
// All operations return errors as values (code kAuditUnavailable, message naming the
// path and errno text). Implementations must be thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/result.h"

namespace rcan::audit {

// A file opened for appending. Not thread-safe; one writer at a time.
class WritableFile {
 public:
  virtual ~WritableFile() = default;
  // Appends all of `data` at the end of the file (may sit in the page cache).
  virtual Status append(std::string_view data) = 0;
  // Makes everything appended so far durable (fdatasync).
  virtual Status sync() = 0;
  virtual Status close() = 0;
};

class Env {
 public:
  virtual ~Env() = default;

  // Opens `path` for appending, creating it (mode 0600) when missing.
  virtual Result<std::unique_ptr<WritableFile>> open_appendable(const std::string& path) = 0;
  // Opens `path` (creating it, mode 0600) for positional writes starting at `offset`;
  // used on preallocated segments, whose file size is larger than their data.
  virtual Result<std::unique_ptr<WritableFile>> open_writable_at(const std::string& path,
                                                                 uint64_t offset) = 0;
  // Opens `path`, which must exist and be a regular file (nothing is created; a symbolic link,
  // a FIFO or a device is refused, without blocking), for positional writes starting at
  // `offset`: a file rewritten in place, which is gone when it was removed meanwhile. Its sync
  // fails when the file was removed after the open (its data would be in no file).
  virtual Result<std::unique_ptr<WritableFile>> open_existing_at(const std::string& path,
                                                                 uint64_t offset) = 0;
  // Creates/overwrites `path` with `bytes` zero bytes, written (not just allocated) and
  // fsync'ed, so that later overwrites need no metadata journal commit on fdatasync.
  virtual Status write_zeros_synced(const std::string& path, uint64_t bytes) = 0;
  virtual Result<std::string> read_file(const std::string& path) = 0;
  // Up to `n` bytes from `offset` (fewer at end of file). `n` comes from indexes on disk, which
  // may be corrupt: an implementation never allocates more than the file holds.
  virtual Result<std::string> read_range(const std::string& path, uint64_t offset, size_t n) = 0;
  virtual Result<uint64_t> file_size(const std::string& path) = 0;
  virtual bool exists(const std::string& path) = 0;
  // Names (not paths) of the entries of `dir`, without "." and "..".
  virtual Result<std::vector<std::string>> children(const std::string& dir) = 0;
  virtual Status create_dir(const std::string& dir) = 0;  // ok when it exists
  virtual Status sync_dir(const std::string& dir) = 0;
  virtual Status remove_file(const std::string& path) = 0;
  virtual Status rename_file(const std::string& from, const std::string& to) = 0;
  // Truncates to `size` and fsyncs the file.
  virtual Status truncate_file(const std::string& path, uint64_t size) = 0;
  // Creates/overwrites `path` (0600) with `data` and fsyncs it.
  virtual Status write_file_synced(const std::string& path, std::string_view data) = 0;
  // The same for a file only its owner may read: the mode is made exactly 0600 (also when the
  // file existed with another), and a symbolic link at `path` is refused (O_NOFOLLOW).
  virtual Status write_private_file_synced(const std::string& path, std::string_view data) = 0;
  // Takes an exclusive advisory lock (flock) on `path`, creating it; released by unlock.
  virtual Result<int> lock_file(const std::string& path) = 0;
  virtual void unlock_file(int handle) = 0;
  // Wall clock, milliseconds since the Unix epoch.
  virtual int64_t now_ms() = 0;

  // Replaces `path` with `data`, atomically and durably: writes `path`.tmp in the same directory
  // (write_private_file_synced: mode 0600, no symbolic link followed, fsync'ed), renames it over
  // `path`, then fsyncs the directory. A failure up to the rename leaves `path` as it was (the
  // temporary file is removed, best effort); a failed directory fsync leaves the new contents in
  // place, perhaps not yet durable. Errors name the step, the file and errno ("rename
  // /d/f.tmp: No space left on device"). Made only of the operations above, so a
  // FaultInjectionEnv can fail each of its steps. The node's state files, its HiTL pending file
  // and the safety core's ESTOP latch are written with it.
  Status write_file_atomic(const std::string& path, std::string_view data);

  // The process-wide POSIX environment (never deleted).
  static Env* posix();
};

}  // namespace rcan::audit
