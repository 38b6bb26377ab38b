// FaultInjectionEnv — a base::Env that fails on purpose (tests only; cf. LevelDB
// db/fault_injection_test.cc).
//
// It forwards to a base Env and remembers, per file written through it, how many bytes
// were durable (covered by a sync or a synced write). Two faults:
//   * fail_after(n): the n-th mutating operation from now (append, sync, create,
//     rename, remove, truncate, synced write) and every later one fails without taking
//     effect — the process "dies" there. An append chosen as the failing operation can
//     be torn: half of its bytes reach the file before it fails (set_torn_appends).
//     Env::write_file_atomic is three of them (the temporary file's synced write, the
//     rename, the directory sync), so each of its steps can be the one that fails.
//   * fail_reads(true): every read (read_file, read_range) fails until fail_reads(false) —
//     a file that is there but cannot be read (EIO); reads count as no operation above.
//   * hold(true): every mutating operation waits until hold(false) — a disk that is slow or
//     hung — before it goes on (or fails as above); held() counts the ones waiting.
//   * drop_unsynced(): after the owner of the Env is gone, cuts every tracked file back
//     to its durable length (keeping `keep_fraction` of the unsynced tail to model a
//     torn page), puts back what a file rewritten in place (open_existing_at) held before
//     its unsynced rewrite (keeping the first `keep_fraction` of the new bytes: a torn
//     write), and deletes files created since the last sync_dir of their directory.
// `*base` must outlive this object.
#pragma once

#include <atomic>
#include <condition_variable>
#include <map>
#include <mutex>
#include <set>

#include "rcan/audit/env.h"
#include "rcan/base/env.h"

namespace rcan::base {

class FaultInjectionEnv : public Env {
 public:
  explicit FaultInjectionEnv(Env* base);

  // Operation `n` (1-based, counting from this call) and all later mutations fail.
  // n == 0 disables injection.
  void fail_after(uint64_t n);
  void hold(bool on);
  size_t held() const;
  void set_torn_appends(bool torn) { torn_appends_ = torn; }
  void fail_reads(bool on) { fail_reads_ = on; }
  bool failed() const;
  // Shifts now_ms() by `ms` (tests of age-based retention).
  void advance_clock(int64_t ms) { clock_offset_ms_ += ms; }
  uint64_t mutations() const;  // mutating operations seen so far
  // This file system as the audit log sees it (AuditLog::Options::env).
  audit::Env* audit() { return &audit_; }
  // Simulates the machine losing power; see above. Call with no writer running.
  IoStatus drop_unsynced(double keep_fraction = 0.0);

  IoResult<std::unique_ptr<WritableFile>> open_appendable(const std::string& path) override;
  // A file rewritten in place: its contents at the open are what a crash before its next sync
  // goes back to (drop_unsynced keeps `keep_fraction` of the new bytes over them: a torn write).
  IoResult<std::unique_ptr<WritableFile>> open_existing_at(const std::string& path,
                                                           uint64_t offset) override;
  IoResult<std::unique_ptr<WritableFile>> open_writable_at(const std::string& path,
                                                           uint64_t offset) override;
  IoStatus write_zeros_synced(const std::string& path, uint64_t bytes) override;
  IoResult<std::string> read_file(const std::string& path) override;
  IoResult<std::string> read_range(const std::string& path, uint64_t offset, size_t n) override;
  IoResult<uint64_t> file_size(const std::string& path) override;
  bool exists(const std::string& path) override;
  IoResult<std::vector<std::string>> children(const std::string& dir) override;
  IoStatus create_dir(const std::string& dir) override;
  IoStatus sync_dir(const std::string& dir) override;
  IoStatus remove_file(const std::string& path) override;
  IoStatus rename_file(const std::string& from, const std::string& to) override;
  IoStatus truncate_file(const std::string& path, uint64_t size) override;
  IoStatus write_file_synced(const std::string& path, std::string_view data) override;
  IoStatus write_private_file_synced(const std::string& path, std::string_view data) override;
  IoResult<int> lock_file(const std::string& path) override;
  void unlock_file(int handle) override;
  int64_t now_ms() override;

  // Internal (used by the file wrapper).
  IoStatus before_mutation(const std::string& what);
  void note_appended(const std::string& path, uint64_t n);
  void note_synced(const std::string& path);
  bool torn_appends() const { return torn_appends_; }
  bool is_failing_now();

 private:
  // write_file_synced and write_private_file_synced: one mutation, tracked as durable.
  IoStatus synced_write(const std::string& path, std::string_view data, bool private_file);

  struct FileState {
    uint64_t size = 0;
    uint64_t durable = 0;
  };
  Env* base_;
  audit::Env audit_{this};
  mutable std::mutex mu_;
  uint64_t ops_ = 0;
  uint64_t fail_at_ = 0;  // absolute op number; 0 = never
  bool hold_ = false;
  size_t held_ = 0;
  std::condition_variable release_;
  bool failed_ = false;
  bool just_tripped_ = false;
  bool torn_appends_ = false;
  std::atomic<int64_t> clock_offset_ms_{0};
  std::atomic<bool> fail_reads_{false};
  std::map<std::string, FileState> files_;
  std::set<std::string> new_files_;              // created, directory not yet synced
  std::map<std::string, std::string> rewrites_;  // rewritten in place, not yet synced: before
};

}  // namespace rcan::base
