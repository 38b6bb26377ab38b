// Ed25519 (RFC 8032, pure) through OpenSSL's EVP API.
#include "rcan/crypto/ed25519.h"

#include <openssl/bio.h>
#include <openssl/evp.h>
#include <openssl/pem.h>

#include <algorithm>
#include <array>
#include <iterator>
#include <memory>

#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace rcan::ed25519 {
namespace {

struct PkeyFree {
  void operator()(EVP_PKEY* p) const { EVP_PKEY_free(p); }
};
struct MdCtxFree {
  void operator()(EVP_MD_CTX* p) const { EVP_MD_CTX_free(p); }
};
struct BioFree {
  void operator()(BIO* p) const { BIO_free(p); }
};
using PkeyPtr = std::unique_ptr<EVP_PKEY, PkeyFree>;
using MdCtxPtr = std::unique_ptr<EVP_MD_CTX, MdCtxFree>;
using BioPtr = std::unique_ptr<BIO, BioFree>;

// The group order L = 2^252 + 27742317777372353535851937790883648493, little-endian.
constexpr uint8_t kOrderL[32] = {0xed, 0xd3, 0xf5, 0x5c, 0x1a, 0x63, 0x12, 0x58, 0xd6, 0x9c, 0xf7,
                                 0xa2, 0xde, 0xf9, 0xde, 0x14, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
                                 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x10};

// RFC 8032 §5.1.7: S must be in [0, L). OpenSSL checks this too; checking here keeps the
// rule explicit and independent of the library version. S is public.
bool scalar_is_canonical(const uint8_t* s) {
  for (int i = 31; i >= 0; --i) {
    if (s[i] < kOrderL[i]) return true;
    if (s[i] > kOrderL[i]) return false;
  }
  return false;  // S == L
}

const uint8_t kEmpty = 0;
const uint8_t* data_or_empty(std::span<const uint8_t> s) { return s.empty() ? &kEmpty : s.data(); }

PkeyPtr private_key(std::span<const uint8_t> seed) {
  return PkeyPtr(EVP_PKEY_new_raw_private_key(EVP_PKEY_ED25519, nullptr, seed.data(), seed.size()));
}

Result<Bytes> raw_public(EVP_PKEY* pkey) {
  Bytes pk(kPublicKeyBytes);
  size_t len = pk.size();
  if (EVP_PKEY_get_raw_public_key(pkey, pk.data(), &len) != 1 || len != kPublicKeyBytes) {
    return Error(ErrorCode::kInternal, "cannot extract the Ed25519 public key");
  }
  return pk;
}

}  // namespace

Result<Bytes> public_key_from_seed(std::span<const uint8_t> seed) {
  if (seed.size() != kSeedBytes) {
    return Error(ErrorCode::kInternal, "Ed25519 seed must be 32 bytes", "seed");
  }
  PkeyPtr pkey = private_key(seed);
  if (!pkey) return Error(ErrorCode::kInternal, "OpenSSL rejected the Ed25519 seed");
  return raw_public(pkey.get());
}

Bytes random_seed() {
  Bytes seed(kSeedBytes);
  if (!random_bytes(seed.data(), seed.size())) return {};  // callers then fail on the length
  return seed;
}

Result<Bytes> sign(std::span<const uint8_t> seed, std::span<const uint8_t> message) {
  if (seed.size() != kSeedBytes) {
    return Error(ErrorCode::kInternal, "Ed25519 seed must be 32 bytes", "seed");
  }
  PkeyPtr pkey = private_key(seed);
  MdCtxPtr ctx(EVP_MD_CTX_new());
  if (!pkey || !ctx || EVP_DigestSignInit(ctx.get(), nullptr, nullptr, nullptr, pkey.get()) != 1) {
    return Error(ErrorCode::kInternal, "OpenSSL Ed25519 signing setup failed");
  }
  Bytes sig(kSignatureBytes);
  size_t len = sig.size();
  if (EVP_DigestSign(ctx.get(), sig.data(), &len, data_or_empty(message), message.size()) != 1 ||
      len != kSignatureBytes) {
    return Error(ErrorCode::kInternal, "OpenSSL Ed25519 signing failed");
  }
  return sig;
}

namespace {

// The key object of the last public key this thread verified with. A node verifies most
// messages with the few keys it trusts (a fleet's coordinator, an operator's bound key), and
// building OpenSSL's key object (a provider look-up under a process-wide lock) costs as much as
// a third of the verification itself. One entry per thread: no lock, nothing shared.
EVP_PKEY* verification_key(std::span<const uint8_t> public_key) {
  thread_local std::array<uint8_t, kPublicKeyBytes> last{};
  thread_local PkeyPtr pkey;
  if (pkey && std::equal(last.begin(), last.end(), public_key.begin())) return pkey.get();
  pkey.reset(
      EVP_PKEY_new_raw_public_key(EVP_PKEY_ED25519, nullptr, public_key.data(), public_key.size()));
  if (pkey) std::copy(public_key.begin(), public_key.end(), last.begin());
  return pkey.get();
}

}  // namespace

bool verify(std::span<const uint8_t> public_key, std::span<const uint8_t> message,
            std::span<const uint8_t> signature) {
  if (public_key.size() != kPublicKeyBytes || signature.size() != kSignatureBytes) return false;
  if (!scalar_is_canonical(signature.data() + 32)) return false;
  EVP_PKEY* pkey = verification_key(public_key);
  MdCtxPtr ctx(EVP_MD_CTX_new());
  if (pkey == nullptr || !ctx ||
      EVP_DigestVerifyInit(ctx.get(), nullptr, nullptr, nullptr, pkey) != 1) {
    return false;
  }
  return EVP_DigestVerify(ctx.get(), signature.data(), signature.size(), data_or_empty(message),
                          message.size()) == 1;
}

// RFC 8410 SubjectPublicKeyInfo, written directly: the DER is a fixed 12-byte prefix and the
// key, and its PEM is one base64 line — byte for byte what OpenSSL's PEM writer produces, without
// its encoder look-ups (a key id is the hash of this text, computed for every signed message).
Result<std::string> public_key_to_pem(std::span<const uint8_t> public_key) {
  if (public_key.size() != kPublicKeyBytes) {
    return Error(ErrorCode::kInternal, "Ed25519 public key must be 32 bytes", "public_key");
  }
  static constexpr uint8_t kSpkiPrefix[12] = {0x30, 0x2a, 0x30, 0x05, 0x06, 0x03,
                                              0x2b, 0x65, 0x70, 0x03, 0x21, 0x00};
  std::array<uint8_t, sizeof kSpkiPrefix + kPublicKeyBytes> der{};
  std::copy(std::begin(kSpkiPrefix), std::end(kSpkiPrefix), der.begin());
  std::copy(public_key.begin(), public_key.end(), der.begin() + sizeof kSpkiPrefix);
  return "-----BEGIN PUBLIC KEY-----\n" + base64_encode(der.data(), der.size()) +
         "\n-----END PUBLIC KEY-----\n";
}

Result<Bytes> public_key_from_pem(std::string_view pem) {
  if (pem.size() > (1u << 16)) {
    return Error(ErrorCode::kInternal, "PEM input too large", "pem");
  }
  BioPtr bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  if (!bio) return Error(ErrorCode::kInternal, "cannot read PEM");
  PkeyPtr pkey(PEM_read_bio_PUBKEY(bio.get(), nullptr, nullptr, nullptr));
  if (!pkey) return Error(ErrorCode::kInternal, "not a PEM public key", "pem");
  if (EVP_PKEY_get_id(pkey.get()) != EVP_PKEY_ED25519) {
    return Error(ErrorCode::kInternal, "PEM public key is not Ed25519", "pem");
  }
  return raw_public(pkey.get());
}

}  // namespace rcan::ed25519
