#include "audit/segment.h"

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace rcan::audit::internal {
namespace {

constexpr char kMagic[8] = {'R', 'C', 'A', 'N', 'A', 'I', 'X', '1'};

void put64(std::string& out, uint64_t v) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
uint64_t get64(const char* p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}

uint64_t expected_size(const IndexHeader& h) {
  return kIndexHeaderBytes + h.count * (kIndexEntryBytes + kIndexHashBytes) +
         h.wm_count * kIndexHashBytes;
}

}  // namespace

std::string segment_file_name(uint64_t id) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "seg-%08llu.log", static_cast<unsigned long long>(id));
  return buf;
}

std::string index_file_name(uint64_t id) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "seg-%08llu.idx", static_cast<unsigned long long>(id));
  return buf;
}

std::optional<uint64_t> parse_segment_file_name(std::string_view name) {
  if (name.size() != 16 || name.substr(0, 4) != "seg-" || name.substr(12) != ".log") return {};
  uint64_t v = 0;
  for (char c : name.substr(4, 8)) {
    if (c < '0' || c > '9') return {};
    v = v * 10 + static_cast<uint64_t>(c - '0');
  }
  if (v == 0) return {};
  return v;
}

Result<std::vector<uint64_t>> segment_ids(Env* env, const std::string& dir) {
  auto names = env->children(dir);
  if (!names.ok()) return names.error();
  std::vector<uint64_t> ids;
  for (const auto& n : *names) {
    if (auto id = parse_segment_file_name(n)) ids.push_back(*id);
  }
  std::sort(ids.begin(), ids.end());
  return ids;
}

uint64_t fnv1a64(std::string_view s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

std::string build_index(const std::vector<IndexEntry>& entries) {
  IndexHeader h;
  h.count = entries.size();
  if (!entries.empty()) {
    h.first_seq = entries.front().seq;
    h.last_seq = entries.back().seq;
    h.min_ts = entries.front().ts;
    h.max_ts = entries.front().ts;
  }
  std::vector<std::pair<uint64_t, uint64_t>> mids, wms;
  mids.reserve(entries.size());
  for (const auto& e : entries) {
    h.min_ts = std::min(h.min_ts, e.ts);
    h.max_ts = std::max(h.max_ts, e.ts);
    mids.emplace_back(e.mid_hash, e.seq);
    if (e.has_wm) wms.emplace_back(e.wm_hash, e.seq);
  }
  h.wm_count = wms.size();
  std::sort(mids.begin(), mids.end());
  std::sort(wms.begin(), wms.end());
  std::string out;
  out.reserve(expected_size(h));
  out.append(kMagic, 8);
  put64(out, h.count);
  put64(out, h.first_seq);
  put64(out, h.last_seq);
  put64(out, static_cast<uint64_t>(h.min_ts));
  put64(out, static_cast<uint64_t>(h.max_ts));
  put64(out, h.wm_count);
  put64(out, fnv1a64(out));
  for (const auto& e : entries) {
    put64(out, e.seq);
    put64(out, e.offset);
    put64(out, e.len);
    put64(out, static_cast<uint64_t>(e.ts));
  }
  for (const auto& [hash, seq] : mids) {
    put64(out, hash);
    put64(out, seq);
  }
  for (const auto& [hash, seq] : wms) {
    put64(out, hash);
    put64(out, seq);
  }
  return out;
}

std::optional<IndexHeader> read_index_header(Env* env, const std::string& path) {
  if (!env->exists(path)) return {};
  auto head = env->read_range(path, 0, kIndexHeaderBytes);
  if (!head.ok() || head->size() != kIndexHeaderBytes) return {};
  const char* p = head->data();
  if (std::memcmp(p, kMagic, 8) != 0) return {};
  if (get64(p + 56) != fnv1a64(std::string_view(p, 56))) return {};
  IndexHeader h;
  h.count = get64(p + 8);
  h.first_seq = get64(p + 16);
  h.last_seq = get64(p + 24);
  h.min_ts = static_cast<int64_t>(get64(p + 32));
  h.max_ts = static_cast<int64_t>(get64(p + 40));
  h.wm_count = get64(p + 48);
  if (h.count == 0 || h.last_seq - h.first_seq + 1 != h.count || h.wm_count > h.count) return {};
  if (h.count > (uint64_t{1} << 40)) return {};  // expected_size() must not wrap around
  auto size = env->file_size(path);
  if (!size.ok() || *size != expected_size(h)) return {};
  return h;
}

Result<IndexEntry> read_index_entry(Env* env, const std::string& path, const IndexHeader& h,
                                    uint64_t i) {
  auto r = env->read_range(path, kIndexHeaderBytes + i * kIndexEntryBytes, kIndexEntryBytes);
  if (!r.ok()) return r.error();
  if (r->size() != kIndexEntryBytes || i >= h.count)
    return Error(ErrorCode::kAuditUnavailable, "short index read in " + path);
  IndexEntry e;
  e.seq = get64(r->data());
  e.offset = get64(r->data() + 8);
  e.len = get64(r->data() + 16);
  e.ts = static_cast<int64_t>(get64(r->data() + 24));
  return e;
}

Result<std::vector<IndexEntry>> read_index_entries(Env* env, const std::string& path,
                                                   const IndexHeader& h) {
  auto r = env->read_range(path, kIndexHeaderBytes, h.count * kIndexEntryBytes);
  if (!r.ok()) return r.error();
  if (r->size() != h.count * kIndexEntryBytes)
    return Error(ErrorCode::kAuditUnavailable, "short index read in " + path);
  std::vector<IndexEntry> out(h.count);
  for (uint64_t i = 0; i < h.count; ++i) {
    const char* p = r->data() + i * kIndexEntryBytes;
    out[i].seq = get64(p);
    out[i].offset = get64(p + 8);
    out[i].len = get64(p + 16);
    out[i].ts = static_cast<int64_t>(get64(p + 24));
  }
  return out;
}

Result<std::vector<uint64_t>> index_lookup(Env* env, const std::string& path, const IndexHeader& h,
                                           bool watermark, uint64_t hash) {
  uint64_t base = kIndexHeaderBytes + h.count * kIndexEntryBytes;
  uint64_t n = h.count;
  if (watermark) {
    base += h.count * kIndexHashBytes;
    n = h.wm_count;
  }
  auto at = [&](uint64_t i) -> Result<std::pair<uint64_t, uint64_t>> {
    auto r = env->read_range(path, base + i * kIndexHashBytes, kIndexHashBytes);
    if (!r.ok()) return r.error();
    if (r->size() != kIndexHashBytes)
      return Error(ErrorCode::kAuditUnavailable, "short index read in " + path);
    return std::make_pair(get64(r->data()), get64(r->data() + 8));
  };
  // lower_bound on hash
  uint64_t lo = 0, hi = n;
  while (lo < hi) {
    uint64_t mid = lo + (hi - lo) / 2;
    auto v = at(mid);
    if (!v.ok()) return v.error();
    if (v->first < hash) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  std::vector<uint64_t> seqs;
  for (uint64_t i = lo; i < n; ++i) {
    auto v = at(i);
    if (!v.ok()) return v.error();
    if (v->first != hash) break;
    seqs.push_back(v->second);
  }
  return seqs;
}

Status for_each_line(Env* env, const std::string& path, uint64_t limit,
                     const std::function<bool(uint64_t, std::string_view)>& fn,
                     const std::function<void(uint64_t, std::string_view)>& partial) {
  constexpr size_t kChunk = 4 << 20;
  std::string carry;
  uint64_t carry_offset = 0;
  uint64_t pos = 0;
  for (;;) {
    size_t want = kChunk;
    if (limit != UINT64_MAX) {
      if (pos >= limit) break;
      want = static_cast<size_t>(std::min<uint64_t>(kChunk, limit - pos));
    }
    auto chunk = env->read_range(path, pos, want);
    if (!chunk.ok()) return chunk.error();
    if (chunk->empty()) break;
    uint64_t chunk_start = pos;
    pos += chunk->size();
    std::string_view c(*chunk);
    size_t start = 0;
    for (;;) {
      size_t nl = c.find('\n', start);
      if (nl == std::string_view::npos) break;
      if (!carry.empty()) {
        carry.append(c.substr(start, nl - start));
        if (!fn(carry_offset, carry)) return Status::Ok();
        carry.clear();
      } else {
        if (!fn(chunk_start + start, c.substr(start, nl - start))) return Status::Ok();
      }
      start = nl + 1;
    }
    bool ended = false;
    if (start < c.size()) {
      std::string_view rest = c.substr(start);
      if (carry.empty()) carry_offset = chunk_start + start;
      // A NUL in the unterminated remainder: preallocated (zero) space or a hole left by
      // a crash. The data ends here.
      size_t z = rest.find('\0');
      if (z != std::string_view::npos) {
        rest = rest.substr(0, z);
        ended = true;
      }
      carry.append(rest);
    }
    if (ended || chunk->size() < want) break;
  }
  if (!carry.empty() && partial) partial(carry_offset, carry);
  return Status::Ok();
}

std::optional<RecordKeys> record_keys(const json::Value& rec) {
  if (!rec.is_object()) return {};
  RecordKeys k;
  const json::Value* seq = rec.get("seq");
  if (!seq || !seq->is_int() || seq->as_int() < 1) return {};
  k.seq = static_cast<uint64_t>(seq->as_int());
  const json::Value* ts = rec.get("timestamp_ms");
  if (ts && ts->is_int()) k.ts = ts->as_int();
  const json::Value* mid = rec.get("message_id");
  if (mid && mid->is_string()) k.message_id = mid->as_string();
  const json::Value* wm = rec.get("watermark_token");
  if (wm && wm->is_string()) k.watermark = wm->as_string();
  const json::Value* kind = rec.get("kind");
  if (kind && kind->is_string()) k.kind = kind->as_string();
  return k;
}

json::ParseOptions record_parse_options() {
  json::ParseOptions o;
  o.max_bytes = 4u << 20;
  o.max_string_bytes = 4u << 20;
  return o;
}

}  // namespace rcan::audit::internal
