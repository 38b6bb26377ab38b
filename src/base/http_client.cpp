#include "base/http_client.h"

#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include "base/clock.h"
#include "rcan/errors.h"

namespace rcan {
namespace {

Error fail(const std::string& what) { return Error(ErrorCode::kInternal, what); }

// Waits for `events` until the deadline; false on timeout or error.
bool wait_fd(int fd, short events, int64_t deadline) {
  while (true) {
    int64_t left = deadline - Clock::system().mono_ms();
    if (left <= 0) return false;
    pollfd p{fd, events, 0};
    int r = ::poll(&p, 1, static_cast<int>(left));
    if (r > 0) return true;
    if (r == 0) return false;
    if (errno != EINTR) return false;
  }
}

}  // namespace

Result<HttpUrl> parse_http_url(std::string_view url) {
  constexpr std::string_view kScheme = "http://";
  auto bad = [](const char* why) { return Error(ErrorCode::kSchemaValidationFailed, why, "url"); };
  if (url.substr(0, kScheme.size()) != kScheme || url.size() > 2048)
    return bad("only http:// URLs are supported");
  std::string_view rest = url.substr(kScheme.size());
  size_t slash = rest.find('/');
  std::string_view authority = rest.substr(0, slash);
  HttpUrl u;
  if (slash != std::string_view::npos) u.path = std::string(rest.substr(slash));
  size_t colon = authority.rfind(':');
  if (colon != std::string_view::npos) {
    std::string_view ps = authority.substr(colon + 1);
    if (ps.empty() || ps.size() > 5) return bad("bad port");
    uint32_t p = 0;
    for (char c : ps) {
      if (c < '0' || c > '9') return bad("bad port");
      p = p * 10 + static_cast<uint32_t>(c - '0');
    }
    if (p < 1 || p > 65535) return bad("bad port");
    u.port = static_cast<uint16_t>(p);
    u.host = std::string(authority.substr(0, colon));
  } else {
    u.host = std::string(authority);
  }
  if (u.host.empty()) return bad("no host");
  for (char c : u.host)
    if (static_cast<unsigned char>(c) <= ' ' || c == '@' || c == '/' || c == 0x7f)
      return bad("bad host");
  for (char c : u.path)
    if (static_cast<unsigned char>(c) <= ' ' || c == 0x7f) return bad("bad path");
  return u;
}

int parse_status_line(std::string_view line) {
  if (line.size() < 12 || line.substr(0, 7) != "HTTP/1." || line[8] != ' ') return 0;
  int code = 0;
  for (size_t i = 9; i < 12; ++i) {
    if (line[i] < '0' || line[i] > '9') return 0;
    code = code * 10 + (line[i] - '0');
  }
  if (line.size() > 12 && line[12] != ' ' && line[12] != '\r') return 0;
  return code >= 100 && code <= 599 ? code : 0;
}

Result<HttpAnswer> http_request(std::string_view method, std::string_view url,
                                std::string_view body, int timeout_ms, size_t max_body) {
  auto u = parse_http_url(url);
  if (!u.ok()) return u.error();
  return http_request(method, *u, body, timeout_ms, max_body);
}

Result<HttpAnswer> http_request(std::string_view method, const HttpUrl& url, std::string_view body,
                                int timeout_ms, size_t max_body) {
  int64_t deadline = Clock::system().mono_ms() + timeout_ms;
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
    if (errno != EINPROGRESS)
      return close_fail("connect to " + url.host + ":" + port + " failed: " + std::strerror(errno));
    if (!wait_fd(fd, POLLOUT, deadline))
      return close_fail("connect to " + url.host + ":" + port + " timed out");
    int err = 0;
    socklen_t len = sizeof err;
    ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0)
      return close_fail("connect to " + url.host + ":" + port + " failed: " + std::strerror(err));
  }
  std::string req = std::string(method) + " " + url.path + " HTTP/1.1\r\nHost: " + url.host + ":" +
                    port +
                    "\r\nAccept: application/json\r\nConnection: close\r\nUser-Agent: rcand\r\n";
  if (!body.empty() || method == "POST")
    req +=
        "Content-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) + "\r\n";
  req += "\r\n";
  req.append(body);
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
    if (!wait_fd(fd, POLLIN, deadline))
      return close_fail("no answer within " + std::to_string(timeout_ms) + " ms");
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
        if (cl != std::string::npos)
          content_length = std::strtoul(head.c_str() + cl + 17, nullptr, 10);
        if (head.find("transfer-encoding: chunked") != std::string::npos)
          return close_fail("chunked answers are not supported");
      }
    }
  }
  ::close(fd);
  if (resp.empty()) return fail("no answer");
  size_t eol = resp.find("\r\n");
  HttpAnswer a;
  a.status = parse_status_line(
      std::string_view(resp).substr(0, eol == std::string::npos ? resp.size() : eol));
  if (header_end == std::string::npos || a.status == 0) return fail("malformed HTTP answer");
  a.body = resp.substr(header_end + 4);
  if (content_length != std::string::npos && a.body.size() > content_length)
    a.body.resize(content_length);
  if (a.body.size() > max_body) return fail("answer too large");
  return a;
}

}  // namespace rcan
