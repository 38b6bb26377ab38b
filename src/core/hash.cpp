#include "rcan/hash.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/rand.h>

#include "rcan/encoding.h"

namespace rcan {

Digest256 sha256(const void* data, size_t len) {
  Digest256 out{};
  unsigned int n = 0;
  EVP_Digest(data, len, out.data(), &n, EVP_sha256(), nullptr);
  return out;
}

std::string sha256_hex(std::string_view s) {
  auto d = sha256(s);
  return to_hex(d.data(), d.size());
}

Digest256 hmac_sha256(const void* key, size_t key_len, const void* data, size_t len) {
  Digest256 out{};
  unsigned int n = 0;
  static const uint8_t kEmpty = 0;
  HMAC(EVP_sha256(), key_len ? key : &kEmpty, static_cast<int>(key_len),
       static_cast<const unsigned char*>(len ? data : &kEmpty), len, out.data(), &n);
  return out;
}

std::string hmac_sha256_hex(std::string_view key, std::string_view data) {
  auto d = hmac_sha256(key, data);
  return to_hex(d.data(), d.size());
}

bool constant_time_equal(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  if (a.empty()) return true;
  return CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

void secure_wipe(void* p, size_t len) {
  if (p && len) OPENSSL_cleanse(p, len);
}

bool random_bytes(void* out, size_t len) {
  return RAND_bytes(static_cast<unsigned char*>(out), static_cast<int>(len)) == 1;
}

}  // namespace rcan
