#include "rcan/crypto/registry_proof.h"

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/encoding.h"

namespace rcan::registry {
namespace {

std::span<const uint8_t> bytes_of(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

Error bad(const std::string& field, const std::string& msg) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field, "proof_invalid");
}

}  // namespace

json::Value Proof::to_json() const {
  json::Object o;
  o.set("challenge_id", challenge_id);
  o.set("ed25519_sig", ed25519_sig);
  o.set("mldsa65_sig", mldsa65_sig);
  return json::Value(std::move(o));
}

Result<Proof> Proof::from_json(const json::Value& v) {
  if (!v.is_object()) return bad("proof", "proof must be an object");
  Proof p;
  for (auto [name, out] :
       {std::pair{"challenge_id", &p.challenge_id}, std::pair{"ed25519_sig", &p.ed25519_sig},
        std::pair{"mldsa65_sig", &p.mldsa65_sig}}) {
    const json::Value* m = v.get(name);
    if (m == nullptr || !m->is_string())
      return bad(std::string("proof.") + name, std::string("proof.") + name + " must be a string");
    *out = m->as_string();
  }
  return p;
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

Status verify_proof(const std::string& ed25519_pub_b64url, const std::string& mldsa65_pub_b64url,
                    const std::string& message, const Proof& proof) {
  auto ed_pk = base64url_decode(ed25519_pub_b64url);
  if (!ed_pk || ed_pk->size() != 32)
    return bad("ed25519_public_key", "ed25519_public_key must be 32 bytes of base64url");
  auto ml_pk = base64url_decode(mldsa65_pub_b64url);
  if (!ml_pk || ml_pk->size() != 1952)
    return bad("mldsa65_public_key", "mldsa65_public_key must be 1952 bytes of base64url");
  auto ed_sig = base64url_decode(proof.ed25519_sig);
  if (!ed_sig || !ed25519::verify(*ed_pk, bytes_of(message), *ed_sig))
    return Error(ErrorCode::kSignatureInvalid, "the Ed25519 proof signature does not verify",
                 "proof.ed25519_sig", "proof_invalid");
  auto ml_sig = base64url_decode(proof.mldsa65_sig);
  if (!ml_sig || !mldsa65::verify(*ml_pk, bytes_of(message), *ml_sig))
    return Error(ErrorCode::kSignatureInvalid, "the ML-DSA-65 proof signature does not verify",
                 "proof.mldsa65_sig", "proof_invalid");
  return Status::Ok();
}

}  // namespace rcan::registry
