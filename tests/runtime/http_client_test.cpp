// The node's outbound HTTP client (runtime/http_client.h) against a loopback server that answers
// one connection with canned bytes: the request it writes (byte for byte, the Content-Type
// rule), the answers it takes (Content-Length, until close) and the ones it refuses, each with
// its message (chunked, over the cap, malformed, none), the one deadline, a refused connect.
#include "runtime/http_client.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <string>
#include <thread>

#include "rcan/errors.h"
#include "test_support.h"

namespace rcan {
namespace {

// Accepts one connection, reads the request (head and Content-Length body), then sends
// `answer` (after `delay_ms`), and closes unless `hold_ms` says to keep it open that long.
class OneShotServer {
 public:
  explicit OneShotServer(std::string answer, int delay_ms = 0, int hold_ms = 0)
      : answer_(std::move(answer)), delay_ms_(delay_ms), hold_ms_(hold_ms) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    EXPECT_EQ(::listen(fd_, 4), 0);
    socklen_t len = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { serve(); });
  }
  ~OneShotServer() {
    thread_.join();
    ::close(fd_);
  }
  std::string url(const std::string& path = "/hook") const {
    return "http://127.0.0.1:" + std::to_string(port_) + path;
  }
  uint16_t port() const { return port_; }
  std::string request() {
    std::lock_guard<std::mutex> lock(mu_);
    return request_;
  }

 private:
  void serve() {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 10'000) <= 0) return;
    int c = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (c < 0) return;
    std::string req;
    char buf[8192];
    while (true) {
      pollfd q{c, POLLIN, 0};
      if (::poll(&q, 1, 5'000) <= 0) break;
      ssize_t n = ::recv(c, buf, sizeof buf, 0);
      if (n <= 0) break;
      req.append(buf, static_cast<size_t>(n));
      size_t he = req.find("\r\n\r\n");
      if (he == std::string::npos) continue;
      size_t cl = req.find("Content-Length: ");
      size_t want = cl == std::string::npos ? 0 : std::stoul(req.substr(cl + 16));
      if (req.size() >= he + 4 + want) break;
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      request_ = req;
    }
    if (delay_ms_ > 0) std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms_));
    if (!answer_.empty()) ::send(c, answer_.data(), answer_.size(), MSG_NOSIGNAL);
    if (hold_ms_ > 0) std::this_thread::sleep_for(std::chrono::milliseconds(hold_ms_));
    ::close(c);
  }

  std::string answer_;
  int delay_ms_ = 0;
  int hold_ms_ = 0;
  int fd_ = -1;
  uint16_t port_ = 0;
  std::thread thread_;
  std::mutex mu_;
  std::string request_;
};

std::string head_for(uint16_t port, const std::string& first_line) {
  return first_line + "\r\nHost: 127.0.0.1:" + std::to_string(port) +
         "\r\nAccept: application/json\r\nConnection: close\r\nUser-Agent: rcand\r\n";
}

// The message of a refused exchange (and that it is INTERNAL).
std::string refusal(const Result<HttpAnswer>& r) {
  if (r.ok()) return "(answered " + std::to_string(r->status) + ")";
  EXPECT_EQ(r.error().code, ErrorCode::kInternal);
  return r.error().message;
}

TEST(NodeHttpClient, WritesTheRequestByteForByte) {
  {
    OneShotServer s("HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\nok");
    auto r = http_request("GET", s.url("/probe?x=1"), "", 2000);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->status, 200);
    EXPECT_EQ(r->body, "ok");
    // No body and not a POST: no Content-Type, no Content-Length.
    EXPECT_EQ(s.request(), head_for(s.port(), "GET /probe?x=1 HTTP/1.1") + "\r\n");
  }
  {
    OneShotServer s("HTTP/1.1 204 No Content\r\n\r\n");
    auto r = http_request("POST", s.url(), "", 2000);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->status, 204);
    // A POST always says what it carries, even nothing.
    EXPECT_EQ(s.request(), head_for(s.port(), "POST /hook HTTP/1.1") +
                               "Content-Type: application/json\r\nContent-Length: 0\r\n\r\n");
  }
  {
    OneShotServer s("HTTP/1.1 201 Created\r\nContent-Length: 0\r\n\r\n");
    auto u = parse_http_url(s.url());
    ASSERT_TRUE(u.ok());
    auto r = http_post_json(*u, "{\"a\":1}", 2000);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->status, 201);
    EXPECT_EQ(s.request(), head_for(s.port(), "POST /hook HTTP/1.1") +
                               "Content-Type: application/json\r\nContent-Length: 7\r\n\r\n"
                               "{\"a\":1}");
  }
}

TEST(NodeHttpClient, TakesALengthOrReadsUntilClose) {
  {
    OneShotServer s("HTTP/1.1 200 OK\r\ncontent-length: 2\r\n\r\nokEXTRA");
    auto r = http_request("GET", s.url(), "", 2000);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->body, "ok");
  }
  {
    OneShotServer s("HTTP/1.0 200 OK\r\nContent-Type: application/json\r\n\r\n{\"b\":2}");
    auto r = http_request("GET", s.url(), "", 2000);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->body, "{\"b\":2}");
  }
  {
    OneShotServer s("HTTP/1.1 503 Service Unavailable\r\nContent-Length: 4\r\n\r\nbusy");
    auto r = http_request("GET", s.url(), "", 2000);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->status, 503);
    EXPECT_EQ(r->body, "busy");
  }
}

TEST(NodeHttpClient, RefusesChunkedAnswersAsSoonAsTheHeadArrives) {
  {
    OneShotServer s("HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n2\r\nok\r\n0\r\n\r\n");
    EXPECT_EQ(refusal(http_request("GET", s.url(), "", 2000)), "chunked answers are not supported");
  }
  {
    // The head alone, the connection kept open: refused without waiting for the deadline.
    OneShotServer s("HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n", 0, 1500);
    auto t0 = std::chrono::steady_clock::now();
    EXPECT_EQ(refusal(http_request("GET", s.url(), "", 5000)), "chunked answers are not supported");
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(1200));
  }
}

TEST(NodeHttpClient, RefusesAnswersOverTheCap) {
  {
    OneShotServer s("HTTP/1.1 200 OK\r\nContent-Length: 11\r\n\r\n0123456789a");
    EXPECT_EQ(refusal(http_request("GET", s.url(), "", 2000, 10)), "answer too large");
  }
  {
    OneShotServer s("HTTP/1.0 200 OK\r\n\r\n" + std::string(64 * 1024, 'x'));
    EXPECT_EQ(refusal(http_request("GET", s.url(), "", 2000, 1024)), "answer too large");
  }
  {
    OneShotServer s("HTTP/1.1 200 OK\r\nContent-Length: 10\r\n\r\n0123456789");
    auto r = http_request("GET", s.url(), "", 2000, 10);  // exactly the cap
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->body, "0123456789");
  }
}

TEST(NodeHttpClient, RefusesMalformedAndMissingAnswers) {
  for (const char* bad :
       {"SSH-2.0-OpenSSH\r\n\r\n", "HTTP/1.1 2x0 OK\r\n\r\n", "HTTP/1.1 200 OK\r\nContent-Le"}) {
    OneShotServer s(bad);
    EXPECT_EQ(refusal(http_request("GET", s.url(), "", 2000)), "malformed HTTP answer") << bad;
  }
  OneShotServer s("");  // reads the request, closes without a byte
  EXPECT_EQ(refusal(http_request("GET", s.url(), "", 2000)), "no answer");
}

TEST(NodeHttpClient, OneDeadlineForTheWholeExchange) {
  OneShotServer s("HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n", /*delay_ms=*/1500);
  auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(refusal(http_request("GET", s.url(), "", 300)), "no answer within 300 ms");
  auto took = std::chrono::steady_clock::now() - t0;
  EXPECT_GE(took, std::chrono::milliseconds(250));
  EXPECT_LT(took, std::chrono::milliseconds(1200));
}

TEST(NodeHttpClient, ARefusedConnectionNamesTheAddress) {
  uint16_t port = 0;
  {
    int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
    ::close(fd);  // bound, never listened: nothing there now
  }
  const std::string where = "127.0.0.1:" + std::to_string(port);
  EXPECT_EQ(refusal(http_request("GET", "http://" + where + "/", "", 2000)),
            "connect to " + where + " failed: Connection refused");
}

TEST(NodeHttpClient, OnlyPlainHttpUrls) {
  auto r = http_request("GET", "https://127.0.0.1:1/", "", 100);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kSchemaValidationFailed);
  EXPECT_EQ(r.error().message, "only http:// URLs are supported");
  EXPECT_EQ(r.error().field, "url");
}

TEST(NodeHttpClient, WebUrlsTakeHttpsWithItsDefaultPort) {
  auto u = parse_web_url("https://registry.example.com/api/v1");
  ASSERT_TRUE(u.ok()) << u.error().message;
  EXPECT_TRUE(u->tls);
  EXPECT_EQ(u->port, 443);
  EXPECT_EQ(u->host, "registry.example.com");
  EXPECT_EQ(u->path, "/api/v1");
  u = parse_web_url("https://127.0.0.1:8443");
  ASSERT_TRUE(u.ok());
  EXPECT_EQ(u->port, 8443);
  EXPECT_EQ(u->path, "/");
  u = parse_web_url("http://h:81/x");
  ASSERT_TRUE(u.ok());
  EXPECT_FALSE(u->tls);
  EXPECT_EQ(u->port, 81);
  EXPECT_FALSE(parse_web_url("ftp://h/").ok());
  EXPECT_FALSE(parse_web_url("https://").ok());
  EXPECT_FALSE(parse_web_url("https://h:0/").ok());
}

TEST(NodeHttpClient, SendsHeadersAndRefusesOnesThatWouldSplitTheRequest) {
  {
    OneShotServer s("HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\nok");
    auto u = parse_http_url(s.url("/api/v1/robots/RRN-000000000001"));
    ASSERT_TRUE(u.ok());
    HttpRequestOptions o;
    o.headers = {{"Authorization", "Bearer rcan_k_s"}};
    auto r = http_request("PATCH", *u, "{}", 2000, o);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(s.request(),
              head_for(s.port(), "PATCH /api/v1/robots/RRN-000000000001 HTTP/1.1") +
                  "Authorization: Bearer rcan_k_s\r\nContent-Type: application/json\r\n"
                  "Content-Length: 2\r\n\r\n{}");
  }
  HttpUrl nowhere{"127.0.0.1", 1, "/", false};
  for (auto h : std::vector<std::pair<std::string, std::string>>{{"X", "a\r\nEvil: 1"},
                                                                 {"X\nY", "v"},
                                                                 {"", "v"},
                                                                 {"X:Y", "v"},
                                                                 {"X", std::string(1, '\0')}}) {
    HttpRequestOptions o;
    o.headers = {h};
    auto r = http_request("GET", nowhere, "", 100, o);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kSchemaValidationFailed);
  }
}

// The registry's webhooks connect to public addresses only: the filter sees every address the
// name resolved to, at connect time, and one it refuses is never connected to.
TEST(NodeHttpClient, AnAddressFilterJudgesWhatTheNameResolvesTo) {
  OneShotServer s("HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\nok");
  auto u = parse_http_url("http://localhost:" + std::to_string(s.port()) + "/hook");
  ASSERT_TRUE(u.ok());
  std::vector<std::string> seen;
  HttpRequestOptions refuse;
  refuse.allow_address = [&](const sockaddr* sa) {
    char text[INET6_ADDRSTRLEN] = {};
    if (sa->sa_family == AF_INET)
      inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(sa)->sin_addr, text, sizeof text);
    else if (sa->sa_family == AF_INET6)
      inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6*>(sa)->sin6_addr, text, sizeof text);
    seen.emplace_back(text);
    return false;
  };
  EXPECT_EQ(refusal(http_request("POST", *u, "{}", 2000, refuse)),
            "refused: localhost resolves to no allowed address");
  EXPECT_NE(std::find(seen.begin(), seen.end(), "127.0.0.1"), seen.end());
  EXPECT_TRUE(s.request().empty());  // nothing connected
  HttpRequestOptions v4;
  v4.allow_address = [](const sockaddr* sa) { return sa->sa_family == AF_INET; };
  auto r = http_request("POST", *u, "{}", 2000, v4);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->status, 200);
}

// https against `openssl s_server` with a certificate for 127.0.0.1: answered when the
// certificate is trusted (ca_file), refused when it is not (the system's anchors).
TEST(NodeHttpClient, HttpsChecksTheServersCertificate) {
  test::TempDir dir;
  const std::string cert = dir.file("cert.pem"), key = dir.file("key.pem");
  auto gen =
      test::run({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                 "ec_paramgen_curve:prime256v1", "-nodes", "-days", "1", "-subj", "/CN=127.0.0.1",
                 "-addext", "subjectAltName=IP:127.0.0.1", "-keyout", key, "-out", cert});
  ASSERT_EQ(gen.exit_code, 0) << gen.err;
  auto serve_once = [&](test::Process& p, uint16_t port) {
    // -www answers a GET with a status page (HTTP/1.0, until close); stdout to stderr so
    // that the test sees ACCEPT.
    return p.start({"/bin/sh", "-c",
                    "exec /usr/bin/openssl s_server -www -naccept 1 -accept 127.0.0.1:" +
                        std::to_string(port) + " -cert " + cert + " -key " + key + " 1>&2"}) &&
           p.wait_for_line("ACCEPT", 10'000).has_value();
  };
  {
    const uint16_t port = test::free_port();
    test::Process server;
    ASSERT_TRUE(serve_once(server, port)) << server.err();
    auto u = parse_web_url("https://127.0.0.1:" + std::to_string(port) + "/");
    ASSERT_TRUE(u.ok());
    HttpRequestOptions o;
    o.ca_file = cert;
    auto r = http_request("GET", *u, "", 5000, o);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->status, 200);
    EXPECT_NE(r->body.find("s_server"), std::string::npos) << r->body;
  }
  {
    const uint16_t port = test::free_port();
    test::Process server;
    ASSERT_TRUE(serve_once(server, port)) << server.err();
    auto u = parse_web_url("https://127.0.0.1:" + std::to_string(port) + "/");
    ASSERT_TRUE(u.ok());
    auto r = http_request("GET", *u, "", 5000, HttpRequestOptions{});
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message.rfind("TLS with 127.0.0.1:", 0), 0u) << r.error().message;
  }
}

}  // namespace
}  // namespace rcan
