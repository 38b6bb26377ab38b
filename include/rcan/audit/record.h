// rcan::audit records — what one line of the audit chain says, and how it is sealed.
//
// A record is a JSON object (docs/AUDIT.md §Record, PROFILE.md §7):
//   principal, ruri, timestamp_ms, message_id, event, outcome   (seed §6, always)
//   sender_type (always), sub, cloud_provider, function_name    (§8.5)
//   ai{provider, model, model_version?, layer?, confidence?, inference_latency_ms?,
//      thought_id?, escalated}                                   (§16.2)
//   gate_bypassed, hitl_timeout_bypass (only when true), watermark_token, action, reason,
//   detail{…} (free-form extra facts: delegation_chain, invoke_id, config_hash, …)
//   kind, segment (system records only: "checkpoint", "recovery", "retention")
//   seq, prev_hash, hmac                                         (added when sealed)
// Optional fields are omitted when absent, never defaulted.
//
// Sealing: hmac = hex HMAC-SHA256(secret, canonical(record without hmac));
// prev_hash = hex SHA-256(canonical(previous record without hmac)), null for seq 1.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/result.h"

namespace rcan::audit {

// §16.2 ai block: the same model as on the message (rcan/message.h), so what a COMMAND
// carries is what its record holds. `confidence` is absent when the model did not report one.
using AiBlock = ::rcan::AiBlock;

// What a caller asks to have recorded. The log adds seq, prev_hash and hmac.
struct AuditEntry {
  std::string principal;
  std::string ruri;
  int64_t timestamp_ms = 0;  // 0 → stamped by the log's clock when sealed
  std::string message_id;
  std::string event;    // e.g. COMMAND, COMMAND_REJECTED, HITL_APPROVED, ESTOP
  std::string outcome;  // ok | blocked | error (seed §6)

  std::string sender_type = "human";  // human | robot | cloud_function | system
  std::optional<std::string> sub;     // JWT subject
  std::optional<std::string> cloud_provider;
  std::optional<std::string> function_name;
  std::optional<AiBlock> ai;
  bool gate_bypassed = false;        // written only when true
  bool hitl_timeout_bypass = false;  // written only when true
  std::optional<std::string> watermark_token;
  std::optional<std::string> action;
  std::optional<std::string> reason;
  json::Object detail;  // written only when non-empty

  // System records written by the log itself; empty for ordinary records.
  std::string kind;
  std::optional<uint64_t> segment;
};

// Checks what the profile requires of an entry (six §6 fields non-empty except a zero
// timestamp, a known sender_type, cloud identity for cloud_function, ai.provider/model,
// confidence finite in [0, 1]). Error code kSchemaValidationFailed naming the field.
Status validate(const AuditEntry& e);

// The unsealed JSON object of an entry (no seq / prev_hash / hmac).
json::Object to_object(const AuditEntry& e);
// The §16.2 ai block as written in a record.
json::Object to_object(const AiBlock& a);
// The inverse of to_object(AuditEntry) for an unsealed entry (a record kept outside the log,
// e.g. a stop the log could not write). Unknown members are ignored. Errors:
// SCHEMA_VALIDATION_FAILED naming the member of the wrong type, or what validate() refuses.
Result<AuditEntry> entry_from_object(const json::Object& o);

// Result of sealing a record at a position in the chain.
struct SealedRecord {
  uint64_t seq = 0;
  std::string preimage;     // canonical JSON without hmac
  std::string record_hash;  // hex SHA-256(preimage): the next record's prev_hash
  std::string hmac;         // hex HMAC-SHA256(secret, preimage)
  std::string line;         // canonical JSON with hmac, no newline
};

// Adds seq and prev_hash (null when `prev_hash` is empty) to `obj`, computes the
// hashes and the stored line. `obj` must not contain seq, prev_hash or hmac.
SealedRecord seal(json::Object obj, uint64_t seq, std::string_view prev_hash,
                  std::string_view secret);

// Recomputes hmac/record_hash of a parsed record (must be an object). `hmac_ok` compares
// in constant time with the record's own hmac member.
struct RecordCheck {
  std::string preimage;
  std::string record_hash;
  bool hmac_present = false;
  bool hmac_ok = false;
};
RecordCheck check_record(const json::Object& rec, std::string_view secret);

// A new random UUIDv4 string (used for system records' message_id).
std::string new_uuid();

}  // namespace rcan::audit
