// The transports beside HTTP/WebSocket, started from the config: gRPC (`grpc` block) and UDP
// heartbeats/discovery (`udp` block). docs/TRANSPORT.md.
#pragma once

#include <memory>

#include "node/config.h"
#include "node/node.h"
#include "transport/grpc_module.h"
#include "transport/udp.h"

namespace rcan::rcand {

struct ExtraTransports {
  std::unique_ptr<transport::GrpcTransport> grpc;  // librcand_grpc.so (grpc_loader.h)
  std::unique_ptr<transport::UdpService> udp;
  // gRPC first (drains its calls through the pipeline), then UDP.
  void stop(int drain_ms);
};

// Starts what the config enables. Errors name the block (e.g. "grpc: cannot listen on …").
Result<std::unique_ptr<ExtraTransports>> start_extra_transports(const config::NodeConfig& cfg, node::Node& node);

}  // namespace rcan::rcand
