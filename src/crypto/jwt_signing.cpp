// The issuer's side (see include/rcan/crypto/jwt.h): signing keys from a PEM private key, a raw
// Ed25519 seed, an HS256 secret or a file holding one of them; the verification key that
// matches a signing key; issue(), which builds and signs a compact token; and the durations
// tokens are issued for.
//
// Contract: a signing key gets exactly one algorithm from its type (detail::classify, as a
// verification key does); key files must not be group/world accessible (keys::read_secret_file).
// The signature itself is made by SigningKey::sign (jws.cpp).
#include <openssl/err.h>
#include <openssl/pem.h>

#include "crypto/jwt_internal.h"
#include "rcan/crypto/jwt.h"
#include "rcan/hash.h"

namespace rcan::jwt {

using detail::BioPtr;
using detail::classify;
using detail::key_error;
using detail::kMaxPemBytes;
using detail::no_password;
using detail::PkeyPtr;
using detail::trim_secret_newline;

// ---------------------------------------------------------------------------------------
// SigningKey

SigningKey::SigningKey() = default;
SigningKey::SigningKey(SigningKey&&) noexcept = default;
SigningKey& SigningKey::operator=(SigningKey&&) noexcept = default;
SigningKey::~SigningKey() = default;

Result<SigningKey> SigningKey::from_pem(std::string_view pem) {
  if (pem.size() > kMaxPemBytes) return key_error("PEM key too large");
  BioPtr bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  if (!bio) return Error(ErrorCode::kInternal, "out of memory");
  PkeyPtr pk(PEM_read_bio_PrivateKey(bio.get(), nullptr, no_password, nullptr));
  ERR_clear_error();
  if (!pk) return key_error("not an unencrypted PEM private key");
  auto alg = classify(pk.get());
  if (!alg.ok()) return alg.error();
  SigningKey k;
  k.alg_ = *alg;
  k.impl_ = std::make_unique<Impl>();
  k.impl_->pkey = std::move(pk);
  return k;
}

Result<SigningKey> SigningKey::ed25519_seed(std::span<const uint8_t> seed) {
  if (seed.size() != 32) return key_error("Ed25519 seed must be 32 bytes");
  PkeyPtr pk(EVP_PKEY_new_raw_private_key(EVP_PKEY_ED25519, nullptr, seed.data(), seed.size()));
  ERR_clear_error();
  if (!pk) return key_error("invalid Ed25519 seed");
  SigningKey k;
  k.alg_ = Alg::kEdDSA;
  k.impl_ = std::make_unique<Impl>();
  k.impl_->pkey = std::move(pk);
  return k;
}

Result<SigningKey> SigningKey::hs256_secret(std::span<const uint8_t> secret) {
  if (secret.size() < kMinHs256SecretBytes)
    return key_error("HS256 secret must be at least 32 bytes, got " +
                     std::to_string(secret.size()));
  SigningKey k;
  k.alg_ = Alg::kHS256;
  k.impl_ = std::make_unique<Impl>();
  k.impl_->secret = keys::SecretBytes(secret.data(), secret.size());
  return k;
}

Result<SigningKey> SigningKey::from_file(const std::string& path, bool hs256) {
  auto s = keys::read_secret_file(path, 0);
  if (!s.ok()) return s.error();
  Result<SigningKey> k = key_error("unreachable");
  if (hs256) {
    std::string t = trim_secret_newline(s->view());
    k = hs256_secret(
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(t.data()), t.size()));
    secure_wipe(t.data(), t.size());
  } else if (s->size() == 32 && s->view().find("-----BEGIN") == std::string_view::npos) {
    k = ed25519_seed(s->span());
  } else {
    k = from_pem(s->view());
  }
  if (!k.ok()) return Error(k.error().code, path + ": " + k.error().message, path);
  return k;
}

Result<VerificationKey> SigningKey::verification_key() const {
  if (alg_ == Alg::kHS256) return VerificationKey::hs256_secret(impl_->secret.span());
  if (alg_ == Alg::kEdDSA) {
    // The raw key: PEM export goes through OpenSSL's encoder machinery, which walks every
    // provider's encoders (slow, and megabytes touched at start-up for one key).
    uint8_t raw[32];
    size_t n = sizeof raw;
    if (EVP_PKEY_get_raw_public_key(impl_->pkey.get(), raw, &n) != 1 || n != sizeof raw) {
      ERR_clear_error();
      return Error(ErrorCode::kInternal, "cannot export public key");
    }
    return VerificationKey::ed25519_raw(raw);
  }
  BioPtr bio(BIO_new(BIO_s_mem()));
  if (!bio || PEM_write_bio_PUBKEY(bio.get(), impl_->pkey.get()) != 1) {
    ERR_clear_error();
    return Error(ErrorCode::kInternal, "cannot export public key");
  }
  char* p = nullptr;
  long n = BIO_get_mem_data(bio.get(), &p);
  return VerificationKey::from_pem(std::string_view(p, static_cast<size_t>(n)));
}

// ---------------------------------------------------------------------------------------
// Issuing

Result<std::string> issue(const json::Object& claims, const SigningKey& key, std::string_view kid) {
  json::Object header;
  header.set("alg", std::string(alg_name(key.alg())));
  header.set("typ", "JWT");
  if (!kid.empty()) header.set("kid", std::string(kid));
  std::string h = json::dump(json::Value(std::move(header)));
  std::string p = json::dump(json::Value(claims));
  std::string input =
      base64url_encode(reinterpret_cast<const uint8_t*>(h.data()), h.size(), false) + "." +
      base64url_encode(reinterpret_cast<const uint8_t*>(p.data()), p.size(), false);
  auto sig = key.sign(input);
  if (!sig.ok()) return sig.error();
  return input + "." + base64url_encode(*sig, false);
}

std::optional<int64_t> parse_duration(std::string_view s) {
  if (s.empty()) return std::nullopt;
  int64_t mult = 1;
  char last = s.back();
  if (last == 's' || last == 'm' || last == 'h' || last == 'd') {
    mult = last == 's' ? 1 : last == 'm' ? 60 : last == 'h' ? 3600 : 86400;
    s.remove_suffix(1);
  }
  if (s.empty() || s.size() > 12) return std::nullopt;
  int64_t v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return std::nullopt;
    v = v * 10 + (c - '0');
  }
  int64_t total = v * mult;
  if (total <= 0 || total > int64_t{10} * 366 * 86400) return std::nullopt;
  return total;
}

}  // namespace rcan::jwt
