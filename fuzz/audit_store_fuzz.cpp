// libFuzzer: the audit log's on-disk store (src/audit/audit_log.cpp, segment.cpp) — the files a
// node reads back at start-up after a crash, a full disk or tampering. The input is split at
// the line "--8<--" into up to four files of a log directory:
//   seg-00000001.log, seg-00000001.idx, seg-00000002.log, CLEAN (the files after the last
//   part are absent)
// and the directory is opened twice: offline (export_dir, as `rcan audit export` does) and by
// AuditLog::open (recovery, as rcand does). Invariants: nothing crashes or hangs; when open
// succeeds, every seq it reports can be read or is cleanly absent (and a record read by seq is
// that record), the export and the lookups return, and a new record appends right after the
// last seq it reported. RCAN_FUZZ_VERBOSE=1 prints what each step gave.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "rcan/audit/audit_log.h"
#include "rcan/json.h"

namespace {

[[noreturn]] void fail(const std::string& what) {
  std::fprintf(stderr, "audit_store_fuzz: %s\n", what.c_str());
  std::abort();
}

// Created on first use, removed at exit (the string outlives the exit handler: never freed).
const std::string& base_dir() {
  static const std::string* dir = [] {
    std::string base = ::access("/dev/shm", W_OK) == 0
                           ? "/dev/shm"
                           : std::filesystem::temp_directory_path().string();
    auto* d = new std::string(base + "/rcan-fuzz-audit-XXXXXX");
    if (!::mkdtemp(d->data())) fail("mkdtemp failed");
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(base_dir(), ec);
    });
    return d;
  }();
  return *dir;
}

void write_file(const std::string& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) fail("cannot write " + path);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view in(reinterpret_cast<const char*>(data), size);
  const std::string dir = base_dir() + "/log";
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  std::filesystem::create_directories(dir, ec);
  static constexpr const char* kFiles[] = {"seg-00000001.log", "seg-00000001.idx",
                                           "seg-00000002.log", "CLEAN"};
  static constexpr std::string_view kCut = "\n--8<--\n";
  for (const char* name : kFiles) {
    const size_t cut = in.find(kCut);
    write_file(dir + "/" + name, in.substr(0, cut));
    if (cut == std::string_view::npos) break;
    in.remove_prefix(cut + kCut.size());
  }

  // Offline reading (no recovery, no lock).
  size_t lines = 0;
  (void)audit::export_dir(dir, 0, INT64_MAX / 2,
                          [&](std::string_view) { return ++lines < 100000; });
  (void)audit::list_segments(dir);

  // Recovery.
  audit::AuditOptions o;
  o.secret = "fuzz-secret-0123456789abcdef";
  o.robot_ruri = "rcan://local.rcan/acme/rover/0a1b2c3d";
  o.preallocate = false;
  o.background_index = false;
  o.max_segment_bytes = 1u << 16;
  auto log = audit::AuditLog::open(dir, std::move(o));
  const bool verbose = std::getenv("RCAN_FUZZ_VERBOSE") != nullptr;
  if (verbose)
    std::fprintf(stderr, "  offline: %zu lines; open: %s\n", lines,
                 log.ok() ? "ok" : log.error().message.c_str());
  if (!log.ok()) {
    if (log.error().message.empty()) fail("open failed without a message");
    return 0;
  }
  audit::AuditStats st = (*log)->stats();
  if (st.last_seq != 0 && st.first_seq > st.last_seq) fail("first_seq > last_seq");
  uint64_t from = st.first_seq ? st.first_seq : 1;
  for (uint64_t seq = from; seq <= st.last_seq && seq < from + 64; ++seq) {
    // Whatever the .idx holds, a record read by seq is the record with that seq.
    auto line = (*log)->get(seq);
    if (!line.ok()) continue;
    auto v = json::parse(*line);
    const json::Value* got = v.ok() ? v->get("seq") : nullptr;
    if (got == nullptr || !got->is_int() || got->as_int() != static_cast<int64_t>(seq))
      fail("get(" + std::to_string(seq) + ") answered with another line");
  }
  (void)(*log)->get(st.last_seq + 1);
  (void)(*log)->export_jsonl(0, INT64_MAX / 2);
  (void)(*log)->find_by_message_id("6f1c3b5e-2a4d-4f7e-9b1a-0c2d3e4f5a60");
  (void)(*log)->find_by_watermark("rcan-wm-v1:0123456789abcdef0123456789abcdef");
  audit::AuditEntry e;
  e.principal = "owner:fuzz";
  e.ruri = "rcan://local.rcan/acme/rover/0a1b2c3d";
  e.message_id = "6f1c3b5e-2a4d-4f7e-9b1a-0c2d3e4f5a6f";
  e.event = "COMMAND";
  e.outcome = "ok";
  const uint64_t before = (*log)->stats().last_seq;
  auto r = (*log)->append(std::move(e));
  if (verbose)
    std::fprintf(
        stderr, "  seqs %llu..%llu, append: %s\n", static_cast<unsigned long long>(st.first_seq),
        static_cast<unsigned long long>(st.last_seq), r.ok() ? "ok" : r.error().message.c_str());
  if (r.ok() && r->seq != before + 1)
    fail("appended seq " + std::to_string(r->seq) + " after " + std::to_string(before));
  return 0;
}
