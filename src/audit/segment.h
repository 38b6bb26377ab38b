// Private: segment files and their sidecar indexes (see docs/AUDIT.md §Storage).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/audit/env.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::audit::internal {

std::string segment_file_name(uint64_t id);  // seg-00000001.log
std::string index_file_name(uint64_t id);    // seg-00000001.idx
std::optional<uint64_t> parse_segment_file_name(std::string_view name);

// Segment ids present in `dir`, ascending.
Result<std::vector<uint64_t>> segment_ids(Env* env, const std::string& dir);

uint64_t fnv1a64(std::string_view s);

// One record's place in a segment.
struct IndexEntry {
  uint64_t seq = 0;
  uint64_t offset = 0;  // of the line's first byte
  uint64_t len = 0;     // without the newline
  int64_t ts = 0;
  uint64_t mid_hash = 0;
  uint64_t wm_hash = 0;
  bool has_wm = false;
};

// What the index file header says about a sealed segment.
struct IndexHeader {
  uint64_t count = 0;
  uint64_t first_seq = 0;
  uint64_t last_seq = 0;
  int64_t min_ts = 0;
  int64_t max_ts = 0;
  uint64_t wm_count = 0;
};

inline constexpr size_t kIndexHeaderBytes = 64;
inline constexpr size_t kIndexEntryBytes = 32;  // table A: seq, offset, len, ts
inline constexpr size_t kIndexHashBytes = 16;   // tables B, C: hash, seq

// Serialises the index of a sealed segment (entries in seq order, contiguous seqs).
std::string build_index(const std::vector<IndexEntry>& entries);
// Reads and checks the header (magic, check word, file size). nullopt when unusable.
std::optional<IndexHeader> read_index_header(Env* env, const std::string& path);
// Table A entry i (0-based).
Result<IndexEntry> read_index_entry(Env* env, const std::string& path, const IndexHeader& h,
                                    uint64_t i);
// Table A in full.
Result<std::vector<IndexEntry>> read_index_entries(Env* env, const std::string& path,
                                                   const IndexHeader& h);
// Seqs whose message_id (table B) or watermark (table C) hash equals `hash`.
Result<std::vector<uint64_t>> index_lookup(Env* env, const std::string& path, const IndexHeader& h,
                                           bool watermark, uint64_t hash);

// Calls fn(offset, line) for each newline-terminated line in [0, limit) of `path`
// (limit = UINT64_MAX: whole file). A final line without newline is passed to
// `partial` when given (offset, bytes), else ignored. fn returns false to stop.
// Reading stops at a NUL byte in an unterminated line (preallocated zero space); the
// bytes before it, if any, are the partial line.
Status for_each_line(Env* env, const std::string& path, uint64_t limit,
                     const std::function<bool(uint64_t, std::string_view)>& fn,
                     const std::function<void(uint64_t, std::string_view)>& partial = {});

// Fields the indexes need, from a parsed record.
struct RecordKeys {
  uint64_t seq = 0;
  int64_t ts = 0;
  std::string message_id;
  std::optional<std::string> watermark;
  std::string kind;
};
std::optional<RecordKeys> record_keys(const json::Value& rec);

json::ParseOptions record_parse_options();

}  // namespace rcan::audit::internal
