#include "rcan/errors.h"

#include <array>
#include <cstdio>

#include "rcan/hash.h"

namespace rcan {
namespace {

struct Entry {
  ErrorCode code;
  std::string_view name;
  int status;
};

constexpr std::array<Entry, 26> kTable{{
    {ErrorCode::kMalformedJson, "MALFORMED_JSON", 400},
    {ErrorCode::kSchemaValidationFailed, "SCHEMA_VALIDATION_FAILED", 400},
    {ErrorCode::kInvalidRuri, "INVALID_RURI", 400},
    {ErrorCode::kVersionIncompatible, "VERSION_INCOMPATIBLE", 400},
    {ErrorCode::kAuthRequired, "AUTH_REQUIRED", 401},
    {ErrorCode::kAuthInvalid, "AUTH_INVALID", 401},
    {ErrorCode::kSessionExpired, "SESSION_EXPIRED", 401},
    {ErrorCode::kInsufficientPrivileges, "INSUFFICIENT_PRIVILEGES", 403},
    {ErrorCode::kConfidenceGateFail, "CONFIDENCE_GATE_FAIL", 403},
    {ErrorCode::kHitlDenied, "HITL_DENIED", 403},
    {ErrorCode::kNotFound, "NOT_FOUND", 404},
    {ErrorCode::kMethodNotAllowed, "METHOD_NOT_ALLOWED", 405},
    {ErrorCode::kMessageStale, "MESSAGE_STALE", 408},
    {ErrorCode::kHitlTimeout, "HITL_TIMEOUT", 408},
    {ErrorCode::kReplayDetected, "REPLAY_DETECTED", 409},
    {ErrorCode::kControlConflict, "CONTROL_CONFLICT", 409},
    {ErrorCode::kBodyTooLarge, "BODY_TOO_LARGE", 413},
    {ErrorCode::kCommandRejected, "COMMAND_REJECTED", 422},
    {ErrorCode::kRateLimited, "RATE_LIMITED", 429},
    {ErrorCode::kInternal, "INTERNAL_ERROR", 500},
    {ErrorCode::kNotImplemented, "NOT_IMPLEMENTED", 501},
    {ErrorCode::kSafeStop, "SAFE_STOP", 503},
    {ErrorCode::kLockdown, "LOCKDOWN", 503},
    {ErrorCode::kAuditUnavailable, "AUDIT_UNAVAILABLE", 503},
    {ErrorCode::kSignatureInvalid, "SIGNATURE_INVALID", 401},
    {ErrorCode::kMissingDelegationChain, "MISSING_DELEGATION_CHAIN", 400},
}};

const Entry* lookup(ErrorCode code) {
  for (const auto& e : kTable)
    if (e.code == code) return &e;
  return nullptr;
}

}  // namespace

std::string_view error_name(ErrorCode code) {
  const Entry* e = lookup(code);
  return e ? e->name : "INTERNAL_ERROR";
}

std::optional<ErrorCode> error_from_name(std::string_view name) {
  for (const auto& e : kTable)
    if (e.name == name) return e.code;
  return std::nullopt;
}

int http_status(ErrorCode code, std::string_view reason) {
  if (code == ErrorCode::kCommandRejected && reason == "estop_active") return 423;
  const Entry* e = lookup(code);
  return e ? e->status : 500;
}

std::string new_uuid_v4() {
  uint8_t b[16];
  if (!random_bytes(b, sizeof b)) {
    // RAND_bytes failing means the process cannot do cryptography at all.
    std::abort();
  }
  b[6] = static_cast<uint8_t>((b[6] & 0x0F) | 0x40);
  b[8] = static_cast<uint8_t>((b[8] & 0x3F) | 0x80);
  char out[37];
  std::snprintf(out, sizeof out,
                "%02x%02x%02x%02x-%02x%02x-%02x%02x-%02x%02x-%02x%02x%02x%02x%02x%02x", b[0], b[1],
                b[2], b[3], b[4], b[5], b[6], b[7], b[8], b[9], b[10], b[11], b[12], b[13], b[14],
                b[15]);
  return out;
}

bool is_uuid(std::string_view s) {
  if (s.size() != 36) return false;
  for (size_t i = 0; i < 36; ++i) {
    char c = s[i];
    if (i == 8 || i == 13 || i == 18 || i == 23) {
      if (c != '-') return false;
    } else if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F'))) {
      return false;
    }
  }
  return true;
}

json::Value error_body(const Error& err, std::string_view reply_to, int64_t timestamp_ms,
                       std::string_view message_id) {
  json::Object detail;
  if (!err.field.empty()) detail.set("field", err.field);
  if (!err.reason.empty()) detail.set("reason", err.reason);
  if (err.reason == "missing_field" && !err.field.empty()) detail.set("missing_field", err.field);
  json::Object payload;
  payload.set("error_code", std::string(error_name(err.code)));
  payload.set("error", err.message);
  if (!err.reason.empty()) payload.set("reason", err.reason);
  payload.set("detail", std::move(detail));
  json::Object body;
  body.set("type", "ERROR");
  body.set("message_id", message_id.empty() ? new_uuid_v4() : std::string(message_id));
  body.set("reply_to", reply_to.empty() ? json::Value() : json::Value(std::string(reply_to)));
  body.set("timestamp_ms", timestamp_ms);
  body.set("payload", std::move(payload));
  return json::Value(std::move(body));
}

}  // namespace rcan
