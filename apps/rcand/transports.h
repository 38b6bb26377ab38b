// The transports beside HTTP/WebSocket, started from the config: UDP heartbeats and discovery
// (`udp` block) and gRPC (`grpc` block). docs/TRANSPORT.md.
#pragma once

#include <memory>

#include "config/config.h"
#include "node/api/node.h"
#include "node/bindings/grpc_module.h"
#include "node/bindings/udp_service.h"

namespace rcan::rcand {

// The UDP service when `udp.enabled` (null otherwise), started. Start it before HTTP serves:
// it installs the claim hook that puts the heartbeat key into GRANTED answers.
// Errors: "udp: …".
Result<std::unique_ptr<node::UdpService>> start_udp(const config::NodeConfig& cfg,
                                                    node::Node& node);

// The gRPC transport (the module librcand_grpc.so, grpc_loader.h) when `grpc.enabled` (null
// otherwise), started. Errors: "grpc: …" (cannot load the module, cannot listen).
Result<std::unique_ptr<node::GrpcTransport>> start_grpc(const config::NodeConfig& cfg,
                                                        node::Node& node);

}  // namespace rcan::rcand
