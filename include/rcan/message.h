// The one internal message model and its JSON codec (docs/PROTOCOL.md §Messages).
//
// Two input shapes are read and normalised into Message:
//   1. the seed / reference-client shape: version, message_id, source_ruri, target_ruri,
//      auth_token, type|message_type, payload, timestamp_ms, ttl_ms, priority, reply_to,
//      scope, sender_type, cloud_provider, function_name, function_region, ai{…}, sig{…};
//   2. the rcan-py shape: rcan, rcan_version, msg_id, timestamp (float s), cmd, target,
//      params, confidence, scope, sender_type, cloud_provider, sig{alg,kid,value}, …
//      — a COMMAND whose action is `cmd` and whose parameters are `params`.
// encode() always writes the seed shape with type and priority as upper-case names.
// Validation is strict: wrong types, bad lengths, non-UUID ids, unknown message types,
// unknown sender types → SCHEMA_VALIDATION_FAILED naming the field; a seed-shape major
// version other than 1 → VERSION_INCOMPATIBLE; a bad RURI → INVALID_RURI.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan {

enum class MessageType : uint8_t {
  // Seed §3.1 (0-based in the seed's own table).
  kDiscover,
  kStatus,
  kCommand,
  kStream,
  kEvent,
  kHandoff,
  kAck,
  kError,
  // Profile §3 additions.
  kAnnounce,
  kGranted,
  kDenied,
  kReleased,
  kAvailable,
  kHeartbeat,
  kSafety,
  kPendingAuth,
  kAuthorize,
  kConsentRequest,
  kTransferRequest,
  kTransferAccept,
  kFleetCommand,
  // Used by later parts of the node (sessions, consent, transfer, swarms).
  kClaim,
  kRelease,
  kConsentGrant,
  kConsentDeny,
  kTransferCancel,
  kSwarmAnnounce,
  // The SDKs' skill invocation (their MessageType.INVOKE = 11): a COMMAND naming a skill.
  kInvoke,
};
enum class Priority : uint8_t { kLow = 0, kNormal = 1, kHigh = 2, kSafety = 3 };
enum class SenderType : uint8_t { kHuman, kRobot, kCloudFunction, kSystem };
enum class WireShape : uint8_t { kSeed, kRcanPy, kRcanTs };

std::string_view message_type_name(MessageType t);
std::optional<MessageType> message_type_from_name(std::string_view name);
std::string_view priority_name(Priority p);
std::optional<Priority> priority_from_name(std::string_view name);
std::string_view sender_type_name(SenderType s);
std::optional<SenderType> sender_type_from_name(std::string_view name);

// §16.2 model identity. `confidence` is absent when unknown — never defaulted.
struct AiBlock {
  std::string provider;  // MUST, non-empty
  std::string model;     // MUST, non-empty
  std::optional<std::string> model_version;
  std::optional<std::string> layer;
  std::optional<double> confidence;  // [0, 1]
  std::optional<double> inference_latency_ms;
  std::optional<std::string> thought_id;
  bool escalated = false;  // always written

  json::Value to_json() const;
};

struct SignatureBlock {
  std::string alg;  // "ml-dsa-65", "ed25519", …
  std::string kid;
  std::string value;
};

struct Message {
  WireShape shape = WireShape::kSeed;
  std::string version = "1.0.0";  // seed `version`, or the rcan-py `rcan` field as sent
  std::string message_id;
  std::string source_ruri;  // canonical, or empty
  std::string target_ruri;  // canonical, "broadcast", or empty
  std::string auth_token;
  MessageType type = MessageType::kCommand;
  Priority priority = Priority::kNormal;
  json::Object payload;
  int64_t timestamp_ms = 0;
  int64_t ttl_ms = 0;  // 0 = no expiry
  std::string reply_to;
  std::vector<std::string> scope;
  SenderType sender_type = SenderType::kHuman;
  bool sender_type_explicit = false;  // false when defaulted (absent on the wire)
  std::string cloud_provider;
  std::string function_name;
  std::string function_region;
  std::optional<AiBlock> ai;
  std::optional<double> confidence;  // rcan-py top-level confidence, when sent
  std::optional<SignatureBlock> sig;
  json::Value delegation_chain;  // null or a non-empty array
  // The object as received, for signature pre-images that must be rebuilt byte-exactly.
  json::Object wire;

  // The command's action type: first present of payload.action_type, payload.action,
  // payload.command (strings). Empty when none.
  std::string action() const;
  bool is_safety() const { return priority == Priority::kSafety || type == MessageType::kSafety; }
};

struct CodecLimits {
  size_t max_body_bytes = 64 * 1024;
  size_t max_token_bytes = 8 * 1024;
  size_t max_scopes = 32;
  size_t max_delegation_hops = 4;
};

// Parses bytes (JSON) and decodes. Body too large → BODY_TOO_LARGE; malformed JSON →
// MALFORMED_JSON; everything else as described above.
Result<Message> parse_message(std::string_view body, const CodecLimits& limits = {});
Result<Message> decode_message(const json::Value& value, const CodecLimits& limits = {});
// The same, keeping `value` itself as the message's wire object instead of a copy (a fleet
// message with a post-quantum signature is some KiB). `value` is moved from when the message
// decodes, and unchanged when it does not.
Result<Message> decode_message(json::Value&& value, const CodecLimits& limits = {});

// The pre-authentication shape check of the live conformance checker's order: a JSON object
// whose `payload` (seed shape) or `cmd` (rcan-py shape) is present. Nothing else is
// required before authentication is looked at.
Status check_shape(const json::Value& value);

struct EncodeOptions {
  bool include_auth_token = true;  // false for logs
};
// Seed shape, type/priority as names.
json::Value encode_message(const Message& m, const EncodeOptions& opts = {});

}  // namespace rcan
