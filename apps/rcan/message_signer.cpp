#include "message_signer.h"

#include "rcan/crypto/jwt.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/errors.h"

namespace rcan::cli {

Result<MessageSigner> MessageSigner::for_token(const std::string& token,
                                               const std::string& key_dir) {
  MessageSigner s;
  auto decoded = jwt::decode(token);
  if (!decoded.ok()) return decoded.error();
  const json::Value* c = decoded->claims.find("cnf");
  if (c == nullptr) return s;
  auto bound = cnf::parse(*c);
  if (!bound.ok()) return bound.error();
  if (key_dir.empty())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "the token is bound to a key (cnf, kid " + bound->kid +
                     "): give its key directory with --key-dir D (or RCAN_KEY_DIR)");
  auto k = keys::load_dir(key_dir);
  if (!k.ok()) return Error(k.error().code, "--key-dir " + key_dir + ": " + k.error().message);
  const Bytes& have = bound->alg == msgsig::Alg::kEd25519 ? k->pub.ed25519_pk : k->pub.mldsa65_pk;
  if (have != bound->public_key)
    return Error(ErrorCode::kSchemaValidationFailed,
                 "--key-dir " + key_dir + " does not hold the key the token is bound to (kid " +
                     bound->kid + ")");
  s.bound_ = std::move(bound).value();
  s.keys_ = std::make_shared<const keys::RobotKeys>(std::move(k).value());
  return s;
}

Status MessageSigner::sign(json::Value& msg) const {
  if (!bound_) return Status::Ok();
  if (!msg.is_object())
    return Error(ErrorCode::kSchemaValidationFailed, "only a JSON object can be signed");
  if (bound_->alg == msgsig::Alg::kEd25519)
    return msgsig::sign_ed25519(msg.as_object(), keys_->ed25519_seed.span());
  return msgsig::sign_mldsa65(msg.as_object(), keys_->mldsa65_sk.span(), keys_->pub.mldsa65_pk);
}

}  // namespace rcan::cli
