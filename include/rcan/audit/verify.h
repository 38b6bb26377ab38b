// Offline verification of exported audit chains, native and rcan-py.
//
// Native (docs/AUDIT.md): one canonical record per line. Checked per line, in order:
// parse (→ "malformed line"), seq = previous + 1 (→ "seq gap"), prev_hash = SHA-256 of the
// previous record's pre-image (→ "prev_hash mismatch"), checkpoint continuity (→ "wrong
// segment link"), hmac (→ "hmac mismatch"). The first record must be seq 1 with a null
// prev_hash, or a checkpoint record (the chain start after retention: its prev_hash is
// vouched for by its own HMAC), unless `allow_partial_start` (a ranged export).
//
// rcan-py CommitmentRecord v0.3 (sdk-wire-formats.md §3.1): pre-image = Python
// json.dumps of the 12 fields (sort_keys, compact, ensure_ascii); hmac = HMAC-SHA256;
// content_hash = SHA-256(pre-image); previous_hash = content_hash of the previous line.
// Strict: the first line must have a null previous_hash (rcan-py does not check this).
#pragma once

#include <cstdint>
#include <istream>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::audit {

struct VerifyOptions {
  bool allow_partial_start = false;
  std::optional<uint64_t> expect_last_seq;  // detects removal of whole trailing records
};

struct VerifyReport {
  bool ok = false;
  uint64_t count = 0;      // records verified before the first failure (all when ok)
  uint64_t first_seq = 0;  // native: seq of the first record
  uint64_t last_seq = 0;   // native: seq of the last good record
  std::string last_hash;   // hash of the last good record
  // On failure: the seq that is bad (native; the expected seq when the line has none),
  // the 0-based line index (both formats), and why.
  uint64_t first_bad_seq = 0;
  uint64_t first_bad_index = 0;
  std::string why;  // "hmac mismatch", "prev_hash mismatch", "seq gap", "malformed line",
                    // "wrong segment link", "bad chain start", "truncated" (+ ": detail")
};

// Incremental native verifier (feed lines in order). Used by the CLI, the fuzzer and
// the data-directory check.
class ChainVerifier {
 public:
  ChainVerifier(std::string secret, VerifyOptions options = {});
  // Returns false once a failure has been found (the report says which).
  bool add_line(std::string_view line);
  // Call at the end; applies expect_last_seq. An empty stream is not ok.
  const VerifyReport& finish();
  const VerifyReport& report() const { return report_; }
  // Expect the next record to open segment `n` (data-directory verification).
  void expect_segment_start(uint64_t n) { expect_segment_ = n; }

 private:
  bool fail(uint64_t seq, std::string why);
  std::string secret_;
  VerifyOptions options_;
  VerifyReport report_;
  uint64_t index_ = 0;
  uint64_t last_seq_ = 0;
  uint64_t segment_ = 0;  // segment number of the last checkpoint, 0 = none seen
  uint64_t expect_segment_ = 0;
  bool failed_ = false;
};

VerifyReport verify_jsonl(std::istream& in, std::string_view secret, VerifyOptions options = {});
VerifyReport verify_jsonl(std::string_view text, std::string_view secret,
                          VerifyOptions options = {});
// Verifies the segment files of a log directory in order, including that every segment
// opens with its checkpoint (a torn last line is reported, not skipped).
VerifyReport verify_dir(const std::string& dir, std::string_view secret);

// ---- rcan-py CommitmentRecord v0.3 ----

struct RcanpyRecord {
  json::Object fields;  // the 12 pre-image fields, missing ones restored (null / "")
  std::string hmac;     // empty when absent
};
// Parses one JSONL line as rcan-py's from_dict does (strict: unknown keys are an error).
Result<RcanpyRecord> rcanpy_parse_line(std::string_view line);
std::string rcanpy_preimage(const json::Object& fields);  // Python json.dumps pre-image
std::string rcanpy_hmac(std::string_view secret, const json::Object& fields);
std::string rcanpy_content_hash(const json::Object& fields);
// json.dumps(to_dict()) line: fixed key order, optional keys dropped when null/empty.
std::string rcanpy_line(const json::Object& fields, std::string_view hmac);

// Re-states native records as a CommitmentRecord chain signed with `secret`.
class RcanpyExporter {
 public:
  explicit RcanpyExporter(std::string secret);
  // One native record (parsed) → one rcan-py line (no newline).
  Result<std::string> add(const json::Object& native);

 private:
  std::string secret_;
  std::optional<std::string> previous_hash_;
};

// Verifies an rcan-py chain. first_bad_index is the 0-based line; why is "hmac mismatch",
// "chain_link: …" or "malformed line: …".
VerifyReport verify_rcanpy_jsonl(std::string_view text, std::string_view secret,
                                 bool strict_start = true);

}  // namespace rcan::audit
