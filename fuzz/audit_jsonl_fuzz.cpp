// libFuzzer: arbitrary bytes as an exported audit chain — native and rcan-py verifiers,
// the rcan-py line parser and re-serialiser, the native → rcan-py re-statement, and each line
// read as an unsealed entry (audit::entry_from_object, the node's stop backlog).
// Must never crash, hang or read out of bounds; every verdict must be self-consistent.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "rcan/audit/record.h"
#include "rcan/audit/verify.h"
#include "rcan/json.h"

namespace {

constexpr const char* kSecret = "fuzz-secret-0123456789abcdef";

void check(bool cond) {
  if (!cond) std::abort();
}

// The rcan-py line form (to_dict) leaves out an optional field that is null or "", and
// from_dict restores a missing one as its default (null; "" for safety_reason). A record
// whose optional field holds the other empty value (e.g. "confidence": "") therefore reads
// back different — in rcan-py exactly as here — and only other records must round-trip.
bool line_form_is_lossless(const rcan::json::Object& fields) {
  for (const char* k :
       {"confidence", "model_identity", "operator", "safety_reason", "previous_hash"}) {
    const rcan::json::Value* v = fields.find(k);
    if (v == nullptr) continue;
    const bool is_reason = std::string_view(k) == "safety_reason";
    if (is_reason ? v->is_null() : (v->is_string() && v->as_string().empty())) return false;
  }
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  using namespace rcan::audit;

  VerifyReport native = verify_jsonl(text, kSecret);
  if (native.ok) {
    check(native.count > 0);
    check(native.last_seq >= native.first_seq);
  } else {
    check(!native.why.empty());
  }
  VerifyOptions partial;
  partial.allow_partial_start = true;
  partial.expect_last_seq = 3;
  (void)verify_jsonl(text, kSecret, partial);

  VerifyReport py = verify_rcanpy_jsonl(text, kSecret, true);
  if (!py.ok) check(!py.why.empty());
  (void)verify_rcanpy_jsonl(text, kSecret, false);

  // Per line: parse as a CommitmentRecord and round-trip; treat as a native record and
  // re-state it for rcan-py.
  RcanpyExporter exporter(kSecret);
  size_t start = 0;
  int lines = 0;
  while (start <= text.size() && lines < 64) {
    size_t nl = text.find('\n', start);
    std::string_view line =
        text.substr(start, nl == std::string_view::npos ? std::string_view::npos : nl - start);
    ++lines;
    auto rec = rcanpy_parse_line(line);
    if (rec.ok()) {
      std::string again = rcanpy_line(rec->fields, rec->hmac);
      auto reparsed = rcanpy_parse_line(again);
      check(reparsed.ok());
      if (line_form_is_lossless(rec->fields))
        check(rcanpy_preimage(reparsed->fields) == rcanpy_preimage(rec->fields));
    }
    auto v = rcan::json::parse(line);
    if (v.ok() && v->is_object()) {
      (void)check_record(v->as_object(), kSecret);
      auto out = exporter.add(v->as_object());
      if (out.ok()) check(rcanpy_parse_line(*out).ok());
      // As a line of the node's stop backlog (an unsealed entry): a valid entry, and reading
      // back what it writes gives the same object.
      auto entry = entry_from_object(v->as_object());
      if (entry.ok()) {
        check(validate(*entry).ok());
        const rcan::json::Object written = to_object(*entry);
        auto again = entry_from_object(written);
        check(again.ok());
        check(rcan::json::canonical(rcan::json::Value(to_object(*again))) ==
              rcan::json::canonical(rcan::json::Value(written)));
      } else {
        check(!entry.error().message.empty());
      }
    }
    if (nl == std::string_view::npos) break;
    start = nl + 1;
  }
  return 0;
}
