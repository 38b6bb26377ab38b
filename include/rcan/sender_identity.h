// §8.5 Cloud Relay Identity as pure functions: message + verified token claims → the sender
// identity recorded in the audit trail, or a rejection with its code.
//
// Rules (docs/PROTOCOL.md §Sender identity):
//  * sender_type ∈ human (default when absent), robot, cloud_function, system;
//  * an envelope claiming cloud_function without cloud_provider or function_name is refused
//    (the codec already refuses it: SCHEMA_VALIDATION_FAILED);
//  * a token claiming sender_type cloud_function without cloud_provider → AUTH_INVALID;
//  * when the token states a sender_type, an envelope that states a different one →
//    INSUFFICIENT_PRIVILEGES (a token's identity caps what the body says about itself);
//    an envelope that is silent takes the token's;
//  * a message signed with a robot key must say robot; robot requires a robot signature and
//    a delegation chain (MISSING_DELEGATION_CHAIN);
//  * system is reserved for the node's own messages: no remote message may claim it.
#pragma once

#include <optional>
#include <string>

#include "rcan/message.h"
#include "rcan/result.h"

namespace rcan {

// What the verified token says about the sender.
struct TokenIdentity {
  std::string sub;
  std::optional<std::string> sender_type;
  std::optional<std::string> cloud_provider;
  std::optional<std::string> function_name;
};

// What the audit record carries.
struct SenderIdentity {
  SenderType sender_type = SenderType::kHuman;
  std::string sub;
  std::string cloud_provider;  // cloud_function only
  std::string function_name;   // cloud_function only
  std::string function_region;
};

// Checks a token's own sender claims (applied at authentication).
Status check_token_sender_claims(const TokenIdentity& token);

// `robot_signed`: the message carries a signature that verified against a configured robot
// key. `remote`: the message arrived from outside the node (everything but internal sources).
Result<SenderIdentity> resolve_sender(const Message& msg, const TokenIdentity& token,
                                      bool robot_signed, bool remote = true);

}  // namespace rcan
