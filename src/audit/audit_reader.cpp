// The audit log's read side (include/rcan/audit/audit_log.h: export_range, find_by_*, get,
// stats; export_dir and list_segments offline).
//
// Contract: a query reads a snapshot of what was durable when it started (taken under
// state_mu_), so appends, rotation and the indexer go on meanwhile; retention removes no file
// while a query runs (readers_). Records are located through the in-memory entries (exact) or
// a sealed segment's .idx (not covered by the chain: a damaged entry sends the read to the
// segment itself, counted in index_fallbacks), and a record that fails its HMAC is refused,
// never returned.
#include <algorithm>
#include <atomic>

#include "audit/audit_log_impl.h"

namespace rcan::audit {

using internal::IndexEntry;

AuditLog::Impl::Snapshot AuditLog::Impl::snapshot() const {
  Snapshot s;
  MutexLock l(state_mu_);
  s.sealed = sealed_;
  s.active_id = active_id_;
  s.active_durable = durable_offset_;
  s.active = active_index_;
  return s;
}

Result<std::vector<IndexEntry>> AuditLog::Impl::entries_of(const Segment& s) const {
  if (s.mem) return *s.mem;
  if (s.header) return internal::read_index_entries(env_, idx_path(s.id), *s.header);
  return unavailable("audit log: no index for segment " + std::to_string(s.id));
}

Result<std::string> AuditLog::Impl::read_line(uint64_t seg_id, const IndexEntry& e) const {
  auto r = env_->read_range(seg_path(seg_id), e.offset, static_cast<size_t>(e.len));
  if (!r.ok()) return r.error();
  if (r->size() != e.len) return unavailable("audit log: short read in segment");
  return std::move(*r);
}

namespace {
struct ReaderGuard {
  explicit ReaderGuard(std::atomic<int>& c) : c_(c) { ++c_; }
  ~ReaderGuard() { --c_; }
  std::atomic<int>& c_;
};
}  // namespace

// A ranged export is a contiguous slice of the chain: from the first record whose
// timestamp is in [from, to] to the last such record, including whatever lies between
// (e.g. checkpoints), so that it verifies with allow_partial_start.
namespace {
class SliceEmitter {
 public:
  SliceEmitter(int64_t from, int64_t to, const AuditLog::LineSink& sink)
      : from_(from), to_(to), sink_(sink) {}
  bool started() const { return started_; }
  bool stopped() const { return stopped_; }
  // Returns false to stop reading.
  bool line(std::string_view l, int64_t ts) {
    bool in = ts >= from_ && ts <= to_;
    if (!started_) {
      if (!in) return true;
      started_ = true;
    }
    if (!in) {
      held_.emplace_back(l);
      return true;
    }
    for (const auto& h : held_) {
      if (!sink_(h)) return stop();
    }
    held_.clear();
    if (!sink_(l)) return stop();
    return true;
  }

 private:
  bool stop() {
    stopped_ = true;
    return false;
  }
  int64_t from_, to_;
  const AuditLog::LineSink& sink_;
  bool started_ = false;
  bool stopped_ = false;
  std::vector<std::string> held_;
};
}  // namespace

Status AuditLog::Impl::export_range(int64_t from, int64_t to, const LineSink& sink) const {
  ReaderGuard guard(readers_);
  Snapshot snap = snapshot();
  struct Part {
    uint64_t id;
    uint64_t limit;
    int64_t min_ts, max_ts;
    const Segment* seg;  // null for the active segment
  };
  std::vector<Part> parts;
  for (const auto& seg : snap.sealed)
    parts.push_back({seg.id, UINT64_MAX, seg.min_ts, seg.max_ts, &seg});
  if (!snap.active.empty()) {
    int64_t mn = snap.active.front().ts, mx = mn;
    for (const auto& e : snap.active) {
      mn = std::min(mn, e.ts);
      mx = std::max(mx, e.ts);
    }
    parts.push_back({snap.active_id, snap.active_durable, mn, mx, nullptr});
  }
  // later_overlap[i]: some part at index >= i has a record in range.
  std::vector<bool> later_overlap(parts.size() + 1, false);
  for (size_t i = parts.size(); i-- > 0;)
    later_overlap[i] = later_overlap[i + 1] || !(parts[i].max_ts < from || parts[i].min_ts > to);
  SliceEmitter out(from, to, sink);
  for (size_t i = 0; i < parts.size() && !out.stopped(); ++i) {
    if (!later_overlap[i]) break;
    const Part& p = parts[i];
    bool overlap = !(p.max_ts < from || p.min_ts > to);
    if (!out.started() && !overlap) continue;
    bool all_in = p.min_ts >= from && p.max_ts <= to;
    std::vector<IndexEntry> loaded;
    const std::vector<IndexEntry>* entries = nullptr;
    if (!all_in) {
      if (p.seg) {
        auto e = entries_of(*p.seg);
        if (!e.ok()) return e.error();
        loaded = std::move(*e);
        entries = &loaded;
      } else {
        entries = &snap.active;
      }
    }
    size_t k = 0;
    Status s = internal::for_each_line(
        env_, seg_path(p.id), p.limit, [&](uint64_t, std::string_view line) {
          int64_t ts = all_in ? from : (k < entries->size() ? (*entries)[k].ts : INT64_MIN);
          ++k;
          return out.line(line, ts);
        });
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

Result<std::vector<std::string>> AuditLog::Impl::find(bool watermark, std::string_view key) const {
  ReaderGuard guard(readers_);
  Snapshot snap = snapshot();
  uint64_t h = internal::fnv1a64(key);
  std::vector<std::string> out;
  auto consider_line = [&](uint64_t seq, Result<std::string> line) -> Status {
    if (!line.ok()) return line.error();
    auto v = json::parse(*line, internal::record_parse_options());
    if (!v.ok() || !v->is_object()) return Status::Ok();
    const json::Value* f = v->get(watermark ? "watermark_token" : "message_id");
    if (!f || !f->is_string() || f->as_string() != key) return Status::Ok();  // hash collision
    if (!check_record(v->as_object(), opts_.secret).hmac_ok)
      return unavailable("audit log: record at seq " + std::to_string(seq) + " fails its hmac");
    out.push_back(std::move(*line));
    return Status::Ok();
  };
  auto consider = [&](uint64_t seg_id, const IndexEntry& e) {
    return consider_line(e.seq, read_line(seg_id, e));
  };
  auto scan_mem = [&](uint64_t seg_id, const std::vector<IndexEntry>& entries) -> Status {
    for (const auto& e : entries) {
      if (watermark ? (e.has_wm && e.wm_hash == h) : e.mid_hash == h) {
        Status s = consider(seg_id, e);
        if (!s.ok()) return s;
      }
    }
    return Status::Ok();
  };
  for (const auto& seg : snap.sealed) {
    Status s;
    if (seg.mem) {
      s = scan_mem(seg.id, *seg.mem);
    } else if (seg.header) {
      auto seqs = internal::index_lookup(env_, idx_path(seg.id), *seg.header, watermark, h);
      if (!seqs.ok()) return seqs.error();
      for (uint64_t seq : *seqs) {
        if (seq < seg.header->first_seq || seq > seg.header->last_seq)
          continue;  // a damaged hash table
        // A damaged entry is looked up in the segment, not trusted (the HMAC is checked below,
        // after the key: a hash collision is a miss, not an error).
        s = consider_line(
            seq, sealed_line(seg.id,
                             internal::read_index_entry(env_, idx_path(seg.id), *seg.header,
                                                        seq - seg.header->first_seq),
                             seq, false));
        if (!s.ok()) break;
      }
    }
    if (!s.ok()) return s.error();
  }
  Status s = scan_mem(snap.active_id, snap.active);
  if (!s.ok()) return s.error();
  return out;
}

Result<std::string> AuditLog::Impl::get(uint64_t seq) const {
  ReaderGuard guard(readers_);
  // Only what locates this one record is copied under the lock (not the active segment's
  // whole index, which made a page of reads quadratic in the segment's size).
  std::optional<Segment> sealed;
  std::optional<IndexEntry> active;
  uint64_t active_id = 0;
  {
    MutexLock l(state_mu_);
    for (const auto& seg : sealed_) {
      if (seq < seg.first_seq || seq > seg.last_seq) continue;
      if (seg.mem || seg.header) {
        sealed = seg;
        break;
      }
    }
    if (!sealed && !active_index_.empty() && seq >= active_index_.front().seq &&
        seq <= active_index_.back().seq) {
      active = active_index_[seq - active_index_.front().seq];
      active_id = active_id_;
    }
  }
  if (sealed && sealed->mem)
    return exact_line(read_line(sealed->id, (*sealed->mem)[seq - sealed->first_seq]), seq);
  if (sealed)
    return sealed_line(sealed->id,
                       internal::read_index_entry(env_, idx_path(sealed->id), *sealed->header,
                                                  seq - sealed->first_seq),
                       seq, true);
  if (active) return exact_line(read_line(active_id, *active), seq);
  return Error(ErrorCode::kNotFound, "no audit record with seq " + std::to_string(seq));
}

// Whether `line` is the record with this seq (and, with verify_hmac, verifies with the secret).
AuditLog::Impl::LineCheck AuditLog::Impl::check_line(std::string_view line, uint64_t seq,
                                                     bool verify_hmac) const {
  auto v = json::parse(line, internal::record_parse_options());
  if (!v.ok() || !v->is_object()) return LineCheck::kOtherLine;
  auto k = internal::record_keys(*v);
  if (!k || k->seq != seq) return LineCheck::kOtherLine;
  if (verify_hmac && !check_record(v->as_object(), opts_.secret).hmac_ok)
    return LineCheck::kBadHmac;
  return LineCheck::kOk;
}

Error AuditLog::Impl::hmac_refusal(uint64_t seq) {
  return unavailable("audit log: record at seq " + std::to_string(seq) + " fails its hmac");
}

// A line read through an in-memory entry (the active segment, or a sealed one whose .idx is
// not written yet): the entry is exact, so a line that is not the verifying record means the
// file changed under the log. Refused, never returned.
Result<std::string> AuditLog::Impl::exact_line(Result<std::string> line, uint64_t seq) const {
  if (!line.ok()) return line;
  switch (check_line(*line, seq, true)) {
    case LineCheck::kOk:
      return line;
    case LineCheck::kBadHmac:
      return hmac_refusal(seq);
    case LineCheck::kOtherLine:
      break;
  }
  return unavailable("audit log: the stored line for seq " + std::to_string(seq) +
                     " is not that record");
}

// Record `seq` of a sealed segment through its .idx entry. The index file is not covered by the
// chain, so a damaged entry (wrong offset, length or seq) must make the answer slower, never
// wrong: when the entry does not lead to the record with that seq, the record is looked for in
// the segment itself (counted in index_fallbacks). With verify_hmac, a record that fails its HMAC
// is refused, never returned (find() checks the HMAC itself, after comparing its key).
Result<std::string> AuditLog::Impl::sealed_line(uint64_t seg_id, Result<IndexEntry> e, uint64_t seq,
                                                bool verify_hmac) const {
  if (e.ok()) {
    auto line = read_line(seg_id, *e);
    if (line.ok()) {
      switch (check_line(*line, seq, verify_hmac)) {
        case LineCheck::kOk:
          return line;
        case LineCheck::kBadHmac:
          return hmac_refusal(seq);
        case LineCheck::kOtherLine:
          break;
      }
    }
  }
  index_fallbacks_.fetch_add(1, std::memory_order_relaxed);
  std::optional<std::string> found;
  Status s = internal::for_each_line(env_, seg_path(seg_id), UINT64_MAX,
                                     [&](uint64_t, std::string_view line) {
                                       // Records are in seq order: stop at the first one at or past
                                       // `seq`.
                                       auto v = json::parse(line, internal::record_parse_options());
                                       auto k = v.ok() ? internal::record_keys(*v) : std::nullopt;
                                       if (!k || k->seq < seq) return true;
                                       if (k->seq == seq) found.emplace(line);
                                       return false;
                                     });
  if (!s.ok()) return s.error();
  if (!found)
    return unavailable("audit log: seq " + std::to_string(seq) +
                       " is missing from sealed segment " + internal::segment_file_name(seg_id));
  if (check_line(*found, seq, verify_hmac) != LineCheck::kOk) return hmac_refusal(seq);
  return std::move(*found);
}

AuditStats AuditLog::Impl::stats() const {
  AuditStats st;
  {
    MutexLock l(state_mu_);
    st.first_seq = !sealed_.empty()         ? sealed_.front().first_seq
                   : !active_index_.empty() ? active_index_.front().seq
                                            : 0;
    st.last_seq = durable_seq_;
    st.last_hash = durable_hash_;
    st.segments = sealed_.size() + 1;
    st.active_segment = active_id_;
    st.total_bytes = durable_offset_;
    for (const auto& s : sealed_) st.total_bytes += s.bytes;
  }
  MutexLock l(mu_);
  st.groups_committed = groups_.load();
  st.syncs = syncs_.load();
  st.failed = failed_.load();
  st.recoveries = recoveries_.load();
  st.index_fallbacks = index_fallbacks_.load(std::memory_order_relaxed);
  return st;
}

// ---------------------------------------------------------------- offline

Result<std::vector<std::string>> list_segments(const std::string& dir, Env* env) {
  if (!env) env = Env::posix();
  auto ids = internal::segment_ids(env, dir);
  if (!ids.ok()) return ids.error();
  std::vector<std::string> out;
  for (uint64_t id : *ids) out.push_back(dir + "/" + internal::segment_file_name(id));
  return out;
}

Status export_dir(const std::string& dir, int64_t from_ms, int64_t to_ms,
                  const AuditLog::LineSink& sink, Env* env) {
  if (!env) env = Env::posix();
  auto segs = list_segments(dir, env);
  if (!segs.ok()) return segs.error();
  if (segs->empty()) return Error(ErrorCode::kNotFound, "no audit segments in " + dir);
  bool everything = from_ms == INT64_MIN && to_ms == INT64_MAX;
  SliceEmitter out(from_ms, to_ms, sink);
  for (const auto& p : *segs) {
    if (out.stopped()) break;
    Status s = internal::for_each_line(env, p, UINT64_MAX, [&](uint64_t, std::string_view line) {
      int64_t ts = from_ms;
      if (!everything) {
        auto v = json::parse(line, internal::record_parse_options());
        const json::Value* t = v.ok() ? v->get("timestamp_ms") : nullptr;
        ts = t && t->is_int() ? t->as_int() : INT64_MIN;
      }
      return out.line(line, ts);
    });
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

}  // namespace rcan::audit
