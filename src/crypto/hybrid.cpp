// Hybrid signed bodies (see include/rcan/crypto/hybrid.h).
#include "rcan/crypto/hybrid.h"

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"

namespace rcan::hybrid {
namespace {

Error invalid(std::string msg, std::string field = "sig") {
  return Error(ErrorCode::kSignatureInvalid, "hybrid signature: " + std::move(msg),
               std::move(field));
}

std::span<const uint8_t> as_bytes(std::string_view s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

}  // namespace

std::string preimage(const json::Object& signed_body) {
  return json::canonical_without(signed_body, "sig");
}

Result<json::Object> sign_body(const json::Object& body, std::span<const uint8_t> mldsa_sk,
                               std::span<const uint8_t> mldsa_pk,
                               std::span<const uint8_t> ed25519_seed, const SignOptions& opts) {
  if (mldsa_sk.size() != mldsa65::kSecretKeyBytes || mldsa_pk.size() != mldsa65::kPublicKeyBytes)
    return Error(ErrorCode::kInternal, "hybrid sign: ML-DSA-65 key has the wrong size");
  if (ed25519_seed.size() != ed25519::kSeedBytes)
    return Error(ErrorCode::kInternal, "hybrid sign: Ed25519 seed must be 32 bytes");
  auto ed_pub = ed25519::public_key_from_seed(ed25519_seed);
  if (!ed_pub.ok()) return ed_pub.error();
  json::Object out = body;
  out.erase("sig");
  out.set("pq_signing_pub", base64_encode(mldsa_pk.data(), mldsa_pk.size()));
  out.set("pq_kid", mldsa65::kid(mldsa_pk));
  std::string pre = json::canonical(json::Value(out));
  mldsa65::SignOptions so;
  so.deterministic = opts.deterministic;
  auto pq_sig = mldsa65::sign(mldsa_sk, as_bytes(pre), so);
  if (!pq_sig.ok()) return pq_sig.error();
  auto ed_sig = ed25519::sign(ed25519_seed, as_bytes(pre));
  if (!ed_sig.ok()) return ed_sig.error();
  json::Object sig;
  sig.set("ml_dsa", base64_encode(*pq_sig));
  sig.set("ed25519", base64_encode(*ed_sig));
  sig.set("ed25519_pub", base64_encode(*ed_pub));
  out.set("sig", json::Value(std::move(sig)));
  return out;
}

Status verify_body(const json::Object& body, std::span<const uint8_t> trusted_pk,
                   const VerifyOptions& opts) {
  if (trusted_pk.size() != mldsa65::kPublicKeyBytes)
    return invalid("trusted ML-DSA-65 key must be 1952 bytes");
  const json::Value* sig = body.find("sig");
  if (!sig) return invalid("the body has no sig");
  if (!sig->is_object()) return invalid("sig is not an object");
  auto field = [&](const char* name) -> std::optional<Bytes> {
    const json::Value* v = sig->get(name);
    if (!v || !v->is_string()) return std::nullopt;
    return base64_decode(v->as_string());
  };
  auto ml = field("ml_dsa");
  if (!ml) return invalid("sig.ml_dsa is missing or not base64", "sig.ml_dsa");
  auto ed = field("ed25519");
  if (!ed) return invalid("sig.ed25519 is missing or not base64", "sig.ed25519");
  auto edpub = field("ed25519_pub");
  if (!edpub) return invalid("sig.ed25519_pub is missing or not base64", "sig.ed25519_pub");
  if (ml->size() != mldsa65::kSignatureBytes)
    return invalid("sig.ml_dsa is not 3309 bytes", "sig.ml_dsa");
  if (ed->size() != ed25519::kSignatureBytes)
    return invalid("sig.ed25519 is not 64 bytes", "sig.ed25519");
  if (edpub->size() != ed25519::kPublicKeyBytes)
    return invalid("sig.ed25519_pub is not 32 bytes", "sig.ed25519_pub");
  if (opts.expected_ed25519_pub && *opts.expected_ed25519_pub != *edpub)
    return invalid("sig.ed25519_pub is not the expected Ed25519 key", "sig.ed25519_pub");

  if (opts.strict) {
    const json::Value* pub = body.find("pq_signing_pub");
    if (!pub || !pub->is_string()) return invalid("pq_signing_pub is missing", "pq_signing_pub");
    auto pub_bytes = base64_decode(pub->as_string());
    if (!pub_bytes || pub_bytes->size() != trusted_pk.size() ||
        !std::equal(pub_bytes->begin(), pub_bytes->end(), trusted_pk.begin()))
      return invalid("pq_signing_pub is not the trusted ML-DSA-65 key", "pq_signing_pub");
    const json::Value* kid = body.find("pq_kid");
    if (!kid || !kid->is_string() || kid->as_string() != mldsa65::kid(trusted_pk))
      return invalid("pq_kid does not name the trusted ML-DSA-65 key", "pq_kid");
  }

  std::string pre = preimage(body);
  if (!mldsa65::verify(trusted_pk, as_bytes(pre), *ml))
    return invalid("ML-DSA-65 signature does not verify", "sig.ml_dsa");
  if (!ed25519::verify(*edpub, as_bytes(pre), *ed))
    return invalid("Ed25519 signature does not verify", "sig.ed25519");
  return Status::Ok();
}

}  // namespace rcan::hybrid
