// Verification keys and the trust store (see include/rcan/crypto/jwt.h): SubjectPublicKeyInfo
// PEM, one JWK (OKP/Ed25519, EC/P-256, RSA, and `oct` only where a shared secret is allowed),
// a JWKS, raw Ed25519 keys, HS256 secrets and the files that hold them; the issuers a node
// trusts and the keys each may sign with.
//
// Contract: every key gets exactly one algorithm from its type (detail::classify), so a token's
// `alg` can never make a key verify under another algorithm; private material (a PEM private
// key, a JWK `d`) is refused where a public key is expected. Errors: kSchemaValidationFailed.
#include <openssl/core_names.h>
#include <openssl/err.h>
#include <openssl/pem.h>

#include <algorithm>

#include "crypto/jwt_internal.h"
#include "rcan/crypto/jwt.h"
#include "rcan/hash.h"

namespace rcan::jwt {

using detail::b64url_segment;
using detail::BioPtr;
using detail::BnPtr;
using detail::classify;
using detail::key_error;
using detail::kMaxPemBytes;
using detail::kMaxRsaBits;
using detail::kMinRsaBits;
using detail::no_password;
using detail::ParamBldFree;
using detail::ParamFree;
using detail::PkeyCtxPtr;
using detail::PkeyPtr;
using detail::trim_secret_newline;

namespace detail {

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

int no_password(char*, int, int, void*) { return -1; }

std::string trim_secret_newline(std::string_view s) {
  if (s.size() >= 2 && s.substr(s.size() - 2) == "\r\n")
    return std::string(s.substr(0, s.size() - 2));
  if (!s.empty() && s.back() == '\n') return std::string(s.substr(0, s.size() - 1));
  return std::string(s);
}

}  // namespace detail

namespace {

std::optional<Bytes> jwk_b64(const json::Value& jwk, const char* name) {
  const json::Value* v = jwk.get(name);
  if (!v || !v->is_string() || v->as_string().empty()) return std::nullopt;
  return b64url_segment(v->as_string());
}

// A P-256 public key from a JWK's x and y (checked to be a point on the curve).
Result<PkeyPtr> ec_p256_pkey(const json::Value& jwk) {
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
  OSSL_PARAM_BLD_push_octet_string(bld.get(), OSSL_PKEY_PARAM_PUB_KEY, point.data(), point.size());
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
  return pk;
}

// An RSA public key from a JWK's n and e (2048..8192-bit odd modulus, odd exponent > 1).
Result<PkeyPtr> rsa_pkey(const json::Value& jwk) {
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
  return pk;
}

// The raw Ed25519 public key of an OKP JWK.
Result<Bytes> okp_ed25519_x(const json::Value& jwk) {
  const json::Value* crv = jwk.get("crv");
  if (!crv || !crv->is_string() || crv->as_string() != "Ed25519")
    return key_error("OKP JWK must have crv Ed25519", "crv");
  if (jwk.get("d"))
    return key_error("JWK contains a private key (d); a public key is expected", "d");
  auto x = jwk_b64(jwk, "x");
  if (!x || x->size() != 32) return key_error("Ed25519 JWK x must be 32 bytes of base64url", "x");
  return std::move(*x);
}

// The JWK's kid ("" when absent); at most 256 characters.
Result<std::string> jwk_kid(const json::Value& jwk) {
  const json::Value* k = jwk.get("kid");
  if (!k) return std::string();
  if (!k->is_string() || k->as_string().size() > 256)
    return key_error("JWK kid must be a short string", "kid");
  return k->as_string();
}

}  // namespace

// ---------------------------------------------------------------------------------------
// VerificationKey

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
  auto kid = jwk_kid(jwk);
  if (!kid.ok()) return kid.error();
  Result<VerificationKey> out = key_error("unsupported JWK");
  if (t == "OKP") {
    auto x = okp_ed25519_x(jwk);
    if (!x.ok()) return x.error();
    out = ed25519_raw(*x);
  } else if (t == "EC" || t == "RSA") {
    auto pk = t == "EC" ? ec_p256_pkey(jwk) : rsa_pkey(jwk);
    if (!pk.ok()) return pk.error();
    VerificationKey k;
    k.alg_ = t == "EC" ? Alg::kES256 : Alg::kRS256;
    k.impl_ = std::make_shared<Impl>();
    k.impl_->pkey = std::move(*pk);
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
  out->kid_ = std::move(*kid);
  return out;
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

}  // namespace rcan::jwt
