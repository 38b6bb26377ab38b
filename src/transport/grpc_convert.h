// RCANMessage (proto/rcan.proto) ⇄ the node's JSON message, and the profile's error codes
// mapped onto gRPC status codes (docs/TRANSPORT.md §gRPC). Pure functions: no sockets, no
// server; shared by the gRPC server, its tests and fuzz/grpc_convert_fuzz.cpp.
#pragma once

#include <string>
#include <string_view>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::v1 {
class RCANMessage;
}

namespace rcan::transport {

// A message received over gRPC → the seed-shape JSON message the pipeline reads
// (docs/PROTOCOL.md). Empty strings, zero numbers, an empty scope list and empty ai/sig are
// absent; an empty payload is `{}`; priority LOW (0, the proto default) is absent, so the
// codec's default applies. Errors: MALFORMED_JSON (payload, ai or sig not JSON; `field`
// names which), SCHEMA_VALIDATION_FAILED (payload/ai/sig not an object, a type or priority
// number outside the enums).
Result<json::Value> grpc_to_json(const v1::RCANMessage& m, size_t max_json_bytes = 64 * 1024);

// An answer or event of the node (any JSON object with a `type`) → RCANMessage. Envelope
// fields map one to one; `payload` is the body's `payload`, or — for bodies without one,
// such as events — the body without its envelope fields. A `type` outside the enum becomes
// EVENT (the original name stays in the payload as `type`).
void json_to_grpc(const json::Value& body, v1::RCANMessage& out);

// The gRPC status code (grpc::StatusCode as int) for an error answer: by the body's
// `payload.error_code` when known, else by the HTTP status.
int grpc_status_code(std::string_view error_code, int http_status);

// "SAFETY" ⇄ SAFETY_MESSAGE and the other type names; -1 for an unknown name.
int grpc_type_from_name(std::string_view name);
std::string grpc_type_name(int type);

}  // namespace rcan::transport
