// HttpServer — the HTTP/1.1 + WebSocket transport of rcand (Boost.Beast behind a pimpl).
//
// One port serves HTTP/1.1 with keep-alive and WebSocket upgrades (plain, or TLS only when
// `tls` is set). Each request becomes an HttpRequest handed to the HttpHandler;
// each accepted upgrade becomes a StreamReceiver obtained from the StreamHandler
// (src/transport/http_api.h). The transport answers only transport-level failures itself —
// oversize bodies/headers, unparsable HTTP, slow clients, too many connections — always with
// the project's JSON error body (docs/TRANSPORT.md has the status mapping).
//
// Threading: `io_threads` threads run one io_context; every connection lives on its own
// strand, so its handler calls, StreamReceiver callbacks and writes never run concurrently.
// Handlers may answer from any thread; the answer is posted back to the connection's strand.
//
// This header includes no Boost: keep it that way, it is included by the daemon's main.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "rcan/result.h"
#include "transport/http_api.h"

namespace rcan::transport {

struct ServerOptions {
  std::string bind_address = "127.0.0.1";
  uint16_t port = 8080;                // 0 = ephemeral (tests); start() returns the bound port
  int io_threads = 2;                  // threads running the io_context (≥ 1)
  size_t max_body_bytes = 64 * 1024;   // larger Content-Length → 413 before reading the body
  size_t max_header_bytes = 8 * 1024;  // request line + header fields → 431 when exceeded
  int read_timeout_ms = 10000;         // whole request, first byte to last (defeats slow-loris)
  int idle_timeout_ms = 60000;         // keep-alive idle wait for the next request's first byte
  size_t max_connections = 1024;       // beyond it: the reserve, then accepted, 503, closed
  // Connections open at once from one IP address (ordinary and reserve together). Over it (and
  // over max_connections) a new connection closes the oldest one that never authenticated
  // (HttpResponse::authenticated) and waits for a request, and takes its slot; with none, it is
  // taken from the reserve; with no reserve left it is answered 503
  // `too_many_connections_from_address` and closed. 0 = no limit.
  size_t max_connections_per_address = 64;
  // Connections accepted over max_connections or max_connections_per_address when no connection
  // can be evicted, each for one request that HttpHandler::serve_on_reserve() admits (a stop); at
  // most 2 of them per address. 0 = none.
  size_t reserved_connections = 16;
  // Keep-alive wait of a connection none of whose answers said `authenticated` (HttpResponse);
  // also the deadline for the one request of a reserve connection. Capped by idle_timeout_ms.
  int unauthenticated_idle_timeout_ms = 5000;
  size_t ws_max_message_bytes = 64 * 1024;  // larger message → close 1009
  size_t ws_send_queue_limit = 256;         // queued frames per WebSocket; beyond it → close 1008
  int ws_handshake_timeout_ms = 10000;      // WebSocket opening/closing handshake limit
  // TLS: when set, the port serves HTTPS/WSS only. PEM files.
  bool tls = false;
  std::string cert_file;
  std::string key_file;
};

struct ServerStats {
  uint64_t connections_open = 0;   // TCP connections currently served (HTTP and WS)
  uint64_t connections_total = 0;  // accepted and served since start()
  uint64_t ws_streams_open = 0;    // WebSocket streams currently open
  uint64_t ws_streams_total = 0;
  uint64_t requests_total = 0;        // HTTP requests handed to the HttpHandler
  uint64_t rejected_connections = 0;  // refused with 503 for max_connections (or while stopping)
  uint64_t rejected_per_address = 0;  // refused with 503 for max_connections_per_address
  uint64_t reserve_connections = 0;   // accepted from the reserve over max_connections
  uint64_t reserve_refused = 0;       // requests on a reserve connection answered 503 (not a stop)
  uint64_t evicted_idle = 0;          // never-authenticated idle connections closed for a new one
  uint64_t evictable_now = 0;         // never-authenticated connections waiting for a request now
  uint64_t rejected_limits = 0;       // 413, 431, 408 answers and WS queue/size closes
  uint64_t bad_requests = 0;          // 400 answers for unparsable HTTP or bad percent-encoding
};

class HttpServer {
 public:
  // `http` and `stream` must outlive the server (until stop() has returned or the
  // destructor has run).
  HttpServer(ServerOptions options, HttpHandler& http, StreamHandler& stream);
  // Calls stop(0) when still running.
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Loads TLS material, binds, listens and starts the I/O threads. Returns the bound port.
  // Fails (without throwing) on a bad address, a busy port or unreadable TLS files.
  // Call at most once.
  Result<uint16_t> start();

  // Graceful shutdown: stops accepting, closes idle keep-alive connections, closes
  // WebSockets with 1001 (going away), lets in-flight requests finish and be answered with
  // `Connection: close` for up to `drain_ms`, then closes whatever is left and joins the
  // I/O threads. Idempotent. Must not be called from an I/O thread (from a handler).
  void stop(int drain_ms);

  // A consistent-enough snapshot (each counter is read atomically).
  ServerStats stats() const;

  class Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace rcan::transport
