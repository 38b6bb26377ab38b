// JWT (JWS compact) verification and issuing (see include/rcan/crypto/jwt.h).
//
// All signature work goes through OpenSSL EVP directly so that the verifier does not depend
// on anything but libcrypto: Ed25519 (EdDSA), ECDSA P-256 + SHA-256 (ES256, with the JOSE
// raw r‖s signature converted to/from DER), RSASSA-PKCS1-v1_5 + SHA-256 (RS256), and
// HMAC-SHA-256 (HS256, compared in constant time).
#include "rcan/crypto/jwt.h"

#include <openssl/bio.h>
#include <openssl/bn.h>
#include <openssl/core_names.h>
#include <openssl/ec.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/param_build.h>
#include <openssl/pem.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include "rcan/hash.h"
#include "rcan/roles.h"
#include "rcan/ruri.h"

namespace rcan::jwt {
namespace {

Error auth_invalid(std::string msg, std::string field = {}, std::string reason = {}) {
  return Error(ErrorCode::kAuthInvalid, "JWT rejected: " + std::move(msg), std::move(field),
               std::move(reason));
}
Error key_error(std::string msg, std::string field = {}) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field));
}

struct PkeyFree {
  void operator()(EVP_PKEY* p) const { EVP_PKEY_free(p); }
};
using PkeyPtr = std::unique_ptr<EVP_PKEY, PkeyFree>;
struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
using BioPtr = std::unique_ptr<BIO, BioFree>;
struct MdCtxFree {
  void operator()(EVP_MD_CTX* c) const { EVP_MD_CTX_free(c); }
};
using MdCtxPtr = std::unique_ptr<EVP_MD_CTX, MdCtxFree>;
struct PkeyCtxFree {
  void operator()(EVP_PKEY_CTX* c) const { EVP_PKEY_CTX_free(c); }
};
using PkeyCtxPtr = std::unique_ptr<EVP_PKEY_CTX, PkeyCtxFree>;
struct BnFree {
  void operator()(BIGNUM* b) const { BN_free(b); }
};
using BnPtr = std::unique_ptr<BIGNUM, BnFree>;
struct ParamBldFree {
  void operator()(OSSL_PARAM_BLD* b) const { OSSL_PARAM_BLD_free(b); }
};
struct ParamFree {
  void operator()(OSSL_PARAM* p) const { OSSL_PARAM_free(p); }
};
struct EcdsaSigFree {
  void operator()(ECDSA_SIG* s) const { ECDSA_SIG_free(s); }
};

constexpr size_t kMaxPemBytes = 64 * 1024;
constexpr int kMinRsaBits = 2048;
constexpr int kMaxRsaBits = 8192;

// Classifies an OpenSSL key into the single JWS algorithm we allow for it.
Result<Alg> classify(EVP_PKEY* pk) {
  int id = EVP_PKEY_get_base_id(pk);
  if (id == EVP_PKEY_ED25519) return Alg::kEdDSA;
  if (id == EVP_PKEY_EC) {
    char group[64] = {0};
    size_t len = 0;
    if (EVP_PKEY_get_group_name(pk, group, sizeof group, &len) != 1)
      return key_error("EC key without a named curve");
    std::string g(group, len);
    if (g != "prime256v1" && g != "P-256" && g != "secp256r1")
      return key_error("EC key on curve " + g + ": only P-256 (ES256) is supported");
    return Alg::kES256;
  }
  if (id == EVP_PKEY_RSA) {
    int bits = EVP_PKEY_get_bits(pk);
    if (bits < kMinRsaBits)
      return key_error("RSA key of " + std::to_string(bits) + " bits: at least 2048 required");
    if (bits > kMaxRsaBits)
      return key_error("RSA key of " + std::to_string(bits) + " bits: at most 8192 supported");
    return Alg::kRS256;
  }
  return key_error("unsupported key type (need Ed25519, EC P-256 or RSA)");
}

// Strict base64url for JWS segments: url alphabet only, no padding, canonical bits. With no '='
// anywhere, nothing is stripped as padding and the url table refuses every other symbol.
std::optional<Bytes> b64url_segment(std::string_view s) {
  if (s.find('=') != std::string_view::npos || s.size() % 4 == 1) return std::nullopt;
  return base64url_decode(s);
}

std::optional<Bytes> jwk_b64(const json::Value& jwk, const char* name) {
  const json::Value* v = jwk.get(name);
  if (!v || !v->is_string() || v->as_string().empty()) return std::nullopt;
  return b64url_segment(v->as_string());
}

// ES256: JOSE raw r‖s (64 bytes) → DER ECDSA-Sig-Value.
std::optional<Bytes> es256_raw_to_der(std::span<const uint8_t> raw) {
  if (raw.size() != 64) return std::nullopt;
  std::unique_ptr<ECDSA_SIG, EcdsaSigFree> sig(ECDSA_SIG_new());
  if (!sig) return std::nullopt;
  BIGNUM* r = BN_bin2bn(raw.data(), 32, nullptr);
  BIGNUM* s = BN_bin2bn(raw.data() + 32, 32, nullptr);
  if (!r || !s || ECDSA_SIG_set0(sig.get(), r, s) != 1) {
    BN_free(r);
    BN_free(s);
    return std::nullopt;
  }
  int len = i2d_ECDSA_SIG(sig.get(), nullptr);
  if (len <= 0) return std::nullopt;
  Bytes der(static_cast<size_t>(len));
  unsigned char* p = der.data();
  if (i2d_ECDSA_SIG(sig.get(), &p) != len) return std::nullopt;
  return der;
}

std::optional<Bytes> es256_der_to_raw(std::span<const uint8_t> der) {
  const unsigned char* p = der.data();
  std::unique_ptr<ECDSA_SIG, EcdsaSigFree> sig(
      d2i_ECDSA_SIG(nullptr, &p, static_cast<long>(der.size())));
  if (!sig) return std::nullopt;
  const BIGNUM* r = nullptr;
  const BIGNUM* s = nullptr;
  ECDSA_SIG_get0(sig.get(), &r, &s);
  Bytes raw(64);
  if (BN_bn2binpad(r, raw.data(), 32) != 32 || BN_bn2binpad(s, raw.data() + 32, 32) != 32)
    return std::nullopt;
  return raw;
}

bool evp_verify(EVP_PKEY* pk, const EVP_MD* md, std::string_view input,
                std::span<const uint8_t> sig) {
  MdCtxPtr ctx(EVP_MD_CTX_new());
  if (!ctx) return false;
  bool ok =
      EVP_DigestVerifyInit(ctx.get(), nullptr, md, nullptr, pk) == 1 &&
      EVP_DigestVerify(ctx.get(), sig.data(), sig.size(),
                       reinterpret_cast<const unsigned char*>(input.data()), input.size()) == 1;
  ERR_clear_error();
  return ok;
}

int no_password(char*, int, int, void*) { return -1; }

std::string trim_secret_newline(std::string_view s) {
  if (s.size() >= 2 && s.substr(s.size() - 2) == "\r\n")
    return std::string(s.substr(0, s.size() - 2));
  if (!s.empty() && s.back() == '\n') return std::string(s.substr(0, s.size() - 1));
  return std::string(s);
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Algorithms

std::string_view alg_name(Alg alg) {
  switch (alg) {
    case Alg::kEdDSA:
      return "EdDSA";
    case Alg::kES256:
      return "ES256";
    case Alg::kRS256:
      return "RS256";
    case Alg::kHS256:
      return "HS256";
  }
  return "?";
}

std::optional<Alg> alg_from_name(std::string_view name) {
  if (name == "EdDSA") return Alg::kEdDSA;
  if (name == "ES256") return Alg::kES256;
  if (name == "RS256") return Alg::kRS256;
  if (name == "HS256") return Alg::kHS256;
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------
// VerificationKey

struct VerificationKey::Impl {
  PkeyPtr pkey;
  keys::SecretBytes secret;
};

VerificationKey::VerificationKey() = default;
VerificationKey::VerificationKey(const VerificationKey& other) = default;
VerificationKey& VerificationKey::operator=(const VerificationKey& other) = default;
VerificationKey::VerificationKey(VerificationKey&&) noexcept = default;
VerificationKey& VerificationKey::operator=(VerificationKey&&) noexcept = default;
VerificationKey::~VerificationKey() = default;

Result<VerificationKey> VerificationKey::from_pem(std::string_view pem) {
  if (pem.size() > kMaxPemBytes) return key_error("PEM key too large");
  if (pem.find("PRIVATE KEY") != std::string_view::npos)
    return key_error("a private key was given where a public key is expected");
  if (pem.find("-----BEGIN PUBLIC KEY-----") == std::string_view::npos)
    return key_error("not a PEM public key (expected -----BEGIN PUBLIC KEY-----)");
  BioPtr bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  if (!bio) return Error(ErrorCode::kInternal, "out of memory");
  PkeyPtr pk(PEM_read_bio_PUBKEY(bio.get(), nullptr, no_password, nullptr));
  ERR_clear_error();
  if (!pk) return key_error("malformed PEM public key");
  auto alg = classify(pk.get());
  if (!alg.ok()) return alg.error();
  VerificationKey k;
  k.alg_ = *alg;
  k.impl_ = std::make_shared<Impl>();
  k.impl_->pkey = std::move(pk);
  return k;
}

Result<VerificationKey> VerificationKey::ed25519_raw(std::span<const uint8_t> raw) {
  if (raw.size() != 32) return key_error("Ed25519 public key must be 32 bytes");
  PkeyPtr pk(EVP_PKEY_new_raw_public_key(EVP_PKEY_ED25519, nullptr, raw.data(), raw.size()));
  ERR_clear_error();
  if (!pk) return key_error("invalid Ed25519 public key");
  VerificationKey k;
  k.alg_ = Alg::kEdDSA;
  k.impl_ = std::make_shared<Impl>();
  k.impl_->pkey = std::move(pk);
  return k;
}

Result<VerificationKey> VerificationKey::hs256_secret(std::span<const uint8_t> secret) {
  if (secret.size() < kMinHs256SecretBytes)
    return key_error("HS256 secret must be at least 32 bytes, got " +
                     std::to_string(secret.size()));
  if (secret.size() > 4096) return key_error("HS256 secret larger than 4096 bytes");
  VerificationKey k;
  k.alg_ = Alg::kHS256;
  k.impl_ = std::make_shared<Impl>();
  k.impl_->secret = keys::SecretBytes(secret.data(), secret.size());
  return k;
}

Result<VerificationKey> VerificationKey::from_jwk(const json::Value& jwk, bool allow_secret) {
  if (!jwk.is_object()) return key_error("JWK is not a JSON object");
  const json::Value* kty = jwk.get("kty");
  if (!kty || !kty->is_string()) return key_error("JWK has no kty", "kty");
  const std::string& t = kty->as_string();
  if (const json::Value* use = jwk.get("use");
      use && !(use->is_string() && use->as_string() == "sig"))
    return key_error("JWK use must be \"sig\"", "use");
  std::string kid;
  if (const json::Value* k = jwk.get("kid")) {
    if (!k->is_string() || k->as_string().size() > 256)
      return key_error("JWK kid must be a short string", "kid");
    kid = k->as_string();
  }
  Result<VerificationKey> out = key_error("unsupported JWK");
  if (t == "OKP") {
    const json::Value* crv = jwk.get("crv");
    if (!crv || !crv->is_string() || crv->as_string() != "Ed25519")
      return key_error("OKP JWK must have crv Ed25519", "crv");
    if (jwk.get("d"))
      return key_error("JWK contains a private key (d); a public key is expected", "d");
    auto x = jwk_b64(jwk, "x");
    if (!x || x->size() != 32) return key_error("Ed25519 JWK x must be 32 bytes of base64url", "x");
    out = ed25519_raw(*x);
  } else if (t == "EC") {
    const json::Value* crv = jwk.get("crv");
    if (!crv || !crv->is_string() || crv->as_string() != "P-256")
      return key_error("EC JWK must have crv P-256", "crv");
    if (jwk.get("d"))
      return key_error("JWK contains a private key (d); a public key is expected", "d");
    auto x = jwk_b64(jwk, "x");
    auto y = jwk_b64(jwk, "y");
    if (!x || x->size() != 32) return key_error("P-256 JWK x must be 32 bytes of base64url", "x");
    if (!y || y->size() != 32) return key_error("P-256 JWK y must be 32 bytes of base64url", "y");
    Bytes point(65);
    point[0] = 0x04;
    std::copy(x->begin(), x->end(), point.begin() + 1);
    std::copy(y->begin(), y->end(), point.begin() + 33);
    std::unique_ptr<OSSL_PARAM_BLD, ParamBldFree> bld(OSSL_PARAM_BLD_new());
    if (!bld) return Error(ErrorCode::kInternal, "out of memory");
    OSSL_PARAM_BLD_push_utf8_string(bld.get(), OSSL_PKEY_PARAM_GROUP_NAME, "P-256", 0);
    OSSL_PARAM_BLD_push_octet_string(bld.get(), OSSL_PKEY_PARAM_PUB_KEY, point.data(),
                                     point.size());
    std::unique_ptr<OSSL_PARAM, ParamFree> params(OSSL_PARAM_BLD_to_param(bld.get()));
    PkeyCtxPtr ctx(EVP_PKEY_CTX_new_from_name(nullptr, "EC", nullptr));
    EVP_PKEY* raw = nullptr;
    if (!params || !ctx || EVP_PKEY_fromdata_init(ctx.get()) != 1 ||
        EVP_PKEY_fromdata(ctx.get(), &raw, EVP_PKEY_PUBLIC_KEY, params.get()) != 1) {
      ERR_clear_error();
      return key_error("P-256 JWK is not a valid curve point", "x");
    }
    PkeyPtr pk(raw);
    PkeyCtxPtr check(EVP_PKEY_CTX_new_from_pkey(nullptr, pk.get(), nullptr));
    if (!check || EVP_PKEY_public_check(check.get()) != 1) {
      ERR_clear_error();
      return key_error("P-256 JWK is not a valid curve point", "x");
    }
    VerificationKey k;
    k.alg_ = Alg::kES256;
    k.impl_ = std::make_shared<Impl>();
    k.impl_->pkey = std::move(pk);
    out = std::move(k);
  } else if (t == "RSA") {
    if (jwk.get("d"))
      return key_error("JWK contains a private key (d); a public key is expected", "d");
    auto n = jwk_b64(jwk, "n");
    auto e = jwk_b64(jwk, "e");
    if (!n || n->size() < kMinRsaBits / 8 - 1 || n->size() > kMaxRsaBits / 8 + 1)
      return key_error("RSA JWK n must be a 2048..8192-bit modulus", "n");
    if (!e || e->empty() || e->size() > 8) return key_error("RSA JWK e is malformed", "e");
    BnPtr bn_n(BN_bin2bn(n->data(), static_cast<int>(n->size()), nullptr));
    BnPtr bn_e(BN_bin2bn(e->data(), static_cast<int>(e->size()), nullptr));
    if (!bn_n || !bn_e) return Error(ErrorCode::kInternal, "out of memory");
    if (!BN_is_odd(bn_e.get()) || BN_is_one(bn_e.get()) || !BN_is_odd(bn_n.get()))
      return key_error("RSA JWK has an invalid modulus or exponent", "e");
    std::unique_ptr<OSSL_PARAM_BLD, ParamBldFree> bld(OSSL_PARAM_BLD_new());
    if (!bld) return Error(ErrorCode::kInternal, "out of memory");
    OSSL_PARAM_BLD_push_BN(bld.get(), OSSL_PKEY_PARAM_RSA_N, bn_n.get());
    OSSL_PARAM_BLD_push_BN(bld.get(), OSSL_PKEY_PARAM_RSA_E, bn_e.get());
    std::unique_ptr<OSSL_PARAM, ParamFree> params(OSSL_PARAM_BLD_to_param(bld.get()));
    PkeyCtxPtr ctx(EVP_PKEY_CTX_new_from_name(nullptr, "RSA", nullptr));
    EVP_PKEY* raw = nullptr;
    if (!params || !ctx || EVP_PKEY_fromdata_init(ctx.get()) != 1 ||
        EVP_PKEY_fromdata(ctx.get(), &raw, EVP_PKEY_PUBLIC_KEY, params.get()) != 1) {
      ERR_clear_error();
      return key_error("RSA JWK could not be imported", "n");
    }
    PkeyPtr pk(raw);
    auto alg = classify(pk.get());
    if (!alg.ok()) return alg.error();
    VerificationKey k;
    k.alg_ = Alg::kRS256;
    k.impl_ = std::make_shared<Impl>();
    k.impl_->pkey = std::move(pk);
    out = std::move(k);
  } else if (t == "oct") {
    if (!allow_secret)
      return key_error(
          "symmetric (oct) JWK refused: HS256 keys must be configured as a shared secret", "kty");
    auto k = jwk_b64(jwk, "k");
    if (!k) return key_error("oct JWK k is malformed", "k");
    out = hs256_secret(*k);
    secure_wipe(k->data(), k->size());
  } else {
    return key_error("unsupported JWK kty \"" + t + "\"", "kty");
  }
  if (!out.ok()) return out;
  if (const json::Value* a = jwk.get("alg")) {
    if (!a->is_string() || a->as_string() != alg_name(out->alg()))
      return key_error("JWK alg does not match its key type (expected " +
                           std::string(alg_name(out->alg())) + ")",
                       "alg");
  }
  out->kid_ = std::move(kid);
  return out;
}

bool VerificationKey::verify(std::string_view input, std::span<const uint8_t> sig) const {
  if (!impl_) return false;
  switch (alg_) {
    case Alg::kHS256: {
      if (sig.size() != 32 || impl_->secret.empty()) return false;
      Digest256 mac =
          hmac_sha256(impl_->secret.data(), impl_->secret.size(), input.data(), input.size());
      bool ok = constant_time_equal(
          std::string_view(reinterpret_cast<const char*>(mac.data()), mac.size()),
          std::string_view(reinterpret_cast<const char*>(sig.data()), sig.size()));
      secure_wipe(mac.data(), mac.size());
      return ok;
    }
    case Alg::kEdDSA:
      if (sig.size() != 64) return false;
      return evp_verify(impl_->pkey.get(), nullptr, input, sig);
    case Alg::kES256: {
      auto der = es256_raw_to_der(sig);
      if (!der) return false;
      return evp_verify(impl_->pkey.get(), EVP_sha256(), input, *der);
    }
    case Alg::kRS256: {
      if (sig.size() != static_cast<size_t>(EVP_PKEY_get_size(impl_->pkey.get()))) return false;
      return evp_verify(impl_->pkey.get(), EVP_sha256(), input, sig);
    }
  }
  return false;
}

Result<std::vector<VerificationKey>> parse_jwk_set(std::string_view text) {
  json::ParseOptions po;
  po.max_depth = 8;
  po.max_bytes = 1 << 20;
  auto doc = json::parse(text, po);
  if (!doc.ok()) return key_error("JWK/JWKS is not valid JSON: " + doc.error().message);
  std::vector<VerificationKey> out;
  if (const json::Value* ks = doc->get("keys")) {
    if (!ks->is_array() || ks->as_array().empty())
      return key_error("JWKS keys must be a non-empty array", "keys");
    size_t i = 0;
    for (const auto& k : ks->as_array()) {
      auto vk = VerificationKey::from_jwk(k, false);
      if (!vk.ok())
        return key_error("JWKS key " + std::to_string(i) + ": " + vk.error().message,
                         vk.error().field);
      out.push_back(std::move(vk).value());
      ++i;
    }
    return out;
  }
  auto vk = VerificationKey::from_jwk(*doc, false);
  if (!vk.ok()) return vk.error();
  out.push_back(std::move(vk).value());
  return out;
}

Result<std::vector<VerificationKey>> load_verification_keys(const std::string& path,
                                                            bool hs256_secret) {
  if (hs256_secret) {
    auto s = keys::read_secret_file(path, 0);
    if (!s.ok()) return s.error();
    std::string trimmed = trim_secret_newline(s->view());
    auto k = VerificationKey::hs256_secret(
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(trimmed.data()), trimmed.size()));
    secure_wipe(trimmed.data(), trimmed.size());
    if (!k.ok()) return Error(k.error().code, path + ": " + k.error().message, path);
    return std::vector<VerificationKey>{std::move(k).value()};
  }
  auto data = keys::read_public_file(path, 1 << 20);
  if (!data.ok()) return data.error();
  std::string_view text(reinterpret_cast<const char*>(data->data()), data->size());
  if (text.find("PRIVATE KEY") != std::string_view::npos)
    return key_error(path + " holds a private key; configure the public key instead", path);
  if (text.find("-----BEGIN") != std::string_view::npos) {
    auto k = VerificationKey::from_pem(text);
    if (!k.ok()) return Error(k.error().code, path + ": " + k.error().message, path);
    return std::vector<VerificationKey>{std::move(k).value()};
  }
  auto ks = parse_jwk_set(text);
  if (!ks.ok()) return Error(ks.error().code, path + ": " + ks.error().message, path);
  return ks;
}

// ---------------------------------------------------------------------------------------
// TrustStore

void TrustStore::add(std::string issuer, VerificationKey key, std::string kid) {
  if (kid.empty()) kid = key.kid();
  entries_.push_back(Entry{std::move(issuer), std::move(kid), std::move(key)});
}

bool TrustStore::knows_issuer(std::string_view issuer) const {
  return std::any_of(entries_.begin(), entries_.end(),
                     [&](const Entry& e) { return e.issuer == issuer; });
}

std::vector<const VerificationKey*> TrustStore::candidates(std::string_view issuer,
                                                           std::string_view kid) const {
  std::vector<const VerificationKey*> with_kid, without_kid;
  for (const auto& e : entries_) {
    if (e.issuer != issuer) continue;
    if (kid.empty()) {
      with_kid.push_back(&e.key);
    } else if (e.kid == kid) {
      with_kid.push_back(&e.key);
    } else if (e.kid.empty()) {
      without_kid.push_back(&e.key);
    }
  }
  if (!with_kid.empty()) return with_kid;
  return without_kid;
}

Result<TrustStore> TrustStore::from_config(const std::vector<IssuerConfig>& issuers) {
  TrustStore ts;
  for (const auto& ic : issuers) {
    if (ic.issuer.empty()) return key_error("trusted issuer with an empty name", "issuer");
    if (ic.key_file.empty())
      return key_error("trusted issuer " + ic.issuer + " has no key file", "key_file");
    bool secret = false;
    if (ic.kind == "hs256_secret") {
      secret = true;
    } else if (ic.kind != "auto" && !ic.kind.empty()) {
      return key_error("trusted issuer " + ic.issuer + ": unknown key kind \"" + ic.kind +
                           "\" (auto | hs256_secret)",
                       "kind");
    }
    auto ks = load_verification_keys(ic.key_file, secret);
    if (!ks.ok()) return ks.error();
    for (auto& k : *ks) ts.add(ic.issuer, std::move(k), ic.kid);
  }
  return ts;
}

// ---------------------------------------------------------------------------------------
// Decoding

Result<Decoded> decode(std::string_view token, size_t max_token_bytes) {
  if (token.empty()) return Error(ErrorCode::kAuthRequired, "no token");
  if (token.size() > max_token_bytes)
    return auth_invalid("token is " + std::to_string(token.size()) + " bytes, limit " +
                            std::to_string(max_token_bytes),
                        "", "oversize");
  size_t d1 = token.find('.');
  size_t d2 = d1 == std::string_view::npos ? d1 : token.find('.', d1 + 1);
  if (d1 == std::string_view::npos || d2 == std::string_view::npos ||
      token.find('.', d2 + 1) != std::string_view::npos)
    return auth_invalid("not a JWS compact token (needs exactly three dot-separated parts)", "",
                        "malformed");
  std::string_view h64 = token.substr(0, d1);
  std::string_view p64 = token.substr(d1 + 1, d2 - d1 - 1);
  std::string_view s64 = token.substr(d2 + 1);
  if (h64.empty() || p64.empty()) return auth_invalid("empty header or payload", "", "malformed");
  auto hb = b64url_segment(h64);
  if (!hb)
    return auth_invalid("header is not base64url (no padding allowed)", "header", "malformed");
  auto pb = b64url_segment(p64);
  if (!pb)
    return auth_invalid("payload is not base64url (no padding allowed)", "payload", "malformed");
  auto sb = b64url_segment(s64);
  if (!sb)
    return auth_invalid("signature is not base64url (no padding allowed)", "signature",
                        "malformed");

  json::ParseOptions hopts;
  hopts.max_depth = 4;
  hopts.max_bytes = hb->size();
  auto header =
      json::parse(std::string_view(reinterpret_cast<const char*>(hb->data()), hb->size()), hopts);
  if (!header.ok())
    return auth_invalid("header is not JSON: " + header.error().message, "header", "malformed");
  if (!header->is_object())
    return auth_invalid("header is not a JSON object", "header", "malformed");
  json::ParseOptions popts;
  popts.max_depth = 16;
  popts.max_bytes = pb->size();
  auto claims =
      json::parse(std::string_view(reinterpret_cast<const char*>(pb->data()), pb->size()), popts);
  if (!claims.ok())
    return auth_invalid("claims are not JSON: " + claims.error().message, "payload", "malformed");
  if (!claims->is_object())
    return auth_invalid("claims are not a JSON object", "payload", "malformed");

  Decoded d;
  d.header.raw = std::move(header->as_object());
  const json::Value* alg = d.header.raw.find("alg");
  if (!alg || !alg->is_string()) return auth_invalid("header has no alg", "alg", "malformed");
  d.header.alg = alg->as_string();
  if (const json::Value* kid = d.header.raw.find("kid")) {
    if (!kid->is_string()) return auth_invalid("header kid is not a string", "kid", "malformed");
    d.header.kid = kid->as_string();
  }
  if (const json::Value* typ = d.header.raw.find("typ")) {
    if (!typ->is_string()) return auth_invalid("header typ is not a string", "typ", "malformed");
    d.header.typ = typ->as_string();
  }
  d.claims = std::move(claims->as_object());
  d.signing_input = std::string(token.substr(0, d2));
  d.signature = std::move(*sb);
  return d;
}

// ---------------------------------------------------------------------------------------
// Claims

int role_level(std::string_view r) {
  auto role = rcan::role_from_name(r);
  return role ? rcan::role_level(*role) : 0;
}

std::string_view role_name(int level) {
  if (level < 1 || level > 5) return "";
  return rcan::role_claim_name(static_cast<rcan::Role>(level));
}

int role_level_from_rcan_role(const json::Value& v) {
  if (!v.is_int() && !v.is_double()) return 0;
  double d = v.is_int() ? static_cast<double>(v.as_int()) : v.as_double();
  auto role = rcan::role_from_rcan_level(d);
  return role ? rcan::role_level(*role) : 0;
}

int scope_min_level(std::string_view s) {
  auto role = rcan::scope_min_role(s);
  return role ? rcan::role_level(*role) : rcan::role_level(rcan::Role::kUser);
}

namespace {

std::string lower(std::string_view s) {
  std::string o(s);
  for (char& c : o)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return o;
}

// NumericDate (RFC 7519 §2): integer or finite float seconds; floats are floored.
Result<std::optional<int64_t>> numeric_date(const json::Object& c, const char* name) {
  const json::Value* v = c.find(name);
  if (!v) return std::optional<int64_t>{};
  if (v->is_int()) return std::optional<int64_t>{v->as_int()};
  if (v->is_double()) {
    double d = v->as_double();
    if (std::isfinite(d) && std::fabs(d) < 1e15)
      return std::optional<int64_t>{static_cast<int64_t>(std::floor(d))};
  }
  return auth_invalid(std::string(name) + " is not a valid NumericDate", name, "malformed");
}

// Appends scopes from a claim that is an array of strings or a space-separated string.
Status collect_scopes(const json::Object& c, const char* name, std::vector<std::string>& out) {
  const json::Value* v = c.find(name);
  if (!v) return Status::Ok();
  auto add = [&](std::string_view s) {
    if (std::find(out.begin(), out.end(), s) == out.end()) out.emplace_back(s);
  };
  if (v->is_string()) {
    std::string_view s = v->as_string();
    size_t i = 0;
    while (i < s.size()) {
      size_t sp = s.find(' ', i);
      std::string_view tok =
          s.substr(i, sp == std::string_view::npos ? std::string_view::npos : sp - i);
      if (!tok.empty()) add(tok);
      if (sp == std::string_view::npos) break;
      i = sp + 1;
    }
    return Status::Ok();
  }
  if (v->is_array()) {
    for (const auto& e : v->as_array()) {
      if (!e.is_string() || e.as_string().empty())
        return auth_invalid(std::string(name) + " must contain only non-empty strings", name,
                            "malformed");
      add(e.as_string());
    }
    return Status::Ok();
  }
  return auth_invalid(std::string(name) + " must be an array or a space-separated string", name,
                      "malformed");
}

Result<std::string> optional_string(const json::Object& c, const char* name) {
  const json::Value* v = c.find(name);
  if (!v) return std::string();
  if (!v->is_string())
    return auth_invalid(std::string(name) + " must be a string", name, "malformed");
  return v->as_string();
}

}  // namespace

bool aud_matches(std::string_view pattern, std::string_view ruri) {
  auto robot = rcan::parse_ruri(ruri);
  if (!robot.ok()) return false;
  return rcan::aud_matches(pattern, *robot);
}

bool Claims::has_scope(std::string_view s) const {
  return std::find(scopes.begin(), scopes.end(), s) != scopes.end();
}

Result<Claims> check_claims(json::Object c, const VerifyOptions& opts, int64_t now) {
  Claims out;
  // Identity strings.
  auto iss = optional_string(c, "iss");
  if (!iss.ok()) return iss.error();
  out.iss = *iss;
  auto sub = optional_string(c, "sub");
  if (!sub.ok()) return sub.error();
  if (sub->empty()) return auth_invalid("sub is missing", "sub", "missing_claim");
  out.sub = *sub;
  auto jti = optional_string(c, "jti");
  if (!jti.ok()) return jti.error();
  out.jti = *jti;

  // Time.
  auto exp = numeric_date(c, "exp");
  if (!exp.ok()) return exp.error();
  auto nbf = numeric_date(c, "nbf");
  if (!nbf.ok()) return nbf.error();
  auto iat = numeric_date(c, "iat");
  if (!iat.ok()) return iat.error();
  out.exp = *exp;
  out.nbf = *nbf;
  out.iat = *iat;
  const int64_t leeway = std::max<int64_t>(0, opts.leeway_s);
  if (!out.exp) return auth_invalid("exp is missing", "exp", "missing_claim");
  if (now >= *out.exp + leeway) return auth_invalid("token expired", "exp", "expired");
  if (out.nbf && now + leeway < *out.nbf)
    return auth_invalid("token not yet valid (nbf)", "nbf", "not_yet_valid");
  if (opts.require_iat && !out.iat) return auth_invalid("iat is missing", "iat", "missing_claim");
  if (out.iat && now + leeway < *out.iat)
    return auth_invalid("token issued in the future (iat)", "iat", "iat_in_future");

  // Audience.
  if (const json::Value* aud = c.find("aud")) {
    if (aud->is_string()) {
      out.aud.push_back(aud->as_string());
    } else if (aud->is_array() && !aud->as_array().empty()) {
      for (const auto& a : aud->as_array()) {
        if (!a.is_string())
          return auth_invalid("aud must contain only strings", "aud", "malformed");
        out.aud.push_back(a.as_string());
      }
    } else {
      return auth_invalid("aud must be a string or a non-empty array of strings", "aud",
                          "malformed");
    }
  }
  if (!opts.skip_audience) {
    if (out.aud.empty()) return auth_invalid("aud is missing", "aud", "missing_claim");
    if (opts.audience.empty())
      return auth_invalid("this verifier has no audience (robot RURI) configured", "aud",
                          "aud_mismatch");
    bool fleet_token = c.find("fleet") != nullptr;
    bool match = std::any_of(out.aud.begin(), out.aud.end(), [&](const std::string& a) {
      if (fleet_token && std::find(opts.fleet_audiences.begin(), opts.fleet_audiences.end(), a) !=
                             opts.fleet_audiences.end())
        return true;
      return aud_matches(a, opts.audience);
    });
    if (!match)
      return auth_invalid("aud does not match this robot (" + opts.audience + ")", "aud",
                          "aud_mismatch");
  }

  // §8.5 sender identity.
  auto st = optional_string(c, "sender_type");
  if (!st.ok()) return st.error();
  out.sender_type = *st;
  auto cp = optional_string(c, "cloud_provider");
  if (!cp.ok()) return cp.error();
  out.cloud_provider = *cp;
  auto fn = optional_string(c, "function_name");
  if (!fn.ok()) return fn.error();
  out.function_name = *fn;
  if (c.find("sender_type")) {
    const std::string& s = out.sender_type;
    if (s != "human" && s != "robot" && s != "cloud_function" && s != "system")
      return auth_invalid("unknown sender_type \"" + s + "\"", "sender_type", "bad_sender_type");
    if (s == "cloud_function" && out.cloud_provider.empty())
      return auth_invalid("sender_type cloud_function without cloud_provider (RCAN §8.5)",
                          "cloud_provider", "missing_cloud_provider");
  }

  // Role.
  int level_named = 0, level_numeric = 0;
  if (const json::Value* r = c.find("role")) {
    if (!r->is_string()) return auth_invalid("role must be a string", "role", "bad_role");
    level_named = role_level(r->as_string());
    if (level_named == 0)
      return auth_invalid("unknown role \"" + r->as_string() + "\"", "role", "bad_role");
  }
  if (const json::Value* r = c.find("rcan_role")) {
    level_numeric = role_level_from_rcan_role(*r);
    if (level_numeric == 0)
      return auth_invalid("rcan_role must be 1, 2, 2.5, 3 or 5", "rcan_role", "bad_role");
  }
  if (level_named && level_numeric && level_named != level_numeric)
    return auth_invalid("role and rcan_role disagree", "role", "bad_role");
  out.role_level = level_named ? level_named : level_numeric;
  if (out.role_level == 0) {
    if (opts.require_role) return auth_invalid("token carries no role", "role", "missing_claim");
    out.role_level = 1;
  }
  out.role = std::string(role_name(out.role_level));

  // Scopes.
  for (const char* name : {"scope", "scopes", "rcan_scopes"}) {
    Status s = collect_scopes(c, name, out.scopes);
    if (!s.ok()) return s.error();
  }
  if (!opts.required_scope.empty()) {
    if (!out.has_scope(opts.required_scope))
      return Error(ErrorCode::kInsufficientPrivileges, "token lacks scope " + opts.required_scope,
                   "scope");
    if (out.role_level < scope_min_level(opts.required_scope))
      return Error(ErrorCode::kInsufficientPrivileges,
                   "role " + out.role + " may not use scope " + opts.required_scope, "scope");
  }

  // Fleet.
  if (const json::Value* f = c.find("fleet")) {
    if (!f->is_array())
      return auth_invalid("fleet must be an array of strings", "fleet", "malformed");
    std::vector<std::string> fleet;
    for (const auto& e : f->as_array()) {
      if (!e.is_string())
        return auth_invalid("fleet must be an array of strings", "fleet", "malformed");
      fleet.push_back(e.as_string());
    }
    bool member = std::any_of(fleet.begin(), fleet.end(), [&](const std::string& id) {
      return std::find(opts.fleet_ids.begin(), opts.fleet_ids.end(), id) != opts.fleet_ids.end();
    });
    if (!member && !opts.skip_fleet)
      return auth_invalid("this device is not in the token's fleet", "fleet", "fleet_mismatch");
    out.fleet = std::move(fleet);
  }
  out.raw = std::move(c);
  return out;
}

// ---------------------------------------------------------------------------------------
// JwtVerifier

Result<Claims> JwtVerifier::verify(std::string_view token, int64_t now) const {
  auto d = decode(token, opts_.max_token_bytes);
  if (!d.ok()) return d.error();
  const std::string& alg_s = d->header.alg;
  if (lower(alg_s) == "none") return auth_invalid("alg none is not accepted", "alg", "alg_none");
  auto alg = alg_from_name(alg_s);
  if (!alg) return auth_invalid("unsupported alg \"" + alg_s + "\"", "alg", "bad_alg");
  if (d->header.raw.find("crit"))
    return auth_invalid("crit header parameters are not supported", "crit", "crit");

  const json::Value* iss = d->claims.find("iss");
  if (!iss || !iss->is_string() || iss->as_string().empty())
    return auth_invalid("iss is missing", "iss", "missing_claim");
  if (!trust_.knows_issuer(iss->as_string()))
    return auth_invalid("issuer \"" + iss->as_string() + "\" is not trusted", "iss",
                        "untrusted_issuer");
  auto cands = trust_.candidates(iss->as_string(), d->header.kid);
  if (cands.empty())
    return auth_invalid("issuer has no key with kid \"" + d->header.kid + "\"", "kid",
                        "unknown_kid");
  bool any_alg = false, verified = false;
  for (const VerificationKey* k : cands) {
    if (k->alg() != *alg) continue;
    any_alg = true;
    if (k->verify(d->signing_input, d->signature)) {
      verified = true;
      break;
    }
  }
  if (!any_alg)
    return auth_invalid(
        "alg " + alg_s + " does not match the issuer's key type (algorithm confusion refused)",
        "alg", "alg_mismatch");
  if (!verified) return auth_invalid("signature does not verify", "signature", "bad_signature");
  auto claims = check_claims(std::move(d->claims), opts_, now);
  if (claims.ok()) claims->kid = d->header.kid;
  return claims;
}

Result<Claims> JwtVerifier::verify(std::string_view token) const {
  auto now = std::chrono::duration_cast<std::chrono::seconds>(
                 std::chrono::system_clock::now().time_since_epoch())
                 .count();
  return verify(token, static_cast<int64_t>(now));
}

// ---------------------------------------------------------------------------------------
// SigningKey and issuing

struct SigningKey::Impl {
  PkeyPtr pkey;
  keys::SecretBytes secret;
};

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

Result<Bytes> SigningKey::sign(std::string_view input) const {
  const auto* in = reinterpret_cast<const unsigned char*>(input.data());
  if (alg_ == Alg::kHS256) {
    Digest256 mac =
        hmac_sha256(impl_->secret.data(), impl_->secret.size(), input.data(), input.size());
    return Bytes(mac.begin(), mac.end());
  }
  MdCtxPtr ctx(EVP_MD_CTX_new());
  const EVP_MD* md = alg_ == Alg::kEdDSA ? nullptr : EVP_sha256();
  size_t len = 0;
  if (!ctx || EVP_DigestSignInit(ctx.get(), nullptr, md, nullptr, impl_->pkey.get()) != 1 ||
      EVP_DigestSign(ctx.get(), nullptr, &len, in, input.size()) != 1) {
    ERR_clear_error();
    return Error(ErrorCode::kInternal, "signing failed");
  }
  Bytes sig(len);
  if (EVP_DigestSign(ctx.get(), sig.data(), &len, in, input.size()) != 1) {
    ERR_clear_error();
    return Error(ErrorCode::kInternal, "signing failed");
  }
  sig.resize(len);
  if (alg_ == Alg::kES256) {
    auto raw = es256_der_to_raw(sig);
    if (!raw) return Error(ErrorCode::kInternal, "ECDSA signature conversion failed");
    return *raw;
  }
  return sig;
}

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
