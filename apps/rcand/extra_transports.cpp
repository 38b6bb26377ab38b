#include "extra_transports.h"

#include "grpc_loader.h"

namespace rcan::rcand {

void ExtraTransports::stop(int drain_ms) {
  if (grpc) grpc->stop(drain_ms);
  if (udp) udp->stop();
}

Result<std::unique_ptr<ExtraTransports>> start_extra_transports(const config::NodeConfig& cfg,
                                                                node::Node& node) {
  auto t = std::make_unique<ExtraTransports>();
  if (cfg.udp.enabled) {
    node::UdpOptions uo;
    uo.bind_address = cfg.udp.bind_address;
    uo.port = cfg.udp.port;
    uo.heartbeat = cfg.udp.heartbeat;
    uo.discovery = cfg.udp.discovery;
    uo.discovery_per_source_per_min = cfg.udp.discovery_per_source_per_min;
    t->udp = std::make_unique<node::UdpService>(uo, node.services());
    if (auto p = t->udp->start(); !p.ok())
      return Error(ErrorCode::kInternal, "udp: " + p.error().message);
  }
  if (cfg.grpc.enabled) {
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
    if (!loaded.ok()) {
      t->stop(0);
      return Error(ErrorCode::kInternal, "grpc: " + loaded.error().message);
    }
    t->grpc = std::move(loaded).value();
    if (auto p = t->grpc->start(); !p.ok()) {
      t->stop(0);
      return Error(ErrorCode::kInternal, "grpc: " + p.error().message);
    }
  }
  return t;
}

}  // namespace rcan::rcand
