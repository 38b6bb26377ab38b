// Blocking TCP (+ TLS) connections for the client: one HTTP/1.1 exchange, or a WebSocket.
#pragma once

#include <openssl/ssl.h>

#include <cstdint>
#include <memory>
#include <string>

#include "client/wire.h"
#include "rcan/client.h"

namespace rcan::client::net {

// The client's clocks in milliseconds: steady (deadlines, timers) and Unix (message timestamps).
int64_t mono_ms();
int64_t wall_ms();

class Conn {
 public:
  Conn() = default;
  ~Conn();
  Conn(const Conn&) = delete;
  Conn& operator=(const Conn&) = delete;

  // Connects within timeout_ms (and does the TLS handshake when ep.tls).
  Result<bool> open(const Endpoint& ep, int timeout_ms, const std::string& ca_file, bool insecure);
  Result<bool> write_all(std::string_view data, int timeout_ms);
  // Appends what arrives within timeout_ms to `buf`. Returns bytes read; 0 = peer closed.
  // TIMEOUT error when nothing came in time.
  Result<size_t> read_some(std::string& buf, int timeout_ms);
  // Data already decrypted and buffered inside TLS (poll() cannot see it).
  bool pending() const;
  int fd() const { return fd_; }
  void close();

 private:
  int fd_ = -1;
  SSL_CTX* ctx_ = nullptr;
  SSL* ssl_ = nullptr;
};

ClientError transport_error(const std::string& code, const std::string& message);

// One request on a fresh connection (Connection: close).
Result<RawResponse> http_exchange(const Endpoint& ep, const std::string& method,
                                  const std::string& path, const std::string& body,
                                  const std::vector<std::pair<std::string, std::string>>& headers,
                                  int timeout_ms, const std::string& ca_file, bool insecure);

// Upgrades `conn` to a WebSocket on `path`. `leftover` receives bytes read past the 101.
Result<bool> ws_handshake(Conn& conn, const Endpoint& ep, const std::string& path,
                          const std::string& token, int timeout_ms, std::string& leftover);

}  // namespace rcan::client::net
