// Private: the writer's hot path. Sealing a record is split in two so that the costly
// part (serialising every member to canonical JSON) runs on the appending thread and the
// writer thread only concatenates, hashes and MACs:
//   prepare(entry)            → members as canonical `"key":value` fragments, sorted
//   seal_prepared(p, seq, …)  → pre-image / line with seq, prev_hash (and hmac) merged in
// The output is byte-identical to seal() in record.h (json::canonical of the object).
#pragma once

#include <openssl/evp.h>

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/audit/record.h"

namespace rcan::audit::internal {

// SHA-256 and HMAC-SHA256 with one fetched digest and precomputed HMAC pads.
// Not thread-safe: one per thread.
class Hasher {
 public:
  explicit Hasher(std::string_view key);
  ~Hasher();
  Hasher(const Hasher&) = delete;
  Hasher& operator=(const Hasher&) = delete;
  std::string sha256_hex(std::string_view data);
  std::string hmac_hex(std::string_view data);

 private:
  void digest(EVP_MD_CTX* from, std::string_view data, uint8_t out[32]);
  EVP_MD* md_ = nullptr;
  EVP_MD_CTX* work_ = nullptr;
  EVP_MD_CTX* inner_ = nullptr;  // state after hashing key ^ ipad
  EVP_MD_CTX* outer_ = nullptr;  // state after hashing key ^ opad
};

struct PreparedRecord {
  // (key, fragment) with fragment = canonical("key") + ":" + canonical(value), sorted by
  // key; never contains seq, prev_hash or hmac.
  std::vector<std::pair<std::string, std::string>> members;
};

PreparedRecord prepare(const json::Object& obj);
// The same as prepare(to_object(e)) without building the object (the appender's hot path).
PreparedRecord prepare(const AuditEntry& e);

SealedRecord seal_prepared(const PreparedRecord& p, uint64_t seq, std::string_view prev_hash,
                           Hasher& hasher);

}  // namespace rcan::audit::internal
