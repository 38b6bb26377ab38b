// The protocol's error catalogue: one enum, its wire names and HTTP statuses.
// The wire names and statuses follow the project's profile (docs/PROTOCOL.md §Errors).
#pragma once

#include <optional>
#include <string_view>

namespace rcan {

enum class ErrorCode {
  kMalformedJson,           // 400 body is not JSON
  kSchemaValidationFailed,  // 400
  kInvalidRuri,             // 400
  kVersionIncompatible,     // 400
  kAuthRequired,            // 401
  kAuthInvalid,             // 401
  kSessionExpired,          // 401
  kInsufficientPrivileges,  // 403
  kConfidenceGateFail,      // 403
  kHitlDenied,              // 403
  kNotFound,                // 404
  kMethodNotAllowed,        // 405
  kMessageStale,            // 408
  kHitlTimeout,             // 408
  kReplayDetected,          // 409
  kControlConflict,         // 409
  kBodyTooLarge,            // 413
  kCommandRejected,         // 422 (prompt_injection) or 423 (estop_active): see http_status()
  kRateLimited,             // 429
  kInternal,                // 500
  kNotImplemented,          // 501
  kSafeStop,                // 503
  kLockdown,                // 503
  kAuditUnavailable,        // 503
  kSignatureInvalid,        // 401 message signature did not verify
  kMissingDelegationChain,  // 400
};

// Wire name, e.g. "INSUFFICIENT_PRIVILEGES".
std::string_view error_name(ErrorCode code);
// Inverse of error_name(); nullopt for an unknown name.
std::optional<ErrorCode> error_from_name(std::string_view name);
// HTTP status for a code; `reason` refines COMMAND_REJECTED (estop_active → 423, else 422).
int http_status(ErrorCode code, std::string_view reason = {});

}  // namespace rcan
