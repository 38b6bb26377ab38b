// gRPC transport (docs/TRANSPORT.md §gRPC): the rcan.v1.Rcan service of proto/rcan.proto —
// unary Send and bidirectional Stream — on gRPC's callback API. Every message is converted
// to the node's JSON message and handed to Node::submit (the one pipeline); answers and
// errors go back as RCANMessages and gRPC status codes. No gRPC header in this file (pimpl).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "rcan/result.h"

namespace rcan::node {

class Node;

struct GrpcOptions {
  std::string bind_address = "127.0.0.1";
  uint16_t port = 8081;  // 0 = any free port (the bound one is returned by start())
  bool tls = false;
  std::string cert_file;       // PEM chain (tls)
  std::string key_file;        // PEM key (tls)
  std::string client_ca_file;  // optional: require client certificates signed by it
  size_t max_message_bytes = 64 * 1024;
  int max_streams = 64;            // open Stream calls; one more is refused RESOURCE_EXHAUSTED
  size_t stream_send_queue = 256;  // answers/events queued on one stream; beyond: the stream ends
};

struct GrpcStats {
  uint64_t calls_total = 0;
  uint64_t streams_open = 0;
  uint64_t streams_total = 0;
  uint64_t streams_refused = 0;
};

class GrpcServer {
 public:
  GrpcServer(GrpcOptions opt, Node& node);
  ~GrpcServer();  // stop(0)
  GrpcServer(const GrpcServer&) = delete;
  GrpcServer& operator=(const GrpcServer&) = delete;

  // Binds and serves; returns the bound port. Errors: INTERNAL (cannot read the TLS files,
  // cannot bind).
  Result<uint16_t> start();
  // Ends every stream (status UNAVAILABLE "node shutting down"), lets calls in flight finish
  // for up to drain_ms, then cancels the rest. Idempotent; call before Node::shutdown().
  void stop(int drain_ms);
  GrpcStats stats() const;

  struct Impl;  // grpc_server.cpp

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace rcan::node
