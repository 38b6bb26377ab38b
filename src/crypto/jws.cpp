// The JWS compact serialisation and its signature algorithms (RFC 7515; see
// include/rcan/crypto/jwt.h): alg names, strict base64url segments, decode() (syntax only:
// three segments, JSON-object header and claims, a string `alg`), and the signature of each
// algorithm — Ed25519 (EdDSA), ECDSA P-256 + SHA-256 (ES256, the JOSE raw r‖s signature
// converted to/from DER), RSASSA-PKCS1-v1_5 + SHA-256 (RS256) and HMAC-SHA-256 (HS256,
// compared in constant time).
//
// All signature work goes through OpenSSL EVP directly, so the verifier depends on nothing but
// libcrypto. Verification answers only true or false (every OpenSSL error is cleared).
#include <openssl/ec.h>
#include <openssl/err.h>

#include "crypto/jwt_internal.h"
#include "rcan/crypto/jwt.h"
#include "rcan/hash.h"

namespace rcan::jwt {

using detail::auth_invalid;
using detail::b64url_segment;
using detail::MdCtxPtr;

namespace detail {

// Strict base64url for JWS segments: url alphabet only, no padding, canonical bits. With no '='
// anywhere, nothing is stripped as padding and the url table refuses every other symbol.
std::optional<Bytes> b64url_segment(std::string_view s) {
  if (s.find('=') != std::string_view::npos || s.size() % 4 == 1) return std::nullopt;
  return base64url_decode(s);
}

}  // namespace detail

namespace {

struct EcdsaSigFree {
  void operator()(ECDSA_SIG* s) const { ECDSA_SIG_free(s); }
};

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
// Signatures: verifying with a public key or secret, signing with a private key or secret

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

}  // namespace rcan::jwt
