#include "client/net.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/err.h>
#include <openssl/x509v3.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>

#include "base/clock.h"
#include "base/strings.h"

namespace rcan::client {

// With the connection code: the exchange's errors name the endpoint, and this file (rcan_http)
// is linked without client.cpp.
std::string Endpoint::url() const {
  std::string h = host.find(':') != std::string::npos ? "[" + host + "]" : host;
  return std::string(tls ? "https://" : "http://") + h + ":" + std::to_string(port) + base_path;
}

}  // namespace rcan::client

namespace rcan::client::net {

int64_t mono_ms() { return steady_ms(); }

int64_t wall_ms() { return unix_ms(); }

namespace {

std::string ssl_error_text() {
  unsigned long e = ERR_get_error();
  if (e == 0) return "TLS handshake failed";
  char buf[256];
  ERR_error_string_n(e, buf, sizeof buf);
  ERR_clear_error();
  return buf;
}

bool wait_fd(int fd, short events, int timeout_ms) {
  pollfd p{fd, events, 0};
  int r;
  do {
    r = ::poll(&p, 1, timeout_ms < 0 ? 0 : timeout_ms);
  } while (r < 0 && errno == EINTR);
  return r > 0;
}

}  // namespace

ClientError transport_error(const std::string& code, const std::string& message) {
  ClientError e;
  e.code = code;
  e.message = message;
  return e;
}

ClientError Conn::fail(FailedAt at, bool timed_out, int sys_error, const std::string& code,
                       const std::string& message) {
  failure_ = ExchangeFailure{at, timed_out, sys_error};
  return transport_error(code, message);
}

Conn::~Conn() { close(); }

void Conn::close() {
  if (ssl_) {
    SSL_free(ssl_);
    ssl_ = nullptr;
  }
  if (ctx_) {
    SSL_CTX_free(ctx_);
    ctx_ = nullptr;
  }
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
}

bool Conn::pending() const { return ssl_ && SSL_pending(ssl_) > 0; }

Result<bool> Conn::open(const Endpoint& ep, int timeout_ms, const std::string& ca_file,
                        bool insecure, const AddressFilter& allow) {
  close();
  int64_t deadline = mono_ms() + timeout_ms;
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_family = AF_UNSPEC;
  addrinfo* res = nullptr;
  std::string port = std::to_string(ep.port);
  int gai = ::getaddrinfo(ep.host.c_str(), port.c_str(), &hints, &res);
  if (gai != 0 || !res)
    return fail(FailedAt::kResolve, false, 0, "CONNECTION_FAILED",
                "cannot resolve " + ep.host + ": " + gai_strerror(gai));
  std::string last = "no address";
  int last_errno = 0;
  bool timed_out = false;
  bool any_allowed = false;
  for (addrinfo* ai = res; ai; ai = ai->ai_next) {
    if (allow && !allow(ai->ai_addr)) continue;
    any_allowed = true;
    int fd =
        ::socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, ai->ai_protocol);
    if (fd < 0) {
      last_errno = errno;
      continue;
    }
    int rc = ::connect(fd, ai->ai_addr, ai->ai_addrlen);
    timed_out = false;
    if (rc != 0 && errno == EINPROGRESS) {
      if (wait_fd(fd, POLLOUT, static_cast<int>(deadline - mono_ms()))) {
        int err = 0;
        socklen_t len = sizeof err;
        ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
        rc = err == 0 ? 0 : -1;
        errno = err;
      } else {
        errno = ETIMEDOUT;
        timed_out = true;
        rc = -1;
      }
    }
    if (rc == 0) {
      fd_ = fd;
      break;
    }
    last_errno = errno;
    last = std::strerror(errno);
    ::close(fd);
  }
  ::freeaddrinfo(res);
  if (!any_allowed)
    return fail(FailedAt::kAddress, false, 0, "CONNECTION_FAILED",
                "refused to connect to " + ep.host + ": it resolves to no allowed address");
  if (fd_ < 0)
    return fail(FailedAt::kConnect, timed_out, last_errno, "CONNECTION_FAILED",
                "cannot connect to " + ep.host + ":" + port + ": " + last + " (is rcand running?)");
  int one = 1;
  ::setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  if (!ep.tls) return true;

  return start_tls(ep, port, deadline, ca_file, insecure);
}

// TLS over the connected socket: TLS 1.2 or later; unless `insecure`, the peer's certificate
// verified against `ca_file` (or the system's anchors) and the host name or IP address.
Result<bool> Conn::start_tls(const Endpoint& ep, const std::string& port, int64_t deadline,
                             const std::string& ca_file, bool insecure) {
  ctx_ = SSL_CTX_new(TLS_client_method());
  if (!ctx_) return fail(FailedAt::kTls, false, 0, "TLS_FAILED", ssl_error_text());
  SSL_CTX_set_min_proto_version(ctx_, TLS1_2_VERSION);
  if (!insecure) {
    SSL_CTX_set_verify(ctx_, SSL_VERIFY_PEER, nullptr);
    int ok = ca_file.empty() ? SSL_CTX_set_default_verify_paths(ctx_)
                             : SSL_CTX_load_verify_locations(ctx_, ca_file.c_str(), nullptr);
    if (ok != 1)
      return fail(FailedAt::kTls, false, 0, "TLS_FAILED",
                  "cannot load trust anchors " + ca_file + ": " + ssl_error_text());
  }
  ssl_ = SSL_new(ctx_);
  if (!ssl_) return fail(FailedAt::kTls, false, 0, "TLS_FAILED", ssl_error_text());
  SSL_set_fd(ssl_, fd_);
  SSL_set_tlsext_host_name(ssl_, ep.host.c_str());
  if (!insecure) {
    X509_VERIFY_PARAM* param = SSL_get0_param(ssl_);
    in6_addr a6;
    in_addr a4;
    bool is_ip = inet_pton(AF_INET, ep.host.c_str(), &a4) == 1 ||
                 inet_pton(AF_INET6, ep.host.c_str(), &a6) == 1;
    if (is_ip)
      X509_VERIFY_PARAM_set1_ip_asc(param, ep.host.c_str());
    else
      SSL_set1_host(ssl_, ep.host.c_str());
  }
  while (true) {
    int r = SSL_connect(ssl_);
    if (r == 1) break;
    int e = SSL_get_error(ssl_, r);
    int left = static_cast<int>(deadline - mono_ms());
    if (e == SSL_ERROR_WANT_READ && left > 0 && wait_fd(fd_, POLLIN, left)) continue;
    if (e == SSL_ERROR_WANT_WRITE && left > 0 && wait_fd(fd_, POLLOUT, left)) continue;
    if (left <= 0)
      return fail(FailedAt::kTls, true, 0, "TIMEOUT",
                  "TLS handshake with " + ep.host + " timed out");
    long v = SSL_get_verify_result(ssl_);
    std::string why = v != X509_V_OK
                          ? std::string("certificate: ") + X509_verify_cert_error_string(v)
                          : ssl_error_text();
    return fail(FailedAt::kTls, false, 0, "TLS_FAILED",
                "TLS with " + ep.host + ":" + port + " failed: " + why);
  }
  return true;
}

Result<bool> Conn::write_all(std::string_view data, int timeout_ms) {
  int64_t deadline = mono_ms() + timeout_ms;
  size_t off = 0;
  while (off < data.size()) {
    int left = static_cast<int>(deadline - mono_ms());
    if (left <= 0) return fail(FailedAt::kSend, true, 0, "TIMEOUT", "sending timed out");
    if (ssl_) {
      int r = SSL_write(ssl_, data.data() + off,
                        static_cast<int>(std::min<size_t>(data.size() - off, 1 << 30)));
      if (r > 0) {
        off += static_cast<size_t>(r);
        continue;
      }
      int e = SSL_get_error(ssl_, r);
      if (e == SSL_ERROR_WANT_WRITE && wait_fd(fd_, POLLOUT, left)) continue;
      if (e == SSL_ERROR_WANT_READ && wait_fd(fd_, POLLIN, left)) continue;
      return fail(FailedAt::kSend, false, 0, "CONNECTION_FAILED",
                  "TLS write failed: " + ssl_error_text());
    }
    ssize_t r = ::send(fd_, data.data() + off, data.size() - off, MSG_NOSIGNAL);
    if (r > 0) {
      off += static_cast<size_t>(r);
      continue;
    }
    if (r < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) {
      wait_fd(fd_, POLLOUT, left);
      continue;
    }
    return fail(FailedAt::kSend, false, errno, "CONNECTION_FAILED",
                std::string("send failed: ") + std::strerror(errno));
  }
  return true;
}

Result<size_t> Conn::read_some(std::string& buf, int timeout_ms) {
  char tmp[16384];
  int64_t deadline = mono_ms() + timeout_ms;
  while (true) {
    if (ssl_) {
      int r = SSL_read(ssl_, tmp, sizeof tmp);
      if (r > 0) {
        buf.append(tmp, static_cast<size_t>(r));
        return static_cast<size_t>(r);
      }
      int e = SSL_get_error(ssl_, r);
      if (e == SSL_ERROR_ZERO_RETURN) return size_t{0};
      int left = static_cast<int>(deadline - mono_ms());
      if ((e == SSL_ERROR_WANT_READ || e == SSL_ERROR_WANT_WRITE)) {
        if (left <= 0 || !wait_fd(fd_, e == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT, left))
          return fail(FailedAt::kReceive, true, 0, "TIMEOUT", "no answer in time");
        continue;
      }
      if (e == SSL_ERROR_SYSCALL && ERR_peek_error() == 0) return size_t{0};  // unclean close
      return fail(FailedAt::kReceive, false, 0, "CONNECTION_FAILED",
                  "TLS read failed: " + ssl_error_text());
    }
    ssize_t r = ::recv(fd_, tmp, sizeof tmp, 0);
    if (r > 0) {
      buf.append(tmp, static_cast<size_t>(r));
      return static_cast<size_t>(r);
    }
    if (r == 0) return size_t{0};
    if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) {
      int left = static_cast<int>(deadline - mono_ms());
      if (left <= 0 || !wait_fd(fd_, POLLIN, left))
        return fail(FailedAt::kReceive, true, 0, "TIMEOUT", "no answer in time");
      continue;
    }
    if (errno == ECONNRESET) return size_t{0};
    return fail(FailedAt::kReceive, false, errno, "CONNECTION_FAILED",
                std::string("receive failed: ") + std::strerror(errno));
  }
}

namespace {

bool is_chunked(const wire::ParsedResponse& pr) {
  for (const auto& [k, v] : pr.headers) {
    if (k != "transfer-encoding") continue;
    if (ascii_lower(v).find("chunked") != std::string::npos) return true;
  }
  return false;
}

// What the parser refused, for ExchangeFailure: its errors name an oversize "... too large".
FailedAt refused_answer(std::string_view buf, bool eof, const std::string& err) {
  if (eof && buf.empty()) return FailedAt::kNoAnswer;
  if (err.find("too large") != std::string::npos) return FailedAt::kTooLarge;
  return FailedAt::kMalformed;
}

}  // namespace

Result<RawResponse> exchange(const Endpoint& ep, std::string_view request,
                             const ExchangeOptions& opts, ExchangeFailure* failure) {
  int64_t deadline = mono_ms() + opts.timeout_ms;
  Conn c;
  // A failure of the connection (it knows where it stopped), or of the exchange itself.
  auto conn_failed = [&](const ClientError& e) -> ClientError {
    if (failure) *failure = c.failure();
    return e;
  };
  auto failed = [&](FailedAt at, bool timed_out, const ClientError& e) -> ClientError {
    if (failure) *failure = ExchangeFailure{at, timed_out, 0};
    return e;
  };
  if (auto o = c.open(ep, opts.timeout_ms, opts.ca_file, opts.insecure, opts.allow_address);
      !o.ok())
    return conn_failed(o.error());
  if (auto w = c.write_all(request, static_cast<int>(deadline - mono_ms())); !w.ok())
    return conn_failed(w.error());
  std::string buf;
  bool eof = false;
  while (true) {
    wire::ParsedResponse pr;
    size_t consumed = 0;
    std::string err;
    wire::Parse p = wire::parse_response(buf, eof, pr, consumed, err, opts.max_body);
    if (opts.refuse_chunked && is_chunked(pr))
      return failed(FailedAt::kChunked, false,
                    transport_error("BAD_RESPONSE", "bad HTTP answer from " + ep.url() +
                                                        ": chunked answers are not supported"));
    if (p == wire::Parse::kComplete) {
      RawResponse r;
      r.status = pr.status;
      r.headers = std::move(pr.headers);
      r.body = std::move(pr.body);
      return r;
    }
    if (p == wire::Parse::kError)
      return failed(
          refused_answer(buf, eof, err), false,
          transport_error("BAD_RESPONSE", "bad HTTP answer from " + ep.url() + ": " + err));
    int left = static_cast<int>(deadline - mono_ms());
    if (left <= 0)
      return failed(FailedAt::kReceive, true,
                    transport_error("TIMEOUT", "no complete answer from " + ep.url() + " in time"));
    auto n = c.read_some(buf, left);
    if (!n.ok()) return conn_failed(n.error());
    if (*n == 0) eof = true;
  }
}

Result<RawResponse> http_exchange(const Endpoint& ep, const std::string& method,
                                  const std::string& path, const std::string& body,
                                  const std::vector<std::pair<std::string, std::string>>& headers,
                                  int timeout_ms, const std::string& ca_file, bool insecure) {
  std::string host = ep.host.find(':') != std::string::npos ? "[" + ep.host + "]" : ep.host;
  std::string req =
      method + " " + ep.base_path + path + " HTTP/1.1\r\nHost: " + host + ":" +
      std::to_string(ep.port) +
      "\r\nConnection: close\r\nUser-Agent: rcan-client/0.1\r\nAccept: application/json\r\n";
  bool typed = false;  // a Content-Type among `headers` replaces the JSON default
  for (const auto& [k, v] : headers) {
    req += k + ": " + v + "\r\n";
    typed = typed || ascii_lower(k) == "content-type";
  }
  if (!body.empty() || method == "POST" || method == "PUT")
    req += std::string(typed ? "" : "Content-Type: application/json\r\n") +
           "Content-Length: " + std::to_string(body.size()) + "\r\n";
  req += "\r\n";
  req += body;
  ExchangeOptions o;
  o.timeout_ms = timeout_ms;
  o.ca_file = ca_file;
  o.insecure = insecure;
  return exchange(ep, req, o);
}

}  // namespace rcan::client::net
