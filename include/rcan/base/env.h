// rcan::base::Env — the file-system surface of everything that writes durable files (the audit
// log, the safety core's ESTOP latch, the node's state files), so tests can break it.
//
// In the spirit of LevelDB's Env: its users never call POSIX directly. Env::posix() is the real
// thing; FaultInjectionEnv (src/testing/fault_env.h) wraps it to fail at a chosen operation and
// to "crash" by dropping every byte that was not fsync'ed.
//
// Errors are values of this layer's own kind (IoError: what failed, on which path, errno text),
// not protocol errors: each user gives a failure its own meaning (the audit log answers
// AUDIT_UNAVAILABLE, the ESTOP latch reports a latch error). Implementations must be
// thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace rcan::base {

// What kind of file-system failure an IoError is.
enum class IoCode {
  kIo,        // a system call failed (IoError::sys_errno says which errno)
  kNotFound,  // the file or directory does not exist (ENOENT)
  kLocked,    // lock_file: another process holds the lock
  kInjected,  // a test's fault injection (FaultInjectionEnv)
};

struct IoError {
  IoCode code = IoCode::kIo;
  int sys_errno = 0;
  std::string message;  // "rename /d/f.tmp: No space left on device"
};

// Success, or an IoError.
class [[nodiscard]] IoStatus {
 public:
  IoStatus() = default;
  IoStatus(IoError err)  // NOLINT(google-explicit-constructor)
      : err_(std::move(err)), ok_(false) {}
  static IoStatus Ok() { return IoStatus(); }
  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  const IoError& error() const { return err_; }

 private:
  IoError err_;
  bool ok_ = true;
};

// A value, or an IoError.
template <typename T>
class [[nodiscard]] IoResult {
 public:
  IoResult(T value)  // NOLINT(google-explicit-constructor)
      : v_(std::in_place_index<0>, std::move(value)) {}
  IoResult(IoError err)  // NOLINT(google-explicit-constructor)
      : v_(std::in_place_index<1>, std::move(err)) {}
  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }
  T& value() & { return std::get<0>(v_); }
  const T& value() const& { return std::get<0>(v_); }
  T&& value() && { return std::get<0>(std::move(v_)); }
  T* operator->() { return &std::get<0>(v_); }
  const T* operator->() const { return &std::get<0>(v_); }
  T& operator*() & { return std::get<0>(v_); }
  const T& operator*() const& { return std::get<0>(v_); }
  const IoError& error() const& { return std::get<1>(v_); }

 private:
  std::variant<T, IoError> v_;
};

// A file opened for appending. Not thread-safe; one writer at a time.
class WritableFile {
 public:
  virtual ~WritableFile() = default;
  // Appends all of `data` at the end of the file (may sit in the page cache).
  virtual IoStatus append(std::string_view data) = 0;
  // Makes everything appended so far durable (fdatasync).
  virtual IoStatus sync() = 0;
  virtual IoStatus close() = 0;
};

class Env {
 public:
  virtual ~Env() = default;

  // Opens `path` for appending, creating it (mode 0600) when missing.
  virtual IoResult<std::unique_ptr<WritableFile>> open_appendable(const std::string& path) = 0;
  // Opens `path` (creating it, mode 0600) for positional writes starting at `offset`;
  // used on preallocated segments, whose file size is larger than their data.
  virtual IoResult<std::unique_ptr<WritableFile>> open_writable_at(const std::string& path,
                                                                   uint64_t offset) = 0;
  // Opens `path`, which must exist and be a regular file (nothing is created; a symbolic link,
  // a FIFO or a device is refused, without blocking), for positional writes starting at
  // `offset`: a file rewritten in place, which is gone when it was removed meanwhile. Its sync
  // fails when the file was removed after the open (its data would be in no file).
  virtual IoResult<std::unique_ptr<WritableFile>> open_existing_at(const std::string& path,
                                                                   uint64_t offset) = 0;
  // Creates/overwrites `path` with `bytes` zero bytes, written (not just allocated) and
  // fsync'ed, so that later overwrites need no metadata journal commit on fdatasync.
  virtual IoStatus write_zeros_synced(const std::string& path, uint64_t bytes) = 0;
  // The whole file (a small one: a state file, the ESTOP latch, an index); kNotFound when it
  // does not exist.
  virtual IoResult<std::string> read_file(const std::string& path) = 0;
  // Up to `n` bytes from `offset` (fewer at end of file). `n` comes from indexes on disk, which
  // may be corrupt: an implementation never allocates more than the file holds.
  virtual IoResult<std::string> read_range(const std::string& path, uint64_t offset, size_t n) = 0;
  virtual IoResult<uint64_t> file_size(const std::string& path) = 0;
  virtual bool exists(const std::string& path) = 0;
  // Names (not paths) of the entries of `dir`, without "." and "..".
  virtual IoResult<std::vector<std::string>> children(const std::string& dir) = 0;
  virtual IoStatus create_dir(const std::string& dir) = 0;  // ok when it exists
  virtual IoStatus sync_dir(const std::string& dir) = 0;
  virtual IoStatus remove_file(const std::string& path) = 0;
  virtual IoStatus rename_file(const std::string& from, const std::string& to) = 0;
  // Truncates to `size` and fsyncs the file.
  virtual IoStatus truncate_file(const std::string& path, uint64_t size) = 0;
  // Creates/overwrites `path` (0600) with `data` and fsyncs it.
  virtual IoStatus write_file_synced(const std::string& path, std::string_view data) = 0;
  // The same for a file only its owner may read: the mode is made exactly 0600 (also when the
  // file existed with another), and a symbolic link at `path` is refused (O_NOFOLLOW).
  virtual IoStatus write_private_file_synced(const std::string& path, std::string_view data) = 0;
  // Takes an exclusive advisory lock (flock) on `path`, creating it; released by unlock.
  virtual IoResult<int> lock_file(const std::string& path) = 0;
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
  IoStatus write_file_atomic(const std::string& path, std::string_view data);

  // The process-wide POSIX environment (never deleted).
  static Env* posix();
};

}  // namespace rcan::base
