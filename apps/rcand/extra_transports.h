// The transports beside HTTP/WebSocket, started from the config: gRPC (`grpc` block) and UDP
// heartbeats/discovery (`udp` block). docs/TRANSPORT.md.
#pragma once

#include <memory>

#include "config/config.h"
#include "node/api/node.h"
#include "node/bindings/grpc_module.h"
#include "node/bindings/udp_service.h"

namespace rcan::rcand {

struct ExtraTransports {
  std::unique_ptr<node::GrpcTransport> grpc;  // librcand_grpc.so (grpc_loader.h)
  std::unique_ptr<node::UdpService> udp;
  // gRPC first (drains its calls through the pipeline), then UDP.
  void stop(int drain_ms);
};

// Starts what the config enables. Errors name the block (e.g. "grpc: cannot listen on …").
Result<std::unique_ptr<ExtraTransports>> start_extra_transports(const config::NodeConfig& cfg,
                                                                node::Node& node);

}  // namespace rcan::rcand
