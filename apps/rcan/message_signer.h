// MessageSigner — signs the messages a CLI verb sends with the key its token is bound to.
//
// A token with a `cnf` claim (rcan/crypto/cnf.h) is accepted by a robot only on messages signed
// by that key, and a robot requires such tokens on MQTT. The signer reads the claim from the
// token, loads the key pair from a key directory (`rcan keys generate --dir D`: ed25519.seed or
// mldsa65.seed, mode 0600) and checks that its public half is the bound one.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "rcan/crypto/cnf.h"
#include "rcan/crypto/keys.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::cli {

class MessageSigner {
 public:
  // For `token` (a JWT, not verified here) and `key_dir` (empty: none given). A token bound to
  // no key gives a signer that leaves messages as they are. Errors: a bound token without a key
  // directory, a directory that cannot be loaded, or a key pair that is not the bound one.
  static Result<MessageSigner> for_token(const std::string& token, const std::string& key_dir);

  // Signs `msg` (an object; any `sig` is replaced) when the token is bound; otherwise a no-op.
  Status sign(json::Value& msg) const;
  bool bound() const { return bound_.has_value(); }

 private:
  std::optional<cnf::BoundKey> bound_;
  std::shared_ptr<const keys::RobotKeys> keys_;
};

}  // namespace rcan::cli
