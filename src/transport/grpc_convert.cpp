// RCANMessage ⇄ JSON and the error-code → gRPC status table (grpc_convert.h).
#include "transport/grpc_convert.h"

#include <grpcpp/support/status_code_enum.h>

#include <array>

#include "rcan.pb.h"
#include "rcan/error_code.h"
#include "rcan/errors.h"

namespace rcan::transport {

namespace {

using PMsg = v1::RCANMessage;

// Proto enum number → wire name. Index = enum value.
constexpr std::array<std::string_view, 21> kTypeNames{
    "DISCOVER",     "STATUS",    "COMMAND",         "STREAM",           "EVENT",
    "HANDOFF",      "ACK",       "ERROR",           "ANNOUNCE",         "GRANTED",
    "DENIED",       "RELEASED",  "AVAILABLE",       "HEARTBEAT",        "SAFETY",
    "PENDING_AUTH", "AUTHORIZE", "CONSENT_REQUEST", "TRANSFER_REQUEST", "TRANSFER_ACCEPT",
    "FLEET_COMMAND"};
constexpr std::array<std::string_view, 4> kPriorityNames{"LOW", "NORMAL", "HIGH", "SAFETY"};

Result<json::Value> json_object_field(const std::string& bytes, const char* field,
                                      size_t max_bytes) {
  json::ParseOptions po;
  po.max_bytes = max_bytes;
  po.max_depth = 32;
  auto v = json::parse(bytes, po);
  if (!v.ok()) {
    Error e = v.error();
    e.field = field;
    e.message = std::string(field) + " is not JSON: " + e.message;
    return e;
  }
  if (!v->is_object())
    return Error(ErrorCode::kSchemaValidationFailed, std::string(field) + " must be a JSON object",
                 field);
  return v;
}

}  // namespace

int grpc_type_from_name(std::string_view name) {
  for (size_t i = 0; i < kTypeNames.size(); ++i)
    if (kTypeNames[i] == name) return static_cast<int>(i);
  return -1;
}

std::string grpc_type_name(int type) {
  if (type < 0 || static_cast<size_t>(type) >= kTypeNames.size()) return {};
  return std::string(kTypeNames[static_cast<size_t>(type)]);
}

Result<json::Value> grpc_to_json(const v1::RCANMessage& m, size_t max_json_bytes) {
  json::Object o;
  auto str = [&](const char* key, const std::string& v) {
    if (!v.empty()) o.set(key, v);
  };
  str("version", m.version());
  str("message_id", m.message_id());
  str("source_ruri", m.source_ruri());
  str("target_ruri", m.target_ruri());
  str("auth_token", m.auth_token());
  std::string type = grpc_type_name(static_cast<int>(m.type()));
  if (type.empty())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "type " + std::to_string(static_cast<int>(m.type())) + " is not a message type",
                 "type");
  o.set("type", type);
  if (m.payload().empty()) {
    o.set("payload", json::Object{});
  } else {
    auto p = json_object_field(m.payload(), "payload", max_json_bytes);
    if (!p.ok()) return p.error();
    o.set("payload", std::move(p).value());
  }
  if (m.timestamp_ms() != 0) o.set("timestamp_ms", static_cast<int64_t>(m.timestamp_ms()));
  if (m.ttl_ms() != 0) o.set("ttl_ms", static_cast<int64_t>(m.ttl_ms()));
  int prio = static_cast<int>(m.priority());
  if (prio < 0 || static_cast<size_t>(prio) >= kPriorityNames.size())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "priority " + std::to_string(prio) + " is not a priority", "priority");
  if (prio != 0) o.set("priority", std::string(kPriorityNames[static_cast<size_t>(prio)]));
  str("reply_to", m.reply_to());
  if (m.scope_size() > 0) {
    json::Array sc;
    for (const auto& s : m.scope()) sc.emplace_back(s);
    o.set("scope", std::move(sc));
  }
  str("sender_type", m.sender_type());
  str("cloud_provider", m.cloud_provider());
  str("function_name", m.function_name());
  str("function_region", m.function_region());
  if (!m.ai().empty()) {
    auto a = json_object_field(m.ai(), "ai", max_json_bytes);
    if (!a.ok()) return a.error();
    o.set("ai", std::move(a).value());
  }
  if (!m.sig().empty()) {
    auto s = json_object_field(m.sig(), "sig", max_json_bytes);
    if (!s.ok()) return s.error();
    o.set("sig", std::move(s).value());
  }
  return json::Value(std::move(o));
}

void json_to_grpc(const json::Value& body, v1::RCANMessage& out) {
  out.Clear();
  if (!body.is_object()) {
    out.set_type(PMsg::EVENT);
    out.set_payload(json::dump(json::Value(json::Object{{"value", body}})));
    return;
  }
  auto s = [&](const char* key) -> std::string {
    const json::Value* v = body.get(key);
    return v && v->is_string() ? v->as_string() : std::string();
  };
  std::string type = s("type");
  int t = grpc_type_from_name(type);
  out.set_type(t >= 0 ? static_cast<PMsg::MessageType>(t) : PMsg::EVENT);
  out.set_version(s("version"));
  out.set_message_id(s("message_id"));
  out.set_source_ruri(s("source_ruri"));
  out.set_target_ruri(s("target_ruri"));
  out.set_reply_to(s("reply_to"));
  if (const json::Value* ts = body.get("timestamp_ms"); ts && ts->is_int())
    out.set_timestamp_ms(ts->as_int());
  if (const json::Value* ttl = body.get("ttl_ms");
      ttl && ttl->is_int() && ttl->as_int() >= 0 && ttl->as_int() <= INT32_MAX)
    out.set_ttl_ms(static_cast<int32_t>(ttl->as_int()));
  std::string prio = s("priority");
  for (size_t i = 0; i < kPriorityNames.size(); ++i)
    if (kPriorityNames[i] == prio) out.set_priority(static_cast<PMsg::Priority>(i));
  const json::Value* payload = body.get("payload");
  if (payload && payload->is_object()) {
    out.set_payload(json::dump(*payload));
  } else {
    json::Object rest;
    for (const auto& [k, v] : body.as_object()) {
      if (k == "version" || k == "message_id" || k == "source_ruri" || k == "target_ruri" ||
          k == "reply_to" || k == "timestamp_ms" || k == "ttl_ms" || k == "priority")
        continue;
      if (k == "type" && t >= 0) continue;
      rest.set(k, v);
    }
    out.set_payload(json::dump(json::Value(std::move(rest))));
  }
}

int grpc_status_code(std::string_view error_code, int http_status) {
  using grpc::StatusCode;
  if (auto c = error_from_name(error_code)) {
    switch (*c) {
      case ErrorCode::kMalformedJson:
      case ErrorCode::kSchemaValidationFailed:
      case ErrorCode::kInvalidRuri:
      case ErrorCode::kVersionIncompatible:
      case ErrorCode::kMissingDelegationChain:
        return StatusCode::INVALID_ARGUMENT;
      case ErrorCode::kAuthRequired:
      case ErrorCode::kAuthInvalid:
      case ErrorCode::kSessionExpired:
      case ErrorCode::kSignatureInvalid:
        return StatusCode::UNAUTHENTICATED;
      case ErrorCode::kInsufficientPrivileges:
      case ErrorCode::kConfidenceGateFail:
      case ErrorCode::kHitlDenied:
        return StatusCode::PERMISSION_DENIED;
      case ErrorCode::kNotFound:
        return StatusCode::NOT_FOUND;
      case ErrorCode::kMethodNotAllowed:
      case ErrorCode::kNotImplemented:
        return StatusCode::UNIMPLEMENTED;
      case ErrorCode::kMessageStale:
      case ErrorCode::kHitlTimeout:
        return StatusCode::DEADLINE_EXCEEDED;
      case ErrorCode::kReplayDetected:
        return StatusCode::ALREADY_EXISTS;
      case ErrorCode::kControlConflict:
        return StatusCode::ABORTED;
      case ErrorCode::kBodyTooLarge:
      case ErrorCode::kRateLimited:
        return StatusCode::RESOURCE_EXHAUSTED;
      case ErrorCode::kCommandRejected:
        return StatusCode::FAILED_PRECONDITION;
      case ErrorCode::kInternal:
        return StatusCode::INTERNAL;
      case ErrorCode::kSafeStop:
      case ErrorCode::kLockdown:
      case ErrorCode::kAuditUnavailable:
        return StatusCode::UNAVAILABLE;
    }
  }
  switch (http_status) {
    case 400:
      return StatusCode::INVALID_ARGUMENT;
    case 401:
      return StatusCode::UNAUTHENTICATED;
    case 403:
      return StatusCode::PERMISSION_DENIED;
    case 404:
      return StatusCode::NOT_FOUND;
    case 408:
      return StatusCode::DEADLINE_EXCEEDED;
    case 409:
      return StatusCode::ABORTED;
    case 413:
    case 429:
      return StatusCode::RESOURCE_EXHAUSTED;
    case 422:
    case 423:
      return StatusCode::FAILED_PRECONDITION;
    case 503:
      return StatusCode::UNAVAILABLE;
    default:
      return http_status >= 500 ? StatusCode::INTERNAL : StatusCode::UNKNOWN;
  }
}

}  // namespace rcan::transport
