// LatchFile: the ESTOP latch's file in the safety core's state directory (safety_state.json),
// read and written through a base::Env (tests inject faults with it).
//
// Format: one JSON object {"check","format","estop_active","source","reason","since_ms",
// "by_level","written_ms"}, padded with spaces to kBytes (one page) and ended by a newline;
// "check" is the SHA-256 of the other members (dumped without it). A latch over a cleared file
// of that fixed form rewrites it in place (one pwrite and one fdatasync, no new file, rename or
// directory sync); anything else replaces it whole (Env::write_file_atomic). A write torn by a
// crash fails the check, and the node comes up latched.
//
// Errors are the latch's: INTERNAL with reason kUnreadable or kUnwritable, the message naming
// the step, the file and errno (the Env's own failure underneath).
//
// Not thread-safe: one thread at a time (the safety core hands the file from one writer to the
// next under its lock).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "rcan/base/env.h"
#include "rcan/result.h"

namespace rcan::node {

// The ESTOP latch as the safety core keeps it, and as its file says.
struct LatchState {
  bool active = false;
  std::string source;
  std::string reason;
  int64_t since_wall_ms = 0;
  int by_level = 0;  // the highest role level that latched it; 0: the node itself
};

// What a latch file held: nothing, a latch state, or something that is not one (`why`).
struct LatchRead {
  bool missing = false;
  bool corrupt = false;
  std::string why;  // corrupt: "state file fails its check (a write torn by a crash?)", …
  LatchState state;
};

class LatchFile {
 public:
  static constexpr const char* kName = "safety_state.json";
  static constexpr const char* kFormat = "rcan-safety-state-v1";
  static constexpr size_t kBytes = 4096;  // one page; a longer state is written whole instead
  static constexpr const char* kUnreadable = "latch_unreadable";
  static constexpr const char* kUnwritable = "latch_unwritable";

  // The file `kName` in `state_dir`. `env` (nullptr → base::Env::posix()) must outlive this.
  LatchFile(const std::string& state_dir, base::Env* env);

  const std::string& path() const { return path_; }
  // Reads and checks the file. Missing → missing; a file of another shape or one failing its
  // check → corrupt (why says which). A file that is there but cannot be read: INTERNAL,
  // kUnreadable.
  Result<LatchRead> read();
  // Keeps a corrupt file as *.corrupt for forensics (best effort).
  void set_aside();
  // Writes `st` (stamped `written_ms`), durably: in place when the file on disk has the fixed
  // form and says cleared and `st` latches, else whole. INTERNAL, kUnwritable on failure (then
  // the next write is whole).
  Status write(const LatchState& st, int64_t written_ms);
  // The file on disk has the fixed form (after read() or a write()).
  bool fixed() const { return fixed_; }

 private:
  base::Env* env_;
  std::string path_;
  // What the file on disk is: the fixed form, and what it says. Unknown (after a failure or
  // before a read): not fixed, latched, so that no write goes in place.
  bool fixed_ = false;
  bool latched_ = true;
};

}  // namespace rcan::node
