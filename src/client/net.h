// Blocking TCP (+ TLS) connections: one HTTP/1.1 exchange, or a WebSocket. The client
// library's transport, and also the node's outbound HTTP client (runtime/http_client.h), which
// words its own errors from ExchangeFailure. net.cpp and wire.cpp are their own small library
// (rcan_http), so that the node links them without the client's mDNS browsing (Avahi);
// ws_handshake is in ws_handshake.cpp, part of rcan_client.
#pragma once

#include <openssl/ssl.h>
#include <sys/socket.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "client/wire.h"
#include "rcan/client.h"

namespace rcan::client::net {

// The client's clocks in milliseconds: steady (deadlines, timers) and Unix (message timestamps).
int64_t mono_ms();
int64_t wall_ms();

// Where a failed connection or exchange stopped, for a caller that words its own errors.
enum class FailedAt : uint8_t {
  kNone,
  kResolve,    // the host name did not resolve
  kConnect,    // no address accepted the connection
  kAddress,    // every address the name resolved to was refused (ExchangeOptions::allow_address)
  kTls,        // the TLS set-up or handshake
  kSend,       // writing the request
  kReceive,    // reading the answer
  kNoAnswer,   // the peer closed without sending a byte
  kTooLarge,   // the answer's body (or head) is over the cap
  kChunked,    // a chunked answer where ExchangeOptions::refuse_chunked
  kMalformed,  // any other answer the parser refused
};
struct ExchangeFailure {
  FailedAt at = FailedAt::kNone;
  bool timed_out = false;  // the deadline passed (connect, TLS, send, receive)
  int sys_error = 0;       // errno of the last failed connect/send/receive, when there was one
};

class Conn {
 public:
  Conn() = default;
  ~Conn();
  Conn(const Conn&) = delete;
  Conn& operator=(const Conn&) = delete;

  // Connects within timeout_ms (and does the TLS handshake when ep.tls). With `allow`, an
  // address it refuses is never connected to: the check is on what the name resolved to, at
  // connect time (a name that resolves elsewhere later gains nothing).
  using AddressFilter = std::function<bool(const sockaddr*)>;
  Result<bool> open(const Endpoint& ep, int timeout_ms, const std::string& ca_file, bool insecure,
                    const AddressFilter& allow = {});
  Result<bool> write_all(std::string_view data, int timeout_ms);
  // Appends what arrives within timeout_ms to `buf`. Returns bytes read; 0 = peer closed.
  // TIMEOUT error when nothing came in time.
  Result<size_t> read_some(std::string& buf, int timeout_ms);
  // Data already decrypted and buffered inside TLS (poll() cannot see it).
  bool pending() const;
  int fd() const { return fd_; }
  void close();
  // Why the last open / write_all / read_some failed.
  const ExchangeFailure& failure() const { return failure_; }

 private:
  Result<bool> start_tls(const Endpoint& ep, const std::string& port, int64_t deadline,
                         const std::string& ca_file, bool insecure);
  ClientError fail(FailedAt at, bool timed_out, int sys_error, const std::string& code,
                   const std::string& message);

  int fd_ = -1;
  ExchangeFailure failure_;
  SSL_CTX* ctx_ = nullptr;
  SSL* ssl_ = nullptr;
};

ClientError transport_error(const std::string& code, const std::string& message);

struct ExchangeOptions {
  int timeout_ms = 10'000;  // one deadline over connect, TLS, send and every read
  std::string ca_file;      // TLS: trust anchors (empty: the system's)
  bool insecure = false;    // TLS: no certificate check
  size_t max_body = wire::kMaxBodyBytes;
  bool refuse_chunked = false;        // fail as soon as the head of a chunked answer arrives
  Conn::AddressFilter allow_address;  // set: only the addresses it allows are connected to
};

// Sends `request` (complete: head and body, written as given) on a fresh connection to `ep` and
// reads one answer. Errors: CONNECTION_FAILED, TLS_FAILED, TIMEOUT, BAD_RESPONSE (see
// http_exchange); `failure`, when given, says where it stopped.
Result<RawResponse> exchange(const Endpoint& ep, std::string_view request,
                             const ExchangeOptions& opts, ExchangeFailure* failure = nullptr);

// One request on a fresh connection (Connection: close), as the client library sends it.
Result<RawResponse> http_exchange(const Endpoint& ep, const std::string& method,
                                  const std::string& path, const std::string& body,
                                  const std::vector<std::pair<std::string, std::string>>& headers,
                                  int timeout_ms, const std::string& ca_file, bool insecure);

// Upgrades `conn` to a WebSocket on `path`. `leftover` receives bytes read past the 101.
Result<bool> ws_handshake(Conn& conn, const Endpoint& ep, const std::string& path,
                          const std::string& token, int timeout_ms, std::string& leftover);

}  // namespace rcan::client::net
