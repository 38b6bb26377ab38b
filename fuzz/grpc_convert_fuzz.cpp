// libFuzzer: an RCANMessage received over gRPC → the node's JSON message, and answers back
// (src/transport/grpc_convert.h). The input is the protobuf wire bytes of a message, exactly
// what the gRPC server deserialises. Invariants: conversion either fails with a coded error
// or yields an object with a type and an object payload; converting that JSON back to an
// RCANMessage keeps the type, id and payload.
#include <cstdint>
#include <cstdlib>

#include "rcan.pb.h"
#include "rcan/error_code.h"
#include "transport/grpc_convert.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  rcan::v1::RCANMessage m;
  if (!m.ParseFromArray(data, static_cast<int>(size))) return 0;
  auto v = rcan::transport::grpc_to_json(m, 64 * 1024);
  if (!v.ok()) {
    auto c = v.error().code;
    if (c != rcan::ErrorCode::kMalformedJson && c != rcan::ErrorCode::kSchemaValidationFailed)
      std::abort();
    return 0;
  }
  const rcan::json::Value* type = v->get("type");
  const rcan::json::Value* payload = v->get("payload");
  if (!type || !type->is_string() || !payload || !payload->is_object()) std::abort();
  rcan::v1::RCANMessage back;
  rcan::transport::json_to_grpc(*v, back);
  if (back.type() != m.type() || back.message_id() != m.message_id()) std::abort();
  auto again = rcan::transport::grpc_to_json(back, 64 * 1024);
  if (!again.ok() || !(*again->get("payload") == *payload)) std::abort();
  (void)rcan::transport::grpc_status_code("X", static_cast<int>(size % 600));
  return 0;
}
