#include "rcan/sender_identity.h"

namespace rcan {

Status check_token_sender_claims(const TokenIdentity& token) {
  if (!token.sender_type) return Status::Ok();
  auto st = sender_type_from_name(*token.sender_type);
  if (!st) {
    return Error(ErrorCode::kAuthInvalid,
                 "token claims an unknown sender_type '" + token.sender_type->substr(0, 32) + "'",
                 "sender_type");
  }
  if (*st == SenderType::kCloudFunction &&
      (!token.cloud_provider || token.cloud_provider->empty())) {
    return Error(ErrorCode::kAuthInvalid,
                 "token claims sender_type cloud_function without cloud_provider",
                 "cloud_provider");
  }
  return Status::Ok();
}

Result<SenderIdentity> resolve_sender(const Message& msg, const TokenIdentity& token,
                                      bool robot_signed, bool remote) {
  if (Status s = check_token_sender_claims(token); !s.ok()) return s.error();
  SenderIdentity id;
  id.sub = token.sub;
  id.sender_type = msg.sender_type;
  if (token.sender_type) {
    SenderType tok = *sender_type_from_name(*token.sender_type);
    if (msg.sender_type_explicit && msg.sender_type != tok) {
      return Error(ErrorCode::kInsufficientPrivileges,
                   "message says sender_type " + std::string(sender_type_name(msg.sender_type)) +
                       " but its token says " + std::string(sender_type_name(tok)),
                   "sender_type");
    }
    id.sender_type = tok;
  }
  if (robot_signed && id.sender_type != SenderType::kRobot) {
    return Error(ErrorCode::kSchemaValidationFailed,
                 "a message signed with a robot key must say sender_type robot", "sender_type");
  }
  if (id.sender_type == SenderType::kRobot) {
    if (!robot_signed) {
      return Error(ErrorCode::kAuthInvalid,
                   "sender_type robot requires a signature by a known robot key", "sig");
    }
    if (msg.delegation_chain.is_null()) {
      return Error(ErrorCode::kMissingDelegationChain,
                   "sender_type robot requires a delegation_chain", "delegation_chain");
    }
  }
  if (id.sender_type == SenderType::kSystem && remote) {
    return Error(ErrorCode::kInsufficientPrivileges,
                 "sender_type system is reserved for the node's own messages", "sender_type");
  }
  if (id.sender_type == SenderType::kCloudFunction) {
    id.cloud_provider =
        !msg.cloud_provider.empty() ? msg.cloud_provider : token.cloud_provider.value_or("");
    id.function_name =
        !msg.function_name.empty() ? msg.function_name : token.function_name.value_or("");
    id.function_region = msg.function_region;
    if (id.cloud_provider.empty()) {
      return Error(ErrorCode::kSchemaValidationFailed,
                   "sender_type cloud_function requires cloud_provider", "cloud_provider");
    }
    if (id.function_name.empty()) {
      return Error(ErrorCode::kSchemaValidationFailed,
                   "sender_type cloud_function requires function_name", "function_name");
    }
    if (token.cloud_provider && !msg.cloud_provider.empty() &&
        *token.cloud_provider != msg.cloud_provider) {
      return Error(ErrorCode::kInsufficientPrivileges,
                   "message cloud_provider disagrees with its token", "cloud_provider");
    }
  }
  return id;
}

}  // namespace rcan
