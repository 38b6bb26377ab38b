// §16.6 AI-output watermark tokens (RCAN v1.7; identical in rcan-py and rcan-ts).
//
//   token = "rcan-wm-v1:" + lower-hex( HMAC-SHA256(key, rrn ":" thought_id ":" timestamp)[0:16] )
//
// The key is the robot's ML-DSA-65 secret key (4032 bytes, FIPS 204 encoding). The
// timestamp string is used verbatim; this node writes it as UTC
// `YYYY-MM-DDTHH:MM:SS.ffffff` (format_timestamp) and stores it in the audit record, since
// verification is by audit lookup, not by recomputation.
//
// The format check is a whole-string match of ^rcan-wm-v1:[0-9a-f]{32}$ — no surrounding
// whitespace and no trailing newline (unlike rcan-py's `re.match(... $)`).
#pragma once

#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "rcan/encoding.h"
#include "rcan/result.h"

namespace rcan::watermark {

inline constexpr std::string_view kPrefix = "rcan-wm-v1:";
inline constexpr size_t kHexChars = 32;
inline constexpr size_t kTokenChars = 11 + kHexChars;  // prefix + 32 hex

// Computes the token. Any key length is accepted by HMAC; production keys are 4032 bytes.
std::string compute(std::span<const uint8_t> key, std::string_view rrn, std::string_view thought_id,
                    std::string_view timestamp_iso);

// True when `token` is exactly ^rcan-wm-v1:[0-9a-f]{32}$.
bool valid_format(std::string_view token);

// Like valid_format(), with a reason: kSchemaValidationFailed, field "watermark_token".
Status check_format(std::string_view token);

// Recomputes and compares in constant time. False for a malformed token.
bool verify(std::span<const uint8_t> key, std::string_view rrn, std::string_view thought_id,
            std::string_view timestamp_iso, std::string_view token);

// UTC "YYYY-MM-DDTHH:MM:SS.ffffff" (microseconds, no zone suffix) of a time point.
std::string format_timestamp(std::chrono::system_clock::time_point t);

// Loads the watermark key from a file:
//   * a raw 4032-byte ML-DSA-65 secret key file → used as is;
//   * a 32-byte ML-DSA-65 seed file (a key directory's `mldsa65.seed`) → the secret key is
//     derived with ML-DSA.KeyGen_internal(seed);
//   * a key directory → its `mldsa65.seed`.
// The file must be a regular file that is not group/world accessible. Any other size is an
// error. The returned buffer is the 4032-byte secret key; the caller should wipe it.
Result<Bytes> load_key(const std::string& path);

}  // namespace rcan::watermark
