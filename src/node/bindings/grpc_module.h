// The gRPC transport as a loadable module (docs/TRANSPORT.md §gRPC module). rcand does not link
// gRPC: the server (grpc_server.cpp, grpc_convert.cpp, the generated code) is built into
// librcand_grpc.so, which rcand dlopen()s only when `grpc.enabled` is true and reaches through
// the one C entry point below. The module uses the node's own code (Node::submit, json, logs)
// from the rcand executable, which exports its symbols for it. No gRPC header here.
#pragma once

#include <cstdint>

#include "node/bindings/grpc_server.h"
#include "rcan/result.h"

namespace rcan::node {

// Bumped whenever GrpcTransport, GrpcOptions or GrpcStats change shape; rcand refuses a module
// built against another version.
inline constexpr int kGrpcModuleAbi = 1;

// What rcand holds: a started (or startable) gRPC server.
class GrpcTransport {
 public:
  virtual ~GrpcTransport() = default;
  virtual Result<uint16_t> start() = 0;  // binds and serves; the bound port
  virtual void stop(int drain_ms) = 0;   // GrpcServer::stop
  virtual GrpcStats stats() const = 0;
};

}  // namespace rcan::node

// The module's entry point (extern "C", found with dlsym): a new, not yet started transport, or
// nullptr when `abi` is not the module's kGrpcModuleAbi. The caller owns the result.
#define RCAN_GRPC_MODULE_ENTRY "rcan_grpc_module_create"
extern "C" {
using RcanGrpcModuleCreate = rcan::node::GrpcTransport* (*)(int abi,
                                                            const rcan::node::GrpcOptions* opt,
                                                            rcan::node::Node* node);
}
