// GET /api/audit's query: parameters, the seq range of a time window, the scan (audit_query.h).
#include "node/api/audit_query.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <vector>

#include "base/strings.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

Error bad(const std::string& field, const std::string& why) {
  return Error(ErrorCode::kSchemaValidationFailed, field + ": " + why, field);
}

bool parse_u64(std::string_view s, uint64_t& out) {
  if (s.empty() || s.size() > 19) return false;
  uint64_t v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + static_cast<uint64_t>(c - '0');
  }
  out = v;
  return true;
}

// Case-insensitive substring; `needle` is already lower case.
bool contains_folded(std::string_view hay, const std::string& needle) {
  if (needle.empty()) return true;
  if (hay.size() < needle.size()) return false;
  auto it = std::search(hay.begin(), hay.end(), needle.begin(), needle.end(), [](char a, char b) {
    return std::tolower(static_cast<unsigned char>(a)) == b;
  });
  return it != hay.end();
}

std::vector<std::string> split_commas(std::string_view s) {
  std::vector<std::string> out;
  for (std::string_view field : split(s, ',', /*keep_empty=*/false)) out.emplace_back(field);
  return out;
}

// The compiled filters of a query, applied to one stored record.
struct Matcher {
  explicit Matcher(const AuditQuery& q)
      : q_(q),
        events_(split_commas(q.event)),
        principal_(ascii_lower(q.principal)),
        text_(ascii_lower(q.text)) {}
  // Cheap test on the raw line, before parsing it.
  bool line_may_match(std::string_view line) const { return contains_folded(line, text_); }
  bool matches(const json::Value& v) const {
    const int64_t ts = json::int_field(v, "timestamp_ms");
    if (q_.from_ms > 0 && ts < q_.from_ms) return false;
    if (q_.to_ms > 0 && ts > q_.to_ms) return false;
    if (!events_.empty() &&
        std::find(events_.begin(), events_.end(), json::string_field(v, "event")) == events_.end())
      return false;
    if (!q_.outcome.empty() && json::string_field(v, "outcome") != q_.outcome) return false;
    if (!q_.message_id.empty() && json::string_field(v, "message_id") != q_.message_id)
      return false;
    if (!principal_.empty() && !contains_folded(json::string_field(v, "principal"), principal_) &&
        !contains_folded(json::string_field(v, "sub"), principal_))
      return false;
    return true;
  }

 private:
  const AuditQuery& q_;
  std::vector<std::string> events_;
  std::string principal_;
  std::string text_;
};

std::optional<json::Value> parse_line(std::string_view line) {
  auto v = json::parse(line, {.max_depth = 64, .max_bytes = 1u << 20});
  if (!v.ok()) return std::nullopt;
  return std::move(v).value();
}

// The record's timestamp, or nothing when it cannot be read.
std::optional<int64_t> ts_of(const audit::AuditLog& log, uint64_t seq) {
  auto line = log.get(seq);
  if (!line.ok()) return std::nullopt;
  auto v = parse_line(*line);
  if (!v) return std::nullopt;
  return json::int_field(*v, "timestamp_ms");
}

// The first seq in [lo, hi] whose record is at or after `ts_ms` (records are in time order
// unless the clock stepped back; the filter still checks each record's own time). hi + 1 when
// none is.
uint64_t first_at_or_after(const audit::AuditLog& log, uint64_t lo, uint64_t hi, int64_t ts_ms) {
  uint64_t a = lo, b = hi + 1;
  while (a < b) {
    uint64_t mid = a + (b - a) / 2;
    auto ts = ts_of(log, mid);
    if (ts && *ts < ts_ms)
      a = mid + 1;
    else
      b = mid;
  }
  return a;
}

void take(AuditPage& page, const Matcher& m, std::string_view line, uint64_t seq, bool& taken) {
  taken = false;
  if (!m.line_may_match(line)) return;
  auto v = parse_line(line);
  if (!v) {
    if (page.first_error.empty()) page.first_error = "stored record is not JSON";
    page.unreadable.emplace_back(static_cast<int64_t>(seq));
    return;
  }
  if (!m.matches(*v)) return;
  page.entries.push_back(std::move(*v));
  taken = true;
}

}  // namespace

Result<size_t> parse_limit(std::optional<std::string_view> value, size_t default_limit,
                           size_t max) {
  if (!value) return default_limit;
  uint64_t n = 0;
  if (!parse_u64(*value, n) || n < 1 || n > max)
    return bad("limit", "must be 1.." + std::to_string(max));
  return static_cast<size_t>(n);
}

json::Object AuditQuery::to_json() const {
  json::Object o{{"limit", static_cast<int64_t>(limit)}};
  if (before) o.set("before", static_cast<int64_t>(before));
  if (after) o.set("after", static_cast<int64_t>(after));
  if (from_ms) o.set("from", from_ms);
  if (to_ms) o.set("to", to_ms);
  for (auto [k, v] : {std::pair{"event", &event}, std::pair{"outcome", &outcome},
                      std::pair{"principal", &principal}, std::pair{"message_id", &message_id},
                      std::pair{"q", &text}})
    if (!v->empty()) o.set(k, *v);
  return o;
}

Result<AuditQuery> parse_audit_query(
    const std::function<std::optional<std::string_view>(std::string_view)>& param,
    size_t default_limit) {
  AuditQuery q;
  q.limit = default_limit;
  auto limit = parse_limit(param("limit"), default_limit, 1000);
  if (!limit.ok()) return limit.error();
  q.limit = *limit;
  for (auto [name, dest] : {std::pair{"before", &q.before}, std::pair{"after", &q.after}}) {
    if (auto v = param(name)) {
      if (!parse_u64(*v, *dest) || *dest == 0)
        return bad(name, "must be a record's seq (1 or more)");
    }
  }
  if (q.before && q.after) return bad("after", "before and after cannot be combined");
  for (auto [name, dest] : {std::pair{"from", &q.from_ms}, std::pair{"to", &q.to_ms}}) {
    if (auto v = param(name)) {
      uint64_t n = 0;
      if (!parse_u64(*v, n) || n > 100'000'000'000'000ULL)
        return bad(name, "must be Unix seconds or milliseconds");
      *dest = static_cast<int64_t>(n < 100'000'000'000ULL ? n * 1000 : n);
    }
  }
  if (q.from_ms && q.to_ms && q.from_ms > q.to_ms) return bad("from", "is later than to");
  struct Text {
    const char* name;
    std::string* dest;
    size_t max;
  } texts[] = {{"event", &q.event, 512},
               {"outcome", &q.outcome, 32},
               {"principal", &q.principal, 256},
               {"message_id", &q.message_id, 128},
               {"q", &q.text, 256}};
  for (const auto& t : texts) {
    auto v = param(t.name);
    if (!v) continue;
    if (v->size() > t.max) return bad(t.name, "longer than " + std::to_string(t.max) + " bytes");
    for (unsigned char c : *v)
      if (c < 0x20 || c == 0x7f) return bad(t.name, "has a control character");
    *t.dest = std::string(*v);
  }
  return q;
}

AuditPage run_audit_query(const audit::AuditLog& log, const AuditQuery& q) {
  AuditPage page;
  const audit::AuditStats st = log.stats();
  if (st.last_seq == 0) return page;
  const Matcher m(q);
  bool taken = false;

  if (!q.message_id.empty()) {  // the sidecar index: every record of that message
    auto lines = log.find_by_message_id(q.message_id);
    if (!lines.ok()) {
      page.first_error = lines.error().message;
      return page;
    }
    std::vector<std::pair<uint64_t, std::string>> found;
    for (const auto& line : *lines) {
      auto v = parse_line(line);
      const uint64_t seq = v ? static_cast<uint64_t>(json::int_field(*v, "seq")) : 0;
      if ((q.before && seq >= q.before) || (q.after && seq <= q.after)) continue;
      found.emplace_back(seq, line);
    }
    page.scanned = found.size();
    if (found.size() > q.limit) {  // the newest `limit` (oldest first for after=)
      if (q.after)
        found.resize(q.limit);
      else
        found.erase(found.begin(), found.end() - static_cast<std::ptrdiff_t>(q.limit));
      if (!q.after) page.next_before = found.front().first;
    }
    for (const auto& [seq, line] : found) take(page, m, line, seq, taken);
    return page;
  }

  uint64_t lo = std::max<uint64_t>(st.first_seq, 1), hi = st.last_seq;
  if (q.before) hi = std::min(hi, q.before - 1);
  if (q.after) lo = std::max(lo, q.after + 1);
  if (lo > hi) return page;
  if (q.from_ms > 0) lo = first_at_or_after(log, lo, hi, q.from_ms);
  if (q.to_ms > 0 && lo <= hi) {
    const uint64_t past = first_at_or_after(log, lo, hi, q.to_ms + 1);
    if (past == 0) return page;
    hi = past - 1;
  }
  if (lo > hi) return page;

  auto visit = [&](uint64_t seq) {
    ++page.scanned;
    auto line = log.get(seq);
    if (!line.ok()) {
      // Removed by retention since stats() was read: gone by design, not a failed check.
      if (line.error().code == ErrorCode::kNotFound) return;
      if (page.first_error.empty()) page.first_error = line.error().message;
      page.unreadable.emplace_back(static_cast<int64_t>(seq));
      return;
    }
    take(page, m, *line, seq, taken);
  };
  if (q.after) {  // oldest first, from just after the cursor
    for (uint64_t seq = lo; seq <= hi; ++seq) {
      if (page.entries.size() >= q.limit) break;
      if (page.scanned >= q.scan_budget) {
        page.complete = false;
        break;
      }
      visit(seq);
    }
    return page;
  }
  // Newest first, then put back in seq order.
  uint64_t seq = hi;
  for (; seq >= lo && seq != 0; --seq) {
    if (page.entries.size() >= q.limit) break;
    if (page.scanned >= q.scan_budget) {
      page.complete = false;
      break;
    }
    visit(seq);
  }
  // `seq` is the next one to examine (or lo - 1 when the range is done).
  if (seq >= lo && seq != 0) page.next_before = seq + 1;
  std::reverse(page.entries.begin(), page.entries.end());
  return page;
}

}  // namespace rcan::node
