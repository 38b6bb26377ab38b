// §16.6 watermark tokens (see include/rcan/crypto/watermark.h).
#include "rcan/crypto/watermark.h"

#include <sys/stat.h>

#include <cstdio>
#include <ctime>
#include <string>

#include "rcan/crypto/keys.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"

namespace rcan::watermark {

std::string compute(std::span<const uint8_t> key, std::string_view rrn, std::string_view thought_id,
                    std::string_view timestamp_iso) {
  std::string msg;
  msg.reserve(rrn.size() + thought_id.size() + timestamp_iso.size() + 2);
  msg.append(rrn).append(1, ':').append(thought_id).append(1, ':').append(timestamp_iso);
  Digest256 mac = hmac_sha256(key.data(), key.size(), msg.data(), msg.size());
  std::string token(kPrefix);
  token += to_hex(mac.data(), 16);
  secure_wipe(mac.data(), mac.size());
  return token;
}

bool valid_format(std::string_view token) {
  if (token.size() != kTokenChars) return false;
  if (token.substr(0, kPrefix.size()) != kPrefix) return false;
  for (char c : token.substr(kPrefix.size())) {
    bool hex = (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
    if (!hex) return false;
  }
  return true;
}

Status check_format(std::string_view token) {
  auto bad = [](std::string m) {
    return Error(ErrorCode::kSchemaValidationFailed,
                 "Invalid watermark token format: " + std::move(m), "watermark_token");
  };
  if (token.size() < kPrefix.size() || token.substr(0, kPrefix.size()) != kPrefix)
    return bad("it must start with \"rcan-wm-v1:\"");
  std::string_view hex = token.substr(kPrefix.size());
  for (size_t i = 0; i < hex.size() && i < kHexChars; ++i) {
    char c = hex[i];
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f')))
      return bad("character " + std::to_string(kPrefix.size() + i) +
                 " is not a lower-case hex digit");
  }
  if (hex.size() != kHexChars)
    return bad("expected 32 hex digits after the prefix, found " + std::to_string(hex.size()) +
               " characters");
  return Status::Ok();
}

bool verify(std::span<const uint8_t> key, std::string_view rrn, std::string_view thought_id,
            std::string_view timestamp_iso, std::string_view token) {
  if (!valid_format(token)) return false;
  std::string expected = compute(key, rrn, thought_id, timestamp_iso);
  return constant_time_equal(expected, token);
}

std::string format_timestamp(std::chrono::system_clock::time_point t) {
  using namespace std::chrono;
  auto us = duration_cast<microseconds>(t.time_since_epoch()).count();
  int64_t secs = us / 1000000;
  int64_t frac = us % 1000000;
  if (frac < 0) {
    frac += 1000000;
    secs -= 1;
  }
  std::time_t tt = static_cast<std::time_t>(secs);
  std::tm tm{};
  gmtime_r(&tt, &tm);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%06lld", tm.tm_year + 1900,
                tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                static_cast<long long>(frac));
  return buf;
}

Result<Bytes> load_key(const std::string& path) {
  std::string file = path;
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
    file = (path.empty() || path.back() == '/' ? path : path + "/") +
           std::string(keys::kMldsaSeedFile);
  auto secret = keys::read_secret_file(file, 0);
  if (!secret.ok()) return secret.error();
  if (secret->size() == mldsa65::kSecretKeyBytes)
    return Bytes(secret->data(), secret->data() + secret->size());
  if (secret->size() == mldsa65::kSeedBytes) {
    auto kp = mldsa65::keygen_from_seed(secret->span());
    if (!kp.ok()) return kp.error();
    return Bytes(kp->secret_key);
  }
  return Error(ErrorCode::kSchemaValidationFailed,
               file +
                   " is neither a 4032-byte ML-DSA-65 secret key nor a 32-byte ML-DSA-65 seed (" +
                   std::to_string(secret->size()) + " bytes)",
               file);
}

}  // namespace rcan::watermark
