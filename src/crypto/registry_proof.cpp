#include "rcan/crypto/registry_proof.h"

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/encoding.h"

namespace rcan::registry {
namespace {

std::span<const uint8_t> bytes_of(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

}  // namespace

json::Value Proof::to_json() const {
  json::Object o;
  o.set("challenge_id", challenge_id);
  o.set("ed25519_sig", ed25519_sig);
  o.set("mldsa65_sig", mldsa65_sig);
  return json::Value(std::move(o));
}

Result<Proof> sign_proof(const keys::RobotKeys& keys, const std::string& challenge_id,
                         const std::string& message) {
  auto ed = ed25519::sign(keys.ed25519_seed.span(), bytes_of(message));
  if (!ed.ok()) return ed.error();
  auto ml = mldsa65::sign(keys.mldsa65_sk.span(), bytes_of(message));
  if (!ml.ok()) return ml.error();
  Proof p;
  p.challenge_id = challenge_id;
  p.ed25519_sig = base64url_encode(*ed);
  p.mldsa65_sig = base64url_encode(*ml);
  return p;
}

Status check_proof_shape(const std::string& ed25519_pub_b64url,
                         const std::string& mldsa65_pub_b64url, const Proof& proof) {
  auto shape = [](const char* field, std::string msg, const char* reason) {
    return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), field, reason);
  };
  if (ed25519_pub_b64url.empty() && mldsa65_pub_b64url.empty())
    return shape("proof", "a proof needs ed25519_public_key and/or mldsa65_public_key", "no_keys");
  if (!ed25519_pub_b64url.empty()) {
    auto pk = base64url_decode(ed25519_pub_b64url);
    if (!pk || pk->size() != ed25519::kPublicKeyBytes)
      return shape("ed25519_public_key", "ed25519_public_key is not 32 bytes of base64url",
                   "bad_key");
    if (proof.ed25519_sig.empty())
      return shape("proof.ed25519_sig", "the proof needs a signature by every key sent",
                   "missing_signature");
  }
  if (!mldsa65_pub_b64url.empty()) {
    auto pk = base64url_decode(mldsa65_pub_b64url);
    if (!pk || pk->size() != mldsa65::kPublicKeyBytes)
      return shape("mldsa65_public_key", "mldsa65_public_key is not 1952 bytes of base64url",
                   "bad_key");
    if (proof.mldsa65_sig.empty())
      return shape("proof.mldsa65_sig", "the proof needs a signature by every key sent",
                   "missing_signature");
  }
  return Status::Ok();
}

Status verify_proof(const std::string& ed25519_pub_b64url, const std::string& mldsa65_pub_b64url,
                    const std::string& message, const Proof& proof) {
  if (Status s = check_proof_shape(ed25519_pub_b64url, mldsa65_pub_b64url, proof); !s.ok())
    return s;
  auto refused = [](const char* field, const char* msg) {
    return Error(ErrorCode::kSignatureInvalid, msg, field, "bad_signature");
  };
  if (!ed25519_pub_b64url.empty()) {
    auto pk = base64url_decode(ed25519_pub_b64url);
    auto sig = base64url_decode(proof.ed25519_sig);
    if (!sig || !ed25519::verify(*pk, bytes_of(message), *sig))
      return refused("proof.ed25519_sig", "the Ed25519 proof of possession does not verify");
  }
  if (!mldsa65_pub_b64url.empty()) {
    auto pk = base64url_decode(mldsa65_pub_b64url);
    auto sig = base64url_decode(proof.mldsa65_sig);
    if (!sig || !mldsa65::verify(*pk, bytes_of(message), *sig))
      return refused("proof.mldsa65_sig", "the ML-DSA-65 proof of possession does not verify");
  }
  return Status::Ok();
}

Result<std::string> sign_update(const keys::RobotKeys& keys, const std::string& message) {
  auto sig = ed25519::sign(keys.ed25519_seed.span(), bytes_of(message));
  if (!sig.ok()) return sig.error();
  return "ed25519=" + base64url_encode(*sig);
}

Status verify_update(const std::string& ed25519_pub_b64url, const std::string& message,
                     std::string_view header) {
  constexpr std::string_view kPrefix = "ed25519=";
  if (header.substr(0, kPrefix.size()) != kPrefix)
    return Error(ErrorCode::kSignatureInvalid, "X-RCAN-Signature must be ed25519=<base64url>",
                 "X-RCAN-Signature", "signature_malformed");
  auto pk = base64url_decode(ed25519_pub_b64url);
  auto sig = base64url_decode(header.substr(kPrefix.size()));
  if (!pk || pk->size() != ed25519::kPublicKeyBytes || !sig ||
      !ed25519::verify(*pk, bytes_of(message), *sig))
    return Error(ErrorCode::kSignatureInvalid,
                 "the update is not signed by the robot's registered Ed25519 key",
                 "X-RCAN-Signature", "bad_signature");
  return Status::Ok();
}

}  // namespace rcan::registry
