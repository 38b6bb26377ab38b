#include "rcan/audit/verify.h"

#include <sstream>

#include "audit/segment.h"
#include "rcan/audit/audit_log.h"
#include "rcan/audit/record.h"
#include "rcan/hash.h"

namespace rcan::audit {

// ---------------------------------------------------------------- native chain

ChainVerifier::ChainVerifier(std::string secret, VerifyOptions options)
    : secret_(std::move(secret)), options_(options) {}

bool ChainVerifier::fail(uint64_t seq, std::string why) {
  failed_ = true;
  report_.ok = false;
  report_.first_bad_seq = seq;
  report_.first_bad_index = index_;
  report_.why = std::move(why);
  return false;
}

namespace {
const json::Value* detail_field(const json::Value& rec, std::string_view key) {
  const json::Value* d = rec.get("detail");
  return d ? d->get(key) : nullptr;
}
bool int_equals(const json::Value* v, uint64_t n) {
  return v && v->is_int() && v->as_int() >= 0 && static_cast<uint64_t>(v->as_int()) == n;
}
}  // namespace

bool ChainVerifier::add_line(std::string_view line) {
  if (failed_) return false;
  const uint64_t expected = last_seq_ + 1;  // meaningless (1) before the first record
  auto v = json::parse(line, internal::record_parse_options());
  if (!v.ok()) return fail(expected, "malformed line: " + v.error().message);
  if (!v->is_object()) return fail(expected, "malformed line: not a JSON object");
  const json::Value* seqv = v->get("seq");
  if (!seqv || !seqv->is_int() || seqv->as_int() < 1)
    return fail(expected, "malformed line: no positive integer seq");
  const uint64_t seq = static_cast<uint64_t>(seqv->as_int());
  const json::Value* ph = v->get("prev_hash");
  if (!ph || !(ph->is_null() || ph->is_string()))
    return fail(seq, "malformed line: prev_hash must be a string or null");
  const json::Value* kindv = v->get("kind");
  const bool checkpoint = kindv && kindv->is_string() && kindv->as_string() == "checkpoint";

  if (report_.count == 0) {
    if (seq == 1) {
      if (!ph->is_null()) return fail(seq, "bad chain start: seq 1 must have a null prev_hash");
    } else if (!checkpoint && !options_.allow_partial_start) {
      return fail(seq, "bad chain start: first record is seq " + std::to_string(seq) +
                           ", neither the genesis record (seq 1) nor a checkpoint");
    } else if (checkpoint && !ph->is_string()) {
      return fail(seq, "bad chain start: checkpoint without prev_hash");
    }
    report_.first_seq = seq;
  } else {
    if (seq != expected)
      return fail(expected, "seq gap: expected seq " + std::to_string(expected) + ", found " +
                                std::to_string(seq));
    if (!ph->is_string() || ph->as_string() != report_.last_hash)
      return fail(seq, "prev_hash mismatch: does not hash the record with seq " +
                           std::to_string(last_seq_));
  }

  RecordCheck chk = check_record(v->as_object(), secret_);
  if (!chk.hmac_present) return fail(seq, "hmac mismatch: record has no hmac");
  if (!chk.hmac_ok) return fail(seq, "hmac mismatch");

  if (checkpoint) {
    const json::Value* segv = v->get("segment");
    if (!segv || !segv->is_int() || segv->as_int() < 1)
      return fail(seq, "wrong segment link: checkpoint without a segment number");
    const uint64_t segment = static_cast<uint64_t>(segv->as_int());
    if (seq == 1) {
      if (segment != 1) return fail(seq, "wrong segment link: genesis checkpoint not in segment 1");
    } else {
      if (!int_equals(detail_field(*v, "prev_last_seq"), seq - 1))
        return fail(seq, "wrong segment link: checkpoint prev_last_seq is not seq " +
                             std::to_string(seq - 1));
      const json::Value* plh = detail_field(*v, "prev_last_hash");
      if (!plh || !plh->is_string() || plh->as_string() != ph->as_string())
        return fail(seq, "wrong segment link: checkpoint prev_last_hash differs from prev_hash");
      if (segment_ != 0 &&
          (segment != segment_ + 1 || !int_equals(detail_field(*v, "prev_segment"), segment_)))
        return fail(seq, "wrong segment link: segment " + std::to_string(segment) +
                             " does not follow segment " + std::to_string(segment_));
    }
    if (expect_segment_ != 0 && segment != expect_segment_)
      return fail(seq, "wrong segment link: segment file " + std::to_string(expect_segment_) +
                           " opens with the checkpoint of segment " + std::to_string(segment));
    segment_ = segment;
  } else if (expect_segment_ != 0) {
    return fail(seq, "wrong segment link: segment file " + std::to_string(expect_segment_) +
                         " does not open with its checkpoint");
  }
  expect_segment_ = 0;

  ++report_.count;
  ++index_;
  last_seq_ = seq;
  report_.last_seq = seq;
  report_.last_hash = chk.record_hash;
  return true;
}

const VerifyReport& ChainVerifier::finish() {
  if (failed_) return report_;
  if (report_.count == 0) {
    fail(1, "malformed line: no records");
    return report_;
  }
  if (options_.expect_last_seq && *options_.expect_last_seq != last_seq_) {
    fail(last_seq_ + 1, "truncated: last seq is " + std::to_string(last_seq_) + ", expected " +
                            std::to_string(*options_.expect_last_seq));
    return report_;
  }
  report_.ok = true;
  return report_;
}

VerifyReport verify_jsonl(std::string_view text, std::string_view secret, VerifyOptions options) {
  ChainVerifier v{std::string(secret), options};
  size_t start = 0;
  while (start < text.size()) {
    size_t nl = text.find('\n', start);
    std::string_view line =
        nl == std::string_view::npos ? text.substr(start) : text.substr(start, nl - start);
    if (!v.add_line(line)) break;
    if (nl == std::string_view::npos) break;
    start = nl + 1;
  }
  return v.finish();
}

VerifyReport verify_jsonl(std::istream& in, std::string_view secret, VerifyOptions options) {
  ChainVerifier v{std::string(secret), options};
  std::string line;
  while (std::getline(in, line)) {
    if (!v.add_line(line)) break;
  }
  return v.finish();
}

VerifyReport verify_dir(const std::string& dir, std::string_view secret) {
  ChainVerifier v{std::string(secret)};
  Env* env = Env::posix();
  auto ids = internal::segment_ids(env, dir);
  if (!ids.ok() || ids->empty()) {
    VerifyReport r;
    r.why = "malformed line: no audit segments in " + dir;
    return r;
  }
  for (uint64_t id : *ids) {
    v.expect_segment_start(id);
    bool go = true;
    Status s = internal::for_each_line(
        env, dir + "/" + internal::segment_file_name(id), UINT64_MAX,
        [&](uint64_t, std::string_view line) { return go = v.add_line(line); },
        [&](uint64_t, std::string_view line) { go = v.add_line(line); });
    if (!s.ok()) {
      VerifyReport r = v.report();
      r.ok = false;
      r.why = "malformed line: " + s.error().message;
      return r;
    }
    if (!go) break;
  }
  return v.finish();
}

// ---------------------------------------------------------------- rcan-py v0.3

namespace {

constexpr const char* kRequired[] = {"schema_version", "record_id", "timestamp",      "action",
                                     "params",         "robot_uri", "safety_approved"};
constexpr const char* kOptional[] = {"confidence", "model_identity", "operator", "safety_reason",
                                     "previous_hash"};

bool known_key(std::string_view k) {
  if (k == "hmac") return true;
  for (const char* r : kRequired)
    if (k == r) return true;
  for (const char* o : kOptional)
    if (k == o) return true;
  return false;
}

bool empty_value(const json::Value& v) {
  return v.is_null() || (v.is_string() && v.as_string().empty());
}

}  // namespace

Result<RcanpyRecord> rcanpy_parse_line(std::string_view line) {
  auto v = json::parse(line, internal::record_parse_options());
  if (!v.ok()) return v.error();
  if (!v->is_object())
    return Error(ErrorCode::kSchemaValidationFailed, "CommitmentRecord line is not an object");
  RcanpyRecord r;
  for (const auto& [k, val] : v->as_object()) {
    if (!known_key(k))
      return Error(ErrorCode::kSchemaValidationFailed, "unknown CommitmentRecord field " + k, k);
  }
  for (const char* k : kRequired) {
    const json::Value* f = v->get(k);
    if (!f) return Error(ErrorCode::kSchemaValidationFailed, std::string("missing field ") + k, k);
    r.fields.set(k, *f);
  }
  for (const char* k : kOptional) {
    const json::Value* f = v->get(k);
    if (f) {
      r.fields.set(k, *f);
    } else if (std::string_view(k) == "safety_reason") {
      r.fields.set(k, "");
    } else {
      r.fields.set(k, nullptr);
    }
  }
  if (const json::Value* h = v->get("hmac")) {
    if (!h->is_string())
      return Error(ErrorCode::kSchemaValidationFailed, "hmac is not a string", "hmac");
    r.hmac = h->as_string();
  }
  return r;
}

std::string rcanpy_preimage(const json::Object& fields) {
  return json::python_dumps(json::Value(fields), /*sort_keys=*/true, /*compact=*/true);
}

std::string rcanpy_hmac(std::string_view secret, const json::Object& fields) {
  return hmac_sha256_hex(secret, rcanpy_preimage(fields));
}

std::string rcanpy_content_hash(const json::Object& fields) {
  return sha256_hex(rcanpy_preimage(fields));
}

std::string rcanpy_line(const json::Object& fields, std::string_view hmac) {
  json::Object d;
  for (const char* k : kRequired) {
    const json::Value* f = fields.find(k);
    d.set(k, f ? *f : json::Value());
  }
  for (const char* k : kOptional) {
    const json::Value* f = fields.find(k);
    if (f && !empty_value(*f)) d.set(k, *f);
  }
  if (!hmac.empty()) d.set("hmac", std::string(hmac));
  return json::python_dumps(json::Value(std::move(d)), /*sort_keys=*/false, /*compact=*/false);
}

RcanpyExporter::RcanpyExporter(std::string secret) : secret_(std::move(secret)) {}

Result<std::string> RcanpyExporter::add(const json::Object& native) {
  const json::Value* seq = native.find("seq");
  const json::Value* ts = native.find("timestamp_ms");
  const json::Value* ruri = native.find("ruri");
  const json::Value* event = native.find("event");
  if (!seq || !seq->is_int() || !ts || !ts->is_int() || !ruri || !ruri->is_string() || !event ||
      !event->is_string())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "native audit record lacks seq, timestamp_ms, ruri or event");
  json::Object f;
  f.set("schema_version", "0.3.0");
  f.set("record_id", "rcan-audit-" + std::to_string(seq->as_int()));
  f.set("timestamp", static_cast<double>(ts->as_int()) / 1000.0);
  const json::Value* action = native.find("action");
  f.set("action", action && action->is_string() ? action->as_string() : event->as_string());
  json::Object params;
  params.set("rcan_audit", native);  // the full native record, hmac included
  f.set("params", std::move(params));
  f.set("robot_uri", ruri->as_string());
  const json::Value* ai = native.find("ai");
  const json::Value* conf = ai ? ai->get("confidence") : nullptr;
  f.set("confidence", conf && conf->is_number() ? *conf : json::Value());
  const json::Value* model = ai ? ai->get("model") : nullptr;
  f.set("model_identity", model && model->is_string() ? *model : json::Value());
  const json::Value* principal = native.find("principal");
  f.set("operator", principal && principal->is_string() ? *principal : json::Value());
  const json::Value* outcome = native.find("outcome");
  std::string oc = outcome && outcome->is_string() ? outcome->as_string() : "";
  bool approved = !(oc == "blocked" || oc == "denied" || oc == "error" || oc == "FAILURE");
  f.set("safety_approved", approved);
  const json::Value* reason = native.find("reason");
  f.set("safety_reason", reason && reason->is_string() ? reason->as_string() : std::string());
  f.set("previous_hash", previous_hash_ ? json::Value(*previous_hash_) : json::Value());
  std::string pre = rcanpy_preimage(f);
  std::string mac = hmac_sha256_hex(secret_, pre);
  previous_hash_ = sha256_hex(pre);
  return rcanpy_line(f, mac);
}

VerifyReport verify_rcanpy_jsonl(std::string_view text, std::string_view secret,
                                 bool strict_start) {
  VerifyReport rep;
  std::optional<std::string> prev;  // content_hash of the previous record
  uint64_t index = 0;
  auto fail = [&](std::string why) {
    rep.ok = false;
    rep.first_bad_index = index;
    rep.first_bad_seq = index;
    rep.why = std::move(why);
    return rep;
  };
  size_t start = 0;
  while (start < text.size()) {
    size_t nl = text.find('\n', start);
    std::string_view line =
        nl == std::string_view::npos ? text.substr(start) : text.substr(start, nl - start);
    start = nl == std::string_view::npos ? text.size() : nl + 1;
    if (line.find_first_not_of(" \t\r") == std::string_view::npos) continue;  // blank line
    auto r = rcanpy_parse_line(line);
    if (!r.ok()) return fail("malformed line: " + r.error().message);
    std::string pre = rcanpy_preimage(r->fields);
    if (r->hmac.empty() || !constant_time_equal(hmac_sha256_hex(secret, pre), r->hmac))
      return fail("hmac mismatch");
    const json::Value* ph = r->fields.find("previous_hash");
    if (index == 0) {
      if (strict_start && !ph->is_null())
        return fail("chain_link: first record has a previous_hash (records before it are missing)");
    } else if (!ph->is_string() || ph->as_string() != *prev) {
      return fail("chain_link: previous_hash does not match record " + std::to_string(index - 1));
    }
    prev = sha256_hex(pre);
    rep.last_hash = *prev;
    ++rep.count;
    ++index;
  }
  if (rep.count == 0) return fail("malformed line: no records");
  rep.ok = true;
  return rep;
}

}  // namespace rcan::audit
