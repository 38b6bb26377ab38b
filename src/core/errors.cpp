#include "rcan/errors.h"

#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstring>

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
  if (code == ErrorCode::kCommandRejected &&
      (reason == "estop_active" || reason == "rearm_required"))
    return 423;
  const Entry* e = lookup(code);
  return e ? e->status : 500;
}

std::string new_uuid_v4() {
  // 16 bytes per id from a per-thread block of 4 KiB drawn from the CSPRNG at once: one
  // RAND_bytes call (and its lock) per 256 ids instead of one per id (every answer carries one).
  // A forked child draws a fresh block (it must not repeat its parent's ids).
  thread_local std::array<uint8_t, 4096> pool;
  thread_local size_t used = pool.size();
  thread_local pid_t owner = 0;
  if (used + 16 > pool.size() || owner != ::getpid()) {
    owner = ::getpid();
    if (!random_bytes(pool.data(), pool.size())) {
      // RAND_bytes failing means the process cannot do cryptography at all.
      std::abort();
    }
    used = 0;
  }
  uint8_t b[16];
  std::memcpy(b, pool.data() + used, sizeof b);
  std::memset(pool.data() + used, 0, sizeof b);  // an id's bytes do not linger in the pool
  used += sizeof b;
  b[6] = static_cast<uint8_t>((b[6] & 0x0F) | 0x40);
  b[8] = static_cast<uint8_t>((b[8] & 0x3F) | 0x80);
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out(36, '-');
  size_t o = 0;
  for (size_t i = 0; i < 16; ++i) {
    if (i == 4 || i == 6 || i == 8 || i == 10) ++o;  // the dashes stay
    out[o++] = kHex[b[i] >> 4];
    out[o++] = kHex[b[i] & 0x0F];
  }
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
