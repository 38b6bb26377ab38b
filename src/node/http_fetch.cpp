#include "node/http_fetch.h"

#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <fcntl.h>

#include "rcan/errors.h"

namespace rcan::node {

Result<UrlParts> parse_http_url(std::string_view url) {
  constexpr std::string_view kScheme = "http://";
  if (url.substr(0, kScheme.size()) != kScheme || url.size() > 2048)
    return Error(ErrorCode::kSchemaValidationFailed, "only http:// URLs are supported", "url");
  std::string_view rest = url.substr(kScheme.size());
  size_t slash = rest.find('/');
  std::string_view authority = rest.substr(0, slash);
  UrlParts u;
  if (slash != std::string_view::npos) u.path = std::string(rest.substr(slash));
  size_t colon = authority.rfind(':');
  if (colon != std::string_view::npos) {
    u.host = std::string(authority.substr(0, colon));
    u.port = std::string(authority.substr(colon + 1));
    if (u.port.empty() || u.port.size() > 5) return Error(ErrorCode::kSchemaValidationFailed, "bad port", "url");
    for (char c : u.port)
      if (c < '0' || c > '9') return Error(ErrorCode::kSchemaValidationFailed, "bad port", "url");
  } else {
    u.host = std::string(authority);
  }
  if (u.host.empty()) return Error(ErrorCode::kSchemaValidationFailed, "no host", "url");
  for (char c : u.host)
    if (c <= ' ' || c == '@' || c == '/') return Error(ErrorCode::kSchemaValidationFailed, "bad host", "url");
  for (char c : u.path)
    if (c <= ' ' || c == 0x7f) return Error(ErrorCode::kSchemaValidationFailed, "bad path", "url");
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

Result<FetchResult> http_fetch(std::string_view method, std::string_view url, std::string_view body,
                               int timeout_ms) {
  auto u = parse_http_url(url);
  if (!u.ok()) return u.error();
  auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  auto left = [&]() -> int {
    auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
    return ms > 0 ? static_cast<int>(ms) : 0;
  };
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (::getaddrinfo(u->host.c_str(), u->port.c_str(), &hints, &res) != 0 || !res)
    return Error(ErrorCode::kInternal, "cannot resolve " + u->host);
  int fd = ::socket(res->ai_family, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd < 0) {
    ::freeaddrinfo(res);
    return Error(ErrorCode::kInternal, "socket failed");
  }
  int rc = ::connect(fd, res->ai_addr, res->ai_addrlen);
  ::freeaddrinfo(res);
  auto fail = [&](const std::string& why) -> Result<FetchResult> {
    ::close(fd);
    return Error(ErrorCode::kInternal, why);
  };
  if (rc != 0 && errno != EINPROGRESS) return fail("connect failed");
  pollfd pfd{fd, POLLOUT, 0};
  if (rc != 0) {
    if (::poll(&pfd, 1, left()) <= 0) return fail("connect timed out");
    int err = 0;
    socklen_t len = sizeof err;
    ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) return fail("connect refused");
  }
  std::string req = std::string(method) + " " + u->path + " HTTP/1.1\r\nHost: " + u->host + ":" + u->port +
                    "\r\nConnection: close\r\nUser-Agent: rcand\r\n";
  if (!body.empty() || method == "POST")
    req += "Content-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) + "\r\n";
  req += "\r\n";
  req.append(body);
  size_t off = 0;
  while (off < req.size()) {
    pfd = {fd, POLLOUT, 0};
    if (::poll(&pfd, 1, left()) <= 0) return fail("send timed out");
    ssize_t n = ::send(fd, req.data() + off, req.size() - off, MSG_NOSIGNAL);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
    if (n <= 0) return fail("send failed");
    off += static_cast<size_t>(n);
  }
  std::string in;
  for (;;) {
    pfd = {fd, POLLIN, 0};
    if (::poll(&pfd, 1, left()) <= 0) break;
    char buf[4096];
    ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
    if (n <= 0) break;
    in.append(buf, static_cast<size_t>(n));
    if (in.size() > (1u << 20)) break;
  }
  ::close(fd);
  FetchResult r;
  size_t eol = in.find("\r\n");
  r.status = parse_status_line(std::string_view(in).substr(0, eol == std::string::npos ? in.size() : eol));
  if (r.status == 0) return Error(ErrorCode::kInternal, in.empty() ? "no answer" : "not an HTTP answer");
  size_t hdr_end = in.find("\r\n\r\n");
  if (hdr_end != std::string::npos) r.body = in.substr(hdr_end + 4);
  return r;
}

}  // namespace rcan::node
