// UDP and gRPC started from the config (transports.h).
#include "transports.h"

#include "grpc_loader.h"

namespace rcan::rcand {

Result<std::unique_ptr<node::UdpService>> start_udp(const config::NodeConfig& cfg,
                                                    node::Node& node) {
  if (!cfg.udp.enabled) return std::unique_ptr<node::UdpService>();
  node::UdpOptions uo;
  uo.bind_address = cfg.udp.bind_address;
  uo.port = cfg.udp.port;
  uo.heartbeat = cfg.udp.heartbeat;
  uo.discovery = cfg.udp.discovery;
  uo.discovery_per_source_per_min = cfg.udp.discovery_per_source_per_min;
  auto udp = std::make_unique<node::UdpService>(uo, node.services());
  if (auto p = udp->start(); !p.ok())
    return Error(ErrorCode::kInternal, "udp: " + p.error().message);
  return udp;
}

Result<std::unique_ptr<node::GrpcTransport>> start_grpc(const config::NodeConfig& cfg,
                                                        node::Node& node) {
  if (!cfg.grpc.enabled) return std::unique_ptr<node::GrpcTransport>();
  node::GrpcOptions go;
  go.bind_address = cfg.grpc.bind_address;
  go.port = cfg.grpc.port;
  go.tls = cfg.grpc.tls.enabled;
  go.cert_file = cfg.grpc.tls.cert_file;
  go.key_file = cfg.grpc.tls.key_file;
  go.client_ca_file = cfg.grpc.client_ca_file;
  go.max_message_bytes = cfg.server.limits.max_body_bytes;
  go.max_streams = static_cast<int>(cfg.grpc.max_streams);
  auto loaded = load_grpc_transport(cfg.grpc.module, go, node);
  if (!loaded.ok()) return Error(ErrorCode::kInternal, "grpc: " + loaded.error().message);
  std::unique_ptr<node::GrpcTransport> grpc = std::move(loaded).value();
  if (auto p = grpc->start(); !p.ok()) {
    grpc->stop(0);
    return Error(ErrorCode::kInternal, "grpc: " + p.error().message);
  }
  return grpc;
}

}  // namespace rcan::rcand
