// The narrow interface between transports and the node.
//
// A transport (src/transport/) owns sockets, parsing, limits and timeouts; it knows nothing
// of RCAN. It turns each HTTP request into an HttpRequest and hands it to an HttpHandler,
// and each accepted WebSocket into a StreamReceiver fed by a StreamHandler. The node
// (src/node/) implements both handlers: routing, the pipeline, audit and safety live there.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace rcan::transport {

// The token of an Authorization value "Bearer <token>" (or "bearer <token>"); empty when the
// value has another form or carries no token. The one place a bearer token is read.
inline std::string_view bearer_token(std::string_view authorization) {
  if (authorization.size() > 7 &&
      (authorization.substr(0, 7) == "Bearer " || authorization.substr(0, 7) == "bearer "))
    return authorization.substr(7);
  return {};
}

struct HttpRequest {
  std::string method;                                      // "GET", "POST", "DELETE", …
  std::string target;                                      // as received: path plus query
  std::string path;                                        // percent-decoded path without the query
  std::vector<std::pair<std::string, std::string>> query;  // decoded, in order
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-cased, in order
  std::string body;
  std::string remote_addr;  // "ip:port"
  bool tls = false;
  // The connection was accepted from the reserve, over max_connections (ServerOptions): only a
  // request HttpHandler::serve_on_reserve() admits reaches the node on it, and it is closed
  // after its one request (a WebSocket: after read_timeout_ms).
  bool reserve = false;
  int64_t received_mono_us =
      0;  // steady clock when the transport had read the request (0: unknown)

  // First header / query value with that (lower-case) name; empty when absent.
  std::string_view header(std::string_view name) const {
    for (const auto& h : headers)
      if (h.first == name) return h.second;
    return {};
  }
  bool has_query(std::string_view name) const {
    for (const auto& q : query)
      if (q.first == name) return true;
    return false;
  }
  // The bearer token of the Authorization header (bearer_token()).
  std::string_view bearer() const { return bearer_token(header("authorization")); }
  std::string_view query_value(std::string_view name) const {
    for (const auto& q : query)
      if (q.first == name) return q.second;
    return {};
  }
};

struct HttpResponse {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
  std::vector<std::pair<std::string, std::string>> headers;  // extra headers
  // When the node handed the answer over (steady clock, µs; 0 = not timed). The transport then
  // reports how long the answer waited before its write began (HttpHandler::answer_waited).
  int64_t answered_mono_us = 0;
  // The request presented a valid credential. A connection keeps the long keep-alive
  // (idle_timeout_ms) only once one of its answers says so; until then it waits
  // unauthenticated_idle_timeout_ms for the next request. The transport knows no credentials:
  // the handler decides.
  bool authenticated = false;
};

// Called on a transport thread. `respond` must be called exactly once, from any thread,
// possibly later (after an audit record is durable, a HiTL decision, …). It is cheap and
// non-blocking: it only posts the response to the connection's executor.
class HttpHandler {
 public:
  using Respond = std::function<void(HttpResponse)>;
  virtual ~HttpHandler() = default;
  virtual void handle(HttpRequest req, Respond respond) = 0;
  // A timed answer (answered_mono_us set) waited `us` between respond() and the start of its
  // write. Called on a transport thread; must be cheap.
  virtual void answer_waited(int64_t us) { (void)us; }
  // Whether `req`, which arrived on a connection accepted from the reserve (req.reserve: the
  // server is at max_connections), is served — a stop must always get through. Any other request
  // is answered 503 `too_many_connections` by the transport and the connection closed. Also
  // asked for a WebSocket upgrade on such a connection. Called on a transport thread; cheap.
  virtual bool serve_on_reserve(const HttpRequest& req) {
    (void)req;
    return false;
  }
};

// The transport's side of one WebSocket. Thread-safe; calls after close are ignored.
class StreamSink {
 public:
  virtual ~StreamSink() = default;
  // Queues one text frame. Returns false when the connection is closed or its send queue
  // is over its limit (a slow reader is disconnected rather than buffered without bound).
  virtual bool send_text(std::string text) = 0;
  // Sends a close frame with `code` and closes.
  virtual void close(uint16_t code, std::string reason) = 0;
  virtual const std::string& remote_addr() const = 0;
};

// The node's side of one WebSocket. Callbacks come from the connection's executor, one
// at a time, in order.
class StreamReceiver {
 public:
  virtual ~StreamReceiver() = default;
  virtual void on_text(std::string text) = 0;
  // The peer sent a binary frame (unsupported in RCAN's binding → the node closes 1003).
  virtual void on_binary() = 0;
  // The connection is gone (peer close, error, timeout, shutdown). Called exactly once.
  virtual void on_closed() = 0;
};

class StreamHandler {
 public:
  virtual ~StreamHandler() = default;
  // Decides whether `upgrade` (a GET with Upgrade: websocket) may open a stream. Returning
  // nullptr refuses it: the transport then answers `refusal` instead of upgrading.
  virtual std::unique_ptr<StreamReceiver> open(const HttpRequest& upgrade,
                                               std::shared_ptr<StreamSink> sink,
                                               HttpResponse& refusal) = 0;
};

}  // namespace rcan::transport
