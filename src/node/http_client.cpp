#include "node/http_client.h"

#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <fcntl.h>

#include "rcan/errors.h"

namespace rcan::node {
namespace {

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

Error fail(const std::string& what) { return Error(ErrorCode::kInternal, what); }

// Waits for `events` until the deadline; false on timeout or error.
bool wait_fd(int fd, short events, int64_t deadline) {
  while (true) {
    int64_t left = deadline - now_ms();
    if (left <= 0) return false;
    pollfd p{fd, events, 0};
    int r = ::poll(&p, 1, static_cast<int>(left));
    if (r > 0) return true;
    if (r == 0) return false;
    if (errno != EINTR) return false;
  }
}

}  // namespace

Result<HttpUrl> parse_http_url(const std::string& url) {
  const std::string scheme = "http://";
  if (url.rfind(scheme, 0) != 0) return fail("only http:// URLs are supported: " + url.substr(0, 128));
  std::string rest = url.substr(scheme.size());
  HttpUrl u;
  size_t slash = rest.find('/');
  std::string hostport = rest.substr(0, slash);
  if (slash != std::string::npos) u.path = rest.substr(slash);
  size_t colon = hostport.rfind(':');
  u.host = hostport.substr(0, colon);
  if (colon != std::string::npos) {
    std::string ps = hostport.substr(colon + 1);
    char* end = nullptr;
    long p = std::strtol(ps.c_str(), &end, 10);
    if (ps.empty() || !end || *end || p < 1 || p > 65535) return fail("bad port in " + url.substr(0, 128));
    u.port = static_cast<uint16_t>(p);
  }
  if (u.host.empty()) return fail("no host in " + url.substr(0, 128));
  for (char c : u.host + u.path)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) return fail("bad character in URL");
  return u;
}

Result<HttpAnswer> http_post_json(const HttpUrl& url, const std::string& json_body, int timeout_ms,
                                  size_t max_body) {
  int64_t deadline = now_ms() + timeout_ms;
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  std::string port = std::to_string(url.port);
  if (::getaddrinfo(url.host.c_str(), port.c_str(), &hints, &res) != 0 || !res)
    return fail("cannot resolve " + url.host);
  int fd = ::socket(res->ai_family, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd < 0) {
    ::freeaddrinfo(res);
    return fail("socket failed");
  }
  int rc = ::connect(fd, res->ai_addr, res->ai_addrlen);
  ::freeaddrinfo(res);
  auto close_fail = [&](const std::string& what) -> Error {
    ::close(fd);
    return fail(what);
  };
  if (rc != 0) {
    if (errno != EINPROGRESS) return close_fail("connect to " + url.host + ":" + port + " failed: " + std::strerror(errno));
    if (!wait_fd(fd, POLLOUT, deadline)) return close_fail("connect to " + url.host + ":" + port + " timed out");
    int err = 0;
    socklen_t len = sizeof err;
    ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) return close_fail("connect to " + url.host + ":" + port + " failed: " + std::strerror(err));
  }
  std::string req = "POST " + url.path + " HTTP/1.1\r\nHost: " + url.host + ":" + port +
                    "\r\nContent-Type: application/json\r\nAccept: application/json\r\nConnection: close\r\n"
                    "Content-Length: " + std::to_string(json_body.size()) + "\r\n\r\n" + json_body;
  size_t sent = 0;
  while (sent < req.size()) {
    if (!wait_fd(fd, POLLOUT, deadline)) return close_fail("send timed out");
    ssize_t n = ::send(fd, req.data() + sent, req.size() - sent, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) continue;
      return close_fail("send failed");
    }
    sent += static_cast<size_t>(n);
  }
  std::string resp;
  char buf[16384];
  size_t header_end = std::string::npos;
  size_t content_length = std::string::npos;
  while (true) {
    if (header_end != std::string::npos && content_length != std::string::npos &&
        resp.size() >= header_end + 4 + content_length)
      break;
    if (!wait_fd(fd, POLLIN, deadline)) return close_fail("no answer within " + std::to_string(timeout_ms) + " ms");
    ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) continue;
      return close_fail("receive failed");
    }
    if (n == 0) break;
    resp.append(buf, static_cast<size_t>(n));
    if (resp.size() > max_body + 16384) return close_fail("answer too large");
    if (header_end == std::string::npos) {
      header_end = resp.find("\r\n\r\n");
      if (header_end != std::string::npos) {
        std::string head = resp.substr(0, header_end);
        for (auto& c : head) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        size_t cl = head.find("\r\ncontent-length:");
        if (cl != std::string::npos) content_length = std::strtoul(head.c_str() + cl + 17, nullptr, 10);
        if (head.find("transfer-encoding: chunked") != std::string::npos)
          return close_fail("chunked answers are not supported");
      }
    }
  }
  ::close(fd);
  if (header_end == std::string::npos || resp.size() < 12 || resp.compare(0, 5, "HTTP/") != 0)
    return fail("malformed HTTP answer");
  HttpAnswer a;
  a.status = std::atoi(resp.c_str() + 9);
  a.body = resp.substr(header_end + 4);
  if (content_length != std::string::npos && a.body.size() > content_length) a.body.resize(content_length);
  if (a.body.size() > max_body) return fail("answer too large");
  return a;
}

}  // namespace rcan::node
