// What the JWT units share (private to src/crypto): the error shapes, OpenSSL ownership types,
// the key classification that decides a key's one algorithm, strict base64url segments, and
// the key objects' storage. Not part of librcan's interface.
//
// The units: jwt_keys.cpp (verification keys from PEM, JWK, JWKS and files; the trust store),
// jws.cpp (the compact serialisation and the four signature algorithms), jwt_claims.cpp (the
// RCAN claim policy), jwt_signing.cpp (signing keys and issuing), jwt.cpp (the verifier that
// runs them in the order of include/rcan/crypto/jwt.h).
#pragma once

#include <openssl/bio.h>
#include <openssl/bn.h>
#include <openssl/evp.h>
#include <openssl/param_build.h>

#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/encoding.h"
#include "rcan/result.h"

namespace rcan::jwt {
namespace detail {

// A token refused: kAuthInvalid, "JWT rejected: …", with the claim (`field`) and a short
// machine-readable `reason`.
inline Error auth_invalid(std::string msg, std::string field = {}, std::string reason = {}) {
  return Error(ErrorCode::kAuthInvalid, "JWT rejected: " + std::move(msg), std::move(field),
               std::move(reason));
}
// A key (or key file) refused: kSchemaValidationFailed.
inline Error key_error(std::string msg, std::string field = {}) {
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

inline constexpr size_t kMaxPemBytes = 64 * 1024;
inline constexpr int kMinRsaBits = 2048;
inline constexpr int kMaxRsaBits = 8192;

// The single JWS algorithm allowed for an OpenSSL key (Ed25519 → EdDSA, P-256 → ES256,
// RSA 2048..8192 bits → RS256); any other key is refused (jwt_keys.cpp).
Result<Alg> classify(EVP_PKEY* pk);
// PEM password callback that refuses: encrypted keys are not read.
int no_password(char*, int, int, void*);
// A shared-secret file's text minus one trailing "\n" or "\r\n".
std::string trim_secret_newline(std::string_view s);

// Strict base64url for JWS segments: url alphabet only, no padding, canonical bits (jws.cpp).
std::optional<Bytes> b64url_segment(std::string_view s);

}  // namespace detail

// A key's material: an OpenSSL key (EdDSA, ES256, RS256), or the HS256 shared secret.
struct VerificationKey::Impl {
  detail::PkeyPtr pkey;
  keys::SecretBytes secret;
};
struct SigningKey::Impl {
  detail::PkeyPtr pkey;
  keys::SecretBytes secret;
};

}  // namespace rcan::jwt
