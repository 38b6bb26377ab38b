#include "rcan/crypto/cnf.h"

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"

namespace rcan::cnf {
namespace {

Error bad(const std::string& what, const std::string& field) {
  return Error(ErrorCode::kAuthInvalid, "cnf: " + what, field);
}

}  // namespace

Result<BoundKey> parse(const json::Value& cnf) {
  if (!cnf.is_object()) return bad("must be an object", "cnf");
  for (const auto& [k, v] : cnf.as_object()) {
    (void)v;
    if (k != "jwk") return bad("only a jwk confirmation key is supported (not " + k + ")", "cnf");
  }
  const json::Value* jwk = cnf.get("jwk");
  if (jwk == nullptr || !jwk->is_object()) return bad("jwk must be an object", "cnf.jwk");
  if (json::string_field(*jwk, "kty") != "OKP")
    return bad("jwk.kty must be \"OKP\"", "cnf.jwk.kty");
  const std::string crv = json::string_field(*jwk, "crv");
  BoundKey k;
  if (crv == "Ed25519") {
    auto x = base64url_decode(json::string_field(*jwk, "x"));
    if (!x || x->size() != ed25519::kPublicKeyBytes)
      return bad("jwk.x must be a base64url Ed25519 public key (32 bytes)", "cnf.jwk.x");
    k.alg = msgsig::Alg::kEd25519;
    k.public_key = std::move(*x);
    auto kid = keys::ed25519_kid(k.public_key);
    if (!kid.ok()) return bad("jwk.x is not an Ed25519 public key", "cnf.jwk.x");
    k.kid = *kid;
  } else if (crv == "ML-DSA-65") {
    auto pk = keys::mldsa65_pk_from_jwk(*jwk);
    if (!pk.ok()) return bad(pk.error().message, "cnf.jwk");
    k.alg = msgsig::Alg::kMlDsa65;
    k.public_key = std::move(*pk);
    k.kid = mldsa65::kid(k.public_key);
  } else {
    return bad("jwk.crv must be \"Ed25519\" or \"ML-DSA-65\"", "cnf.jwk.crv");
  }
  return k;
}

Result<json::Value> make(msgsig::Alg alg, std::span<const uint8_t> public_key) {
  json::Value jwk;
  if (alg == msgsig::Alg::kEd25519) {
    if (public_key.size() != ed25519::kPublicKeyBytes)
      return Error(ErrorCode::kSchemaValidationFailed, "an Ed25519 public key is 32 bytes");
    jwk = json::Value(
        json::Object{{"kty", "OKP"},
                     {"crv", "Ed25519"},
                     {"x", base64url_encode(public_key.data(), public_key.size(), false)}});
  } else {
    if (public_key.size() != mldsa65::kPublicKeyBytes)
      return Error(ErrorCode::kSchemaValidationFailed, "an ML-DSA-65 public key is 1952 bytes");
    jwk = keys::mldsa65_jwk(public_key);
  }
  return json::Value(json::Object{{"jwk", std::move(jwk)}});
}

Result<msgsig::SigBlock> verify(const json::Object& msg, const BoundKey& key) {
  msgsig::TrustedKeys one;
  (key.alg == msgsig::Alg::kEd25519 ? one.ed25519 : one.mldsa65).push_back(key.public_key);
  auto r = msgsig::verify(msg, one);
  if (!r.ok() && r.error().field == "sig.kid")
    return Error(ErrorCode::kSignatureInvalid,
                 "the message is not signed by the key its token is bound to (cnf)", "sig.kid");
  return r;
}

}  // namespace rcan::cnf
