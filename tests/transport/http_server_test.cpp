// HttpServer over real loopback sockets: keep-alive, responses from other threads, limits,
// timeouts, percent-decoding, WebSocket framing and limits, graceful stop, TLS.
// The clients are plain POSIX sockets (and OpenSSL for TLS) so this file needs no Beast.
#include "transport/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "rcan/json.h"
#include "runtime/log.h"
#include "test_support.h"

namespace rcan::transport {
namespace {

using namespace std::chrono_literals;
using transport::HttpRequest;
using transport::HttpResponse;

// ---- a tiny blocking client ------------------------------------------------------------------

struct Resp {
  int status = 0;
  std::map<std::string, std::string> headers;  // lower-case names
  std::string body;
  std::string header(const std::string& n) const {
    auto it = headers.find(n);
    return it == headers.end() ? std::string() : it->second;
  }
  json::Value json() const {
    auto v = json::parse(body);
    EXPECT_TRUE(v.ok()) << body;
    return v.ok() ? *v : json::Value();
  }
  // payload.error_code of the project's error body.
  std::string error_code() const {
    auto v = json();
    const json::Value* p = v.get("payload");
    const json::Value* c = p ? p->get("error_code") : nullptr;
    return c && c->is_string() ? c->as_string() : std::string();
  }
  std::string error_reason() const {
    auto v = json();
    const json::Value* p = v.get("payload");
    const json::Value* d = p ? p->get("detail") : nullptr;
    const json::Value* r = d ? d->get("reason") : nullptr;
    if (!r && p) r = p->get("reason");
    return r && r->is_string() ? r->as_string() : std::string();
  }
};

class Client {
 public:
  // `source`: a loopback address to connect from (127.0.0.2, …), to be another client address.
  explicit Client(uint16_t port, int rcvbuf = 0, const char* source = nullptr) {
    const test::LoopbackSocket s = test::loopback_socket(port, source, rcvbuf);
    fd_ = s.fd;
    connected_ = s.connected;
  }
  ~Client() {
    if (fd_ >= 0) ::close(fd_);
  }
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  bool connected() const { return connected_; }
  // Closes our end (a WebSocket server waits for it after the close handshake).
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  bool send(std::string_view data) {
    while (!data.empty()) {
      const ssize_t n = ::send(fd_, data.data(), data.size(), MSG_NOSIGNAL);
      if (n <= 0) return false;
      data.remove_prefix(static_cast<size_t>(n));
    }
    return true;
  }
  // Reads more bytes into the buffer; false on EOF, error or timeout.
  bool fill(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) <= 0) return false;
    char tmp[65536];
    const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
    if (n <= 0) {
      eof_ = true;
      return false;
    }
    buf_.append(tmp, static_cast<size_t>(n));
    return true;
  }
  std::optional<Resp> read_response(int timeout_ms = 5000, bool head = false) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    auto left = [&] {
      return static_cast<int>(std::max<int64_t>(
          0, std::chrono::duration_cast<std::chrono::milliseconds>(deadline -
                                                                   std::chrono::steady_clock::now())
                 .count()));
    };
    size_t end;
    while ((end = buf_.find("\r\n\r\n")) == std::string::npos)
      if (!fill(left())) return std::nullopt;
    Resp r;
    std::string head_text = buf_.substr(0, end);
    buf_.erase(0, end + 4);
    size_t line_end = head_text.find("\r\n");
    std::string status_line = head_text.substr(0, line_end);
    if (status_line.size() < 12) return std::nullopt;
    r.status = std::atoi(status_line.c_str() + 9);
    size_t pos = line_end == std::string::npos ? head_text.size() : line_end + 2;
    while (pos < head_text.size()) {
      size_t e = head_text.find("\r\n", pos);
      if (e == std::string::npos) e = head_text.size();
      std::string line = head_text.substr(pos, e - pos);
      pos = e + 2;
      const size_t colon = line.find(':');
      if (colon == std::string::npos) continue;
      std::string name = line.substr(0, colon);
      for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      std::string value = line.substr(colon + 1);
      while (!value.empty() && value.front() == ' ') value.erase(0, 1);
      r.headers[name] = value;
    }
    if (head || r.status < 200 || r.status == 204 || r.status == 304) return r;
    const size_t len = static_cast<size_t>(std::atoll(r.header("content-length").c_str()));
    while (buf_.size() < len)
      if (!fill(left())) return std::nullopt;
    r.body = buf_.substr(0, len);
    buf_.erase(0, len);
    return r;
  }
  // True when the server closes the connection within the timeout (pending data discarded).
  bool wait_closed(int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      char tmp[65536];
      const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
      if (n <= 0) return true;
      buf_.append(tmp, static_cast<size_t>(n));
    }
    return false;
  }
  std::string& buffer() { return buf_; }
  int fd() const { return fd_; }

  // ---- WebSocket (client side: masked frames) ----
  bool ws_handshake(const std::string& path, std::optional<Resp>* out = nullptr) {
    send("GET " + path +
         " HTTP/1.1\r\nHost: localhost\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
         "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n");
    auto r = read_response(5000, true);
    if (out) *out = r;
    return r && r->status == 101 &&
           r->header("sec-websocket-accept") == "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=";
  }
  bool ws_send(uint8_t opcode, std::string_view payload, bool fin = true) {
    std::string f;
    f.push_back(static_cast<char>((fin ? 0x80 : 0) | opcode));
    const size_t n = payload.size();
    if (n < 126) {
      f.push_back(static_cast<char>(0x80 | n));
    } else if (n < 65536) {
      f.push_back(static_cast<char>(0x80 | 126));
      f.push_back(static_cast<char>(n >> 8));
      f.push_back(static_cast<char>(n & 0xFF));
    } else {
      f.push_back(static_cast<char>(0x80 | 127));
      for (int i = 7; i >= 0; --i) f.push_back(static_cast<char>((n >> (8 * i)) & 0xFF));
    }
    const uint8_t mask[4] = {0x12, 0x34, 0x56, 0x78};
    for (uint8_t m : mask) f.push_back(static_cast<char>(m));
    for (size_t i = 0; i < n; ++i) f.push_back(static_cast<char>(payload[i] ^ mask[i % 4]));
    return send(f);
  }
  struct Frame {
    uint8_t opcode = 0;
    std::string payload;
    int close_code() const {
      return payload.size() >= 2
                 ? (static_cast<uint8_t>(payload[0]) << 8) | static_cast<uint8_t>(payload[1])
                 : -1;
    }
  };
  // Next data or close frame (pings are skipped).
  std::optional<Frame> ws_read(int timeout_ms = 5000) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      auto left = [&] {
        return static_cast<int>(
            std::max<int64_t>(0, std::chrono::duration_cast<std::chrono::milliseconds>(
                                     deadline - std::chrono::steady_clock::now())
                                     .count()));
      };
      while (buf_.size() < 2)
        if (!fill(left())) return std::nullopt;
      const uint8_t b0 = static_cast<uint8_t>(buf_[0]);
      const uint8_t b1 = static_cast<uint8_t>(buf_[1]);
      size_t len = b1 & 0x7F;
      size_t hdr = 2;
      if (len == 126) hdr = 4;
      if (len == 127) hdr = 10;
      while (buf_.size() < hdr)
        if (!fill(left())) return std::nullopt;
      if (len == 126) len = (static_cast<uint8_t>(buf_[2]) << 8) | static_cast<uint8_t>(buf_[3]);
      if (len == 127) {
        len = 0;
        for (int i = 2; i < 10; ++i) len = (len << 8) | static_cast<uint8_t>(buf_[i]);
      }
      while (buf_.size() < hdr + len)
        if (!fill(left())) return std::nullopt;
      Frame fr;
      fr.opcode = b0 & 0x0F;
      fr.payload = buf_.substr(hdr, len);
      buf_.erase(0, hdr + len);
      if (fr.opcode == 0x9 || fr.opcode == 0xA) continue;  // ping / pong
      return fr;
    }
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
  bool eof_ = false;
  std::string buf_;
};

std::string get(const std::string& target, const std::string& extra = {}) {
  return "GET " + target + " HTTP/1.1\r\nHost: localhost\r\n" + extra + "\r\n";
}
std::string post(const std::string& target, const std::string& body,
                 const std::string& extra = {}) {
  return "POST " + target + " HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n" +
         "Content-Length: " + std::to_string(body.size()) + "\r\n" + extra + "\r\n" + body;
}

// ---- fake node -------------------------------------------------------------------------------

class FakeHttp : public transport::HttpHandler {
 public:
  ~FakeHttp() override { join(); }
  void join() {
    std::vector<std::thread> ts;
    {
      std::lock_guard<std::mutex> lock(mu_);
      ts.swap(threads_);
    }
    for (auto& t : ts) t.join();
  }
  void handle(HttpRequest req, Respond respond) override {
    ++calls;
    {
      std::lock_guard<std::mutex> lock(mu_);
      last_ = req;
    }
    if (req.path == "/delay") {
      const int ms = std::atoi(std::string(req.query_value("ms")).c_str());
      std::lock_guard<std::mutex> lock(mu_);
      threads_.emplace_back([ms, respond, path = req.path, q = std::string(req.query_value("n"))] {
        std::this_thread::sleep_for(std::chrono::milliseconds(ms));
        HttpResponse r;
        r.body = R"({"delayed":true,"n":")" + q + "\"}";
        respond(r);
      });
      return;
    }
    if (req.path == "/drop") return;  // never answers: the transport must answer 500
    if (req.path == "/auth") {        // as the node answers a request with a valid credential
      HttpResponse r;
      r.body = "{}";
      r.authenticated = true;
      respond(r);
      return;
    }
    if (req.path == "/throw") throw std::runtime_error("handler failed");
    if (req.path == "/headers") {
      HttpResponse r;
      r.content_type = "text/plain";
      r.body = "hi";
      r.headers = {{"X-Good", "yes"},         {"X-Bad", "a\r\nInjected: 1"},
                   {"Content-Length", "999"}, {"Bad Name", "x"},
                   {"Connection", "upgrade"}, {"Cache-Control", "max-age=5"}};
      respond(r);
      return;
    }
    if (req.path == "/status") {
      HttpResponse r;
      r.status = std::atoi(std::string(req.query_value("s")).c_str());
      r.body = "{}";
      respond(r);
      return;
    }
    json::Object q;
    json::Array qa;
    for (auto& [k, v] : req.query) qa.push_back(json::Array{json::Value(k), json::Value(v)});
    json::Object o{{"method", req.method}, {"path", req.path},
                   {"target", req.target}, {"query", qa},
                   {"body", req.body},     {"remote", req.remote_addr},
                   {"tls", req.tls},       {"x_test", std::string(req.header("x-test"))}};
    HttpResponse r;
    r.body = json::dump(json::Value(std::move(o)));
    respond(std::move(r));
  }
  // Over the connection limit only "/stop" (and the "/ws" upgrade) is served.
  bool serve_on_reserve(const HttpRequest& req) override {
    return req.path == "/stop" || req.path == "/ws";
  }
  HttpRequest last() {
    std::lock_guard<std::mutex> lock(mu_);
    return last_;
  }
  std::atomic<int> calls{0};

 private:
  std::mutex mu_;
  HttpRequest last_;
  std::vector<std::thread> threads_;
};

struct WsEvents {
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::string> texts;
  int binaries = 0;
  int closed = 0;
  int opened = 0;
  bool flood_done = false;
  int flood_sent = 0;
  bool flood_last_result = true;
  template <class Pred>
  bool wait(Pred pred, int ms = 5000) {
    std::unique_lock<std::mutex> lock(mu);
    return cv.wait_for(lock, std::chrono::milliseconds(ms), pred);
  }
};

class FakeReceiver : public transport::StreamReceiver {
 public:
  FakeReceiver(std::shared_ptr<transport::StreamSink> sink, WsEvents& ev)
      : sink_(std::move(sink)), ev_(ev) {}
  ~FakeReceiver() override {
    if (flood_.joinable()) flood_.join();
  }
  void on_text(std::string text) override {
    {
      std::lock_guard<std::mutex> lock(ev_.mu);
      ev_.texts.push_back(text);
    }
    ev_.cv.notify_all();
    if (text == "close") {
      sink_->close(4001, "bye");
    } else if (text == "flood") {
      auto sink = sink_;
      WsEvents* ev = &ev_;
      flood_ = std::thread([sink, ev] {
        const std::string frame(32 * 1024, 'x');
        int sent = 0;
        bool ok = true;
        for (int i = 0; i < 100000 && ok; ++i) {
          ok = sink->send_text(frame);
          if (ok) ++sent;
        }
        {
          std::lock_guard<std::mutex> lock(ev->mu);
          ev->flood_done = true;
          ev->flood_sent = sent;
          ev->flood_last_result = ok;
        }
        ev->cv.notify_all();
      });
    } else {
      sink_->send_text("echo:" + text);
    }
  }
  void on_binary() override {
    {
      std::lock_guard<std::mutex> lock(ev_.mu);
      ++ev_.binaries;
    }
    ev_.cv.notify_all();
    sink_->close(1003, "binary frames are not supported");
  }
  void on_closed() override {
    {
      std::lock_guard<std::mutex> lock(ev_.mu);
      ++ev_.closed;
    }
    ev_.cv.notify_all();
  }

 private:
  std::shared_ptr<transport::StreamSink> sink_;
  WsEvents& ev_;
  std::thread flood_;
};

class FakeStreams : public transport::StreamHandler {
 public:
  std::unique_ptr<transport::StreamReceiver> open(const HttpRequest& upgrade,
                                                  std::shared_ptr<transport::StreamSink> sink,
                                                  HttpResponse& refusal) override {
    if (upgrade.path == "/refuse") {
      refusal.status = 401;
      refusal.body = R"({"refused":true})";
      return nullptr;
    }
    if (upgrade.path == "/greet") sink->send_text("welcome");
    {
      std::lock_guard<std::mutex> lock(ev.mu);
      ++ev.opened;
    }
    return std::make_unique<FakeReceiver>(std::move(sink), ev);
  }
  WsEvents ev;
};

// ---- fixture ---------------------------------------------------------------------------------

class HttpServerTest : public ::testing::Test {
 protected:
  // RCAN_TEST_LOG=debug shows the server's log lines.
  static void SetUpTestSuite() {
    const char* lvl = std::getenv("RCAN_TEST_LOG");
    rcan::set_log_level(lvl ? rcan::parse_log_level(lvl).value_or(rcan::LogLevel::kError)
                            : rcan::LogLevel::kError);
  }
  void start(ServerOptions opt = {}) {
    opt.port = 0;
    server_ = std::make_unique<HttpServer>(opt, http_, streams_);
    auto port = server_->start();
    ASSERT_TRUE(port.ok()) << port.error().message;
    port_ = *port;
  }
  void TearDown() override {
    if (server_) server_->stop(500);
  }
  FakeHttp http_;
  FakeStreams streams_;
  std::unique_ptr<HttpServer> server_;
  uint16_t port_ = 0;
};

// ---- HTTP ------------------------------------------------------------------------------------

TEST_F(HttpServerTest, KeepAliveServesSeveralRequestsOnOneConnection) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.connected());
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(c.send(post("/echo?i=" + std::to_string(i), R"({"a":1})", "X-Test: Yes\r\n")));
    auto r = c.read_response();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
    EXPECT_EQ(r->header("connection"), "keep-alive");
    EXPECT_EQ(r->header("content-type"), "application/json");
    EXPECT_EQ(r->header("x-content-type-options"), "nosniff");
    EXPECT_EQ(r->header("cache-control"), "no-store");
    EXPECT_EQ(r->header("server"), "rcand");
    EXPECT_FALSE(r->header("date").empty());
    auto v = r->json();
    EXPECT_EQ(v.get("body")->as_string(), R"({"a":1})");
    EXPECT_EQ(v.get("method")->as_string(), "POST");
    EXPECT_EQ(v.get("x_test")->as_string(), "Yes");
    EXPECT_EQ(v.get("path")->as_string(), "/echo");
    EXPECT_EQ(v.get("remote")->as_string().rfind("127.0.0.1:", 0), 0u);
  }
  EXPECT_EQ(http_.calls.load(), 3);
  EXPECT_EQ(server_->stats().connections_total, 1u);
  EXPECT_EQ(server_->stats().requests_total, 3u);
}

TEST_F(HttpServerTest, ResponsePostedFromAnotherThreadLater) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(get("/delay?ms=200&n=1")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->body, R"({"delayed":true,"n":"1"})");
  ASSERT_TRUE(c.send(get("/echo")));  // the connection is still usable
  auto r2 = c.read_response();
  ASSERT_TRUE(r2);
  EXPECT_EQ(r2->status, 200);
}

TEST_F(HttpServerTest, PipelinedRequestsAreAnsweredInOrder) {
  start();
  Client c(port_);
  ASSERT_TRUE(
      c.send(get("/delay?ms=150&n=first") + get("/echo?n=second") + get("/delay?ms=10&n=third")));
  auto r1 = c.read_response();
  auto r2 = c.read_response();
  auto r3 = c.read_response();
  ASSERT_TRUE(r1 && r2 && r3);
  EXPECT_EQ(r1->body, R"({"delayed":true,"n":"first"})");
  EXPECT_NE(r2->body.find("second"), std::string::npos);
  EXPECT_EQ(r3->body, R"({"delayed":true,"n":"third"})");
}

TEST_F(HttpServerTest, ContentLengthOverLimitIs413BeforeTheBodyIsSent) {
  ServerOptions o;
  o.max_body_bytes = 1024;
  start(o);
  Client c(port_);
  // Headers only: the answer must come without the server waiting for the 10 MB body.
  ASSERT_TRUE(c.send("POST /echo HTTP/1.1\r\nHost: x\r\nContent-Length: 10000000\r\n\r\n"));
  auto r = c.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 413);
  EXPECT_EQ(r->error_code(), "BODY_TOO_LARGE");
  EXPECT_EQ(r->header("connection"), "close");
  EXPECT_TRUE(c.wait_closed(3000));
  EXPECT_EQ(http_.calls.load(), 0);
  EXPECT_EQ(server_->stats().rejected_limits, 1u);
}

// A client that writes its whole body before it reads (Python's http.client does) gets the
// 413, not a broken pipe: the server discards what still arrives before it closes.
TEST_F(HttpServerTest, AClientThatWritesItsWholeOversizeBodyFirstReadsThe413) {
  ServerOptions o;
  o.max_body_bytes = 1024;
  start(o);
  Client c(port_);
  const size_t body = 20 * 1024 * 1024;
  ASSERT_TRUE(c.send("POST /echo HTTP/1.1\r\nHost: x\r\nContent-Length: " + std::to_string(body) +
                     "\r\n\r\n"));
  const std::string chunk(1024 * 1024, 'x');
  for (size_t sent = 0; sent < body; sent += chunk.size())
    ASSERT_TRUE(c.send(chunk)) << "the server closed after " << sent << " bytes of body";
  auto r = c.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 413);
  EXPECT_EQ(r->error_code(), "BODY_TOO_LARGE");
  EXPECT_TRUE(c.wait_closed(3000));
  EXPECT_EQ(http_.calls.load(), 0);
}

TEST_F(HttpServerTest, BodyAtTheLimitIsAccepted) {
  ServerOptions o;
  o.max_body_bytes = 1024;
  start(o);
  Client c(port_);
  ASSERT_TRUE(c.send(post("/echo", std::string(1024, 'a'))));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
}

TEST_F(HttpServerTest, ChunkedBodyIsReassembledAndLimited) {
  ServerOptions o;
  o.max_body_bytes = 1024;
  start(o);
  {
    Client c(port_);
    ASSERT_TRUE(
        c.send("POST /echo HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n"
               "5\r\nhello\r\n6\r\n world\r\n0\r\n\r\n"));
    auto r = c.read_response();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
    EXPECT_EQ(r->json().get("body")->as_string(), "hello world");
  }
  {
    Client c(port_);
    std::string req = "POST /echo HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n";
    for (int i = 0; i < 5; ++i) req += "200\r\n" + std::string(512, 'z') + "\r\n";
    req += "0\r\n\r\n";
    ASSERT_TRUE(c.send(req));
    auto r = c.read_response();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 413);
    EXPECT_EQ(r->error_code(), "BODY_TOO_LARGE");
  }
  EXPECT_EQ(http_.calls.load(), 1);
}

TEST_F(HttpServerTest, OversizeHeadersAre431WithTheErrorBody) {
  ServerOptions o;
  o.max_header_bytes = 2048;
  start(o);
  Client c(port_);
  ASSERT_TRUE(c.send(get("/echo", "X-Big: " + std::string(4096, 'h') + "\r\n")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 431);
  EXPECT_EQ(r->error_code(), "SCHEMA_VALIDATION_FAILED");
  EXPECT_EQ(r->error_reason(), "headers_too_large");
  auto v = r->json();
  EXPECT_EQ(v.get("payload")->get("error")->as_string(), "request headers too large");
  EXPECT_TRUE(c.wait_closed(3000));
  EXPECT_EQ(http_.calls.load(), 0);
}

TEST_F(HttpServerTest, MalformedRequestsAre400WithTheErrorBody) {
  start();
  const std::vector<std::string> bad = {
      "GARBAGE\r\n\r\n",
      "GET /echo HTTP/9.9\r\nHost: x\r\n\r\n",
      "GET /echo HTTP/1.1\r\nBad Header\r\n\r\n",
      "POST /echo HTTP/1.1\r\nContent-Length: abc\r\n\r\n",
      "POST /echo HTTP/1.1\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\nab",
      "POST /echo HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
      "GET echo HTTP/1.1\r\nHost: x\r\n\r\n",
      "GET /echo%zz HTTP/1.1\r\nHost: x\r\n\r\n",
      "GET /echo?x=%4 HTTP/1.1\r\nHost: x\r\n\r\n",
      "GET /a%00b HTTP/1.1\r\nHost: x\r\n\r\n",
  };
  for (const auto& b : bad) {
    Client c(port_);
    ASSERT_TRUE(c.send(b));
    auto r = c.read_response();
    ASSERT_TRUE(r) << b;
    EXPECT_EQ(r->status, 400) << b;
    EXPECT_EQ(r->error_code(), "MALFORMED_JSON") << b;
    EXPECT_TRUE(c.wait_closed(3000)) << b;
  }
  EXPECT_EQ(http_.calls.load(), 0);
  EXPECT_EQ(server_->stats().bad_requests, bad.size());
}

TEST_F(HttpServerTest, PathAndQueryArePercentDecodedAndHeaderNamesLowerCased) {
  start();
  Client c(port_);
  ASSERT_TRUE(
      c.send(get("/a%20b/c%2Fd%C3%A9?x=1%202&y=%C3%A9&flag&z=a+b&&=v", "X-TEST: Mixed\r\n")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  const HttpRequest req = http_.last();
  EXPECT_EQ(req.path, "/a b/c/d\xC3\xA9");
  EXPECT_EQ(req.target, "/a%20b/c%2Fd%C3%A9?x=1%202&y=%C3%A9&flag&z=a+b&&=v");
  ASSERT_EQ(req.query.size(), 5u);
  EXPECT_EQ(req.query[0], (std::pair<std::string, std::string>("x", "1 2")));
  EXPECT_EQ(req.query[1], (std::pair<std::string, std::string>("y", "\xC3\xA9")));
  EXPECT_EQ(req.query[2], (std::pair<std::string, std::string>("flag", "")));
  EXPECT_EQ(req.query[3], (std::pair<std::string, std::string>("z", "a b")));
  EXPECT_EQ(req.query[4], (std::pair<std::string, std::string>("", "v")));
  EXPECT_EQ(req.header("x-test"), "Mixed");
  EXPECT_EQ(req.header("host"), "localhost");
  EXPECT_FALSE(req.tls);
}

TEST_F(HttpServerTest, AbsoluteFormTargetIsReducedToThePath) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(get("http://localhost:8080/abs/path?q=1")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(http_.last().path, "/abs/path");
  EXPECT_EQ(http_.last().query_value("q"), "1");
}

TEST_F(HttpServerTest, HeadAnswersHeadersWithoutBody) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send("HEAD /echo HTTP/1.1\r\nHost: x\r\n\r\n"));
  auto r = c.read_response(5000, /*head=*/true);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_GT(std::atoi(r->header("content-length").c_str()), 0);
  // No body bytes follow: the next response starts right away.
  ASSERT_TRUE(c.send(get("/echo?after=head")));
  auto r2 = c.read_response();
  ASSERT_TRUE(r2);
  EXPECT_EQ(r2->status, 200);
  EXPECT_NE(r2->body.find("after"), std::string::npos);
}

TEST_F(HttpServerTest, Http10WithoutKeepAliveIsClosedAfterTheAnswer) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send("GET /echo HTTP/1.0\r\n\r\n"));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->header("connection"), "close");
  EXPECT_TRUE(c.wait_closed(3000));
}

TEST_F(HttpServerTest, ConnectionCloseRequestIsHonoured) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(get("/echo", "Connection: close\r\n")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->header("connection"), "close");
  EXPECT_TRUE(c.wait_closed(3000));
}

TEST_F(HttpServerTest, ExpectContinueGets100ThenTheAnswer) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(
      "POST /echo HTTP/1.1\r\nHost: x\r\nContent-Length: 4\r\nExpect: 100-continue\r\n\r\n"));
  auto cont = c.read_response();
  ASSERT_TRUE(cont);
  EXPECT_EQ(cont->status, 100);
  ASSERT_TRUE(c.send("abcd"));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->json().get("body")->as_string(), "abcd");
}

TEST_F(HttpServerTest, SlowLorisHeadersAreCutOffWith408) {
  ServerOptions o;
  o.read_timeout_ms = 300;
  start(o);
  Client c(port_);
  const std::string req = get("/echo", "X-Slow: " + std::string(200, 's') + "\r\n");
  bool cut = false;
  // One byte every 20 ms would take over 4 s; the server must give up long before.
  for (size_t i = 0; i < req.size(); ++i) {
    if (!c.send(std::string_view(&req[i], 1))) {
      cut = true;
      break;
    }
    pollfd p{c.fd(), POLLIN, 0};
    if (::poll(&p, 1, 20) > 0) {
      cut = true;
      break;
    }
  }
  ASSERT_TRUE(cut);
  auto r = c.read_response(2000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 408);
  EXPECT_EQ(r->error_reason(), "read_timeout");
  EXPECT_TRUE(c.wait_closed(3000));
  EXPECT_EQ(http_.calls.load(), 0);
}

TEST_F(HttpServerTest, SlowBodyIsCutOffWith408) {
  ServerOptions o;
  o.read_timeout_ms = 300;
  start(o);
  Client c(port_);
  ASSERT_TRUE(c.send("POST /echo HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\nabc"));
  auto r = c.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 408);
  EXPECT_TRUE(c.wait_closed(3000));
}

TEST_F(HttpServerTest, SilentConnectionIsClosedAfterTheReadTimeout) {
  ServerOptions o;
  o.read_timeout_ms = 200;
  start(o);
  Client c(port_);
  EXPECT_TRUE(c.wait_closed(3000));
}

TEST_F(HttpServerTest, IdleKeepAliveConnectionIsClosed) {
  ServerOptions o;
  o.idle_timeout_ms = 200;
  start(o);
  Client c(port_);
  ASSERT_TRUE(c.send(get("/echo")));
  ASSERT_TRUE(c.read_response());
  EXPECT_TRUE(c.wait_closed(3000));
}

TEST_F(HttpServerTest, ConnectionsOverTheLimitGet503AndAreClosed) {
  ServerOptions o;
  o.max_connections = 2;
  o.reserved_connections = 0;  // no reserve: the third connection is refused at once
  start(o);
  // Authenticated: never evicted for a new connection.
  auto a = std::make_unique<Client>(port_);
  Client b(port_);
  ASSERT_TRUE(a->send(get("/auth")));
  ASSERT_TRUE(a->read_response());
  ASSERT_TRUE(b.send(get("/auth")));
  ASSERT_TRUE(b.read_response());
  Client extra(port_);
  auto r = extra.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_EQ(r->error_code(), "RATE_LIMITED");
  EXPECT_EQ(r->error_reason(), "too_many_connections");
  EXPECT_TRUE(extra.wait_closed(3000));
  EXPECT_GE(server_->stats().rejected_connections, 1u);
  // Closing one frees a slot.
  a.reset();
  bool served = false;
  for (int i = 0; i < 50 && !served; ++i) {
    Client again(port_);
    again.send(get("/echo"));
    auto r2 = again.read_response(2000);
    served = r2 && r2->status == 200;
    if (!served) std::this_thread::sleep_for(20ms);
  }
  EXPECT_TRUE(served);
}

// Finding R6: one address holds at most max_connections_per_address; others are still served.
TEST_F(HttpServerTest, OneAddressGetsMaxConnectionsPerAddressAndNoMore) {
  ServerOptions o;
  o.max_connections_per_address = 3;
  o.reserved_connections = 0;  // no reserve: the fourth connection is refused at once
  start(o);
  std::vector<std::unique_ptr<Client>> held;
  for (int i = 0; i < 3; ++i) {  // authenticated: never evicted for a new connection
    held.push_back(std::make_unique<Client>(port_, 0, "127.0.0.2"));
    ASSERT_TRUE(held.back()->send(get("/auth")));
    ASSERT_TRUE(held.back()->read_response());
  }
  Client fourth(port_, 0, "127.0.0.2");
  auto r = fourth.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_EQ(r->error_code(), "RATE_LIMITED");
  EXPECT_EQ(r->error_reason(), "too_many_connections_from_address");
  EXPECT_TRUE(fourth.wait_closed(3000));
  EXPECT_EQ(server_->stats().rejected_per_address, 1u);
  Client other(port_, 0, "127.0.0.3");  // another address is served
  ASSERT_TRUE(other.send(get("/echo")));
  auto ok = other.read_response();
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 200);
  held.pop_back();  // a closed connection frees the address's slot
  bool served = false;
  for (int i = 0; i < 50 && !served; ++i) {
    Client again(port_, 0, "127.0.0.2");
    again.send(get("/echo"));
    auto r2 = again.read_response(2000);
    served = r2 && r2->status == 200;
    if (!served) std::this_thread::sleep_for(20ms);
  }
  EXPECT_TRUE(served);
}

// Finding R6: over max_connections the reserve serves a stop, and nothing else.
TEST_F(HttpServerTest, TheReserveServesOnlyAStopOverTheConnectionLimit) {
  ServerOptions o;
  o.max_connections = 2;
  o.reserved_connections = 8;
  start(o);
  Client a(port_, 0, "127.0.0.2"), b(port_, 0, "127.0.0.3");
  for (Client* c : {&a, &b}) {
    ASSERT_TRUE(c->send(get("/auth")));
    ASSERT_TRUE(c->read_response());
  }
  Client other(port_);  // from the reserve: anything but a stop is 503 and closed
  ASSERT_TRUE(other.send(get("/echo")));
  auto r = other.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_EQ(r->error_reason(), "reserve_for_stop_only");
  EXPECT_TRUE(other.wait_closed(3000));
  Client stop(port_);
  ASSERT_TRUE(stop.send(post("/stop", "{}")));
  auto s = stop.read_response(3000);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->status, 200);
  EXPECT_EQ(s->header("connection"), "close");  // one request per reserve connection
  EXPECT_TRUE(http_.last().reserve);
  EXPECT_TRUE(stop.wait_closed(3000));
  EXPECT_EQ(server_->stats().reserve_refused, 1u);
  EXPECT_GE(server_->stats().reserve_connections, 2u);
  // One address holds at most two reserve connections at once.
  Client r1(port_, 0, "127.0.0.4"), r2(port_, 0, "127.0.0.4");
  std::this_thread::sleep_for(100ms);  // both accepted (from the reserve) before the third
  Client r3(port_, 0, "127.0.0.4");
  auto full = r3.read_response(3000);
  ASSERT_TRUE(full);
  EXPECT_EQ(full->error_reason(), "too_many_connections");
}

// Finding R6: the long keep-alive only after an answer that said "authenticated".
TEST_F(HttpServerTest, UnauthenticatedKeepAliveIsShortAuthenticatedKeepsTheLongOne) {
  ServerOptions o;
  o.idle_timeout_ms = 60000;
  o.unauthenticated_idle_timeout_ms = 300;
  start(o);
  Client anon(port_), authed(port_);
  ASSERT_TRUE(anon.send(get("/echo")));
  ASSERT_TRUE(anon.read_response());
  ASSERT_TRUE(authed.send(get("/auth")));
  ASSERT_TRUE(authed.read_response());
  ASSERT_TRUE(authed.send(get("/echo")));  // later unauthenticated requests keep it long
  ASSERT_TRUE(authed.read_response());
  EXPECT_TRUE(anon.wait_closed(3000));
  std::this_thread::sleep_for(1000ms);
  ASSERT_TRUE(authed.send(get("/echo")));
  auto r = authed.read_response(2000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
}

// Finding F14: over the per-address limit a new connection closes the oldest connection of that
// address that never authenticated and waits for a request, and takes its slot; authenticated
// ones and ones in the middle of a request are never closed for it.
TEST_F(HttpServerTest, OverThePerAddressLimitTheOldestUnauthenticatedIdleConnectionMakesRoom) {
  ServerOptions o;
  o.max_connections_per_address = 4;
  start(o);
  Client anon1(port_, 0, "127.0.0.2"), authed(port_, 0, "127.0.0.2");
  ASSERT_TRUE(anon1.send(get("/echo")));  // answered, not authenticated: idle and evictable
  ASSERT_TRUE(anon1.read_response());
  ASSERT_TRUE(authed.send(get("/auth")));
  ASSERT_TRUE(authed.read_response());
  Client silent(port_, 0, "127.0.0.2");   // never sent a byte: evictable too, but newer
  Client partial(port_, 0, "127.0.0.2");  // a request under way: not evictable
  ASSERT_TRUE(partial.send("GET /echo HTTP/1.1\r\nHost: x\r\n"));
  std::this_thread::sleep_for(100ms);   // the four accepted, in this order
  Client other(port_, 0, "127.0.0.3");  // another address has its own slots
  ASSERT_TRUE(other.send(get("/echo")));
  ASSERT_TRUE(other.read_response());
  Client fifth(port_, 0, "127.0.0.2");
  ASSERT_TRUE(fifth.send(get("/echo")));
  auto r = fifth.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_TRUE(anon1.wait_closed(3000));  // the oldest unauthenticated one
  Client sixth(port_, 0, "127.0.0.2");
  ASSERT_TRUE(sixth.send(get("/echo")));
  auto r6 = sixth.read_response(3000);
  ASSERT_TRUE(r6);
  EXPECT_EQ(r6->status, 200);
  EXPECT_TRUE(silent.wait_closed(3000));  // the next oldest, never the authenticated one
  ASSERT_TRUE(authed.send(get("/echo")));
  auto ra = authed.read_response(3000);
  ASSERT_TRUE(ra);
  EXPECT_EQ(ra->status, 200);
  ASSERT_TRUE(partial.send("\r\n"));  // the request under way completes
  auto rp = partial.read_response(3000);
  ASSERT_TRUE(rp);
  EXPECT_EQ(rp->status, 200);
  ASSERT_TRUE(other.send(get("/echo")));
  EXPECT_TRUE(other.read_response(3000));
  EXPECT_EQ(server_->stats().evicted_idle, 2u);
  EXPECT_EQ(server_->stats().rejected_per_address, 0u);
}

// Finding F14: over max_connections the oldest unauthenticated idle connection of any address
// makes room; with only authenticated ones, the reserve is used.
TEST_F(HttpServerTest, OverTheConnectionLimitTheOldestUnauthenticatedIdleConnectionMakesRoom) {
  ServerOptions o;
  o.max_connections = 2;
  o.reserved_connections = 4;
  start(o);
  Client anon(port_, 0, "127.0.0.2"), authed(port_, 0, "127.0.0.3");
  ASSERT_TRUE(anon.send(get("/echo")));
  ASSERT_TRUE(anon.read_response());
  ASSERT_TRUE(authed.send(get("/auth")));
  ASSERT_TRUE(authed.read_response());
  // anon's answer reached it before its connection went back to waiting for a request, the
  // moment it becomes evictable: wait for that (on a loaded machine the next client was faster).
  for (int i = 0; i < 300 && server_->stats().evictable_now == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_EQ(server_->stats().evictable_now, 1u);
  Client next(port_, 0, "127.0.0.4");
  ASSERT_TRUE(next.send(get("/auth")));
  auto r = next.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_FALSE(http_.last().reserve);  // an ordinary slot: anon's
  EXPECT_TRUE(anon.wait_closed(3000));
  Client over(port_, 0, "127.0.0.2");  // both authenticated now: the reserve, for a stop only
  ASSERT_TRUE(over.send(get("/echo")));
  auto refused = over.read_response(3000);
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 503);
  EXPECT_EQ(refused->error_reason(), "reserve_for_stop_only");
  EXPECT_EQ(server_->stats().evicted_idle, 1u);
}

// Finding F14: an address whose every connection is authenticated or busy still gets a stop
// through, from the reserve, over the per-address limit — and nothing else.
TEST_F(HttpServerTest, AStopIsServedFromTheReserveOverThePerAddressLimit) {
  ServerOptions o;
  o.max_connections_per_address = 2;
  start(o);
  Client a(port_, 0, "127.0.0.2"), b(port_, 0, "127.0.0.2");
  for (Client* c : {&a, &b}) {
    ASSERT_TRUE(c->send(get("/auth")));
    ASSERT_TRUE(c->read_response());
  }
  Client status(port_, 0, "127.0.0.2");
  ASSERT_TRUE(status.send(get("/echo")));
  auto refused = status.read_response(3000);
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 503);
  EXPECT_EQ(refused->error_reason(), "reserve_for_stop_only");
  EXPECT_TRUE(status.wait_closed(3000));
  Client stop(port_, 0, "127.0.0.2");
  ASSERT_TRUE(stop.send(post("/stop", "{}")));
  auto s = stop.read_response(3000);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->status, 200);
  EXPECT_EQ(s->header("connection"), "close");
  EXPECT_TRUE(http_.last().reserve);
  EXPECT_EQ(server_->stats().reserve_connections, 2u);
  EXPECT_EQ(server_->stats().evicted_idle, 0u);
}

// Finding F14: a client re-opening idle connections from the same address as fast as they are
// closed cannot keep a stop from that address out, nor evict an authenticated connection.
TEST_F(HttpServerTest, AStopGetsThroughWhileTheSameAddressReopensIdleConnections) {
  ServerOptions o;
  o.max_connections_per_address = 16;
  start(o);
  Client authed(port_, 0, "127.0.0.2");
  ASSERT_TRUE(authed.send(get("/auth")));
  ASSERT_TRUE(authed.read_response());
  std::atomic<bool> done{false};
  std::atomic<int> opened{0};
  std::thread flood([&] {
    std::deque<std::unique_ptr<Client>> held;
    while (!done.load()) {
      held.push_back(std::make_unique<Client>(port_, 0, "127.0.0.2"));
      if (held.back()->connected()) ++opened;
      if (held.size() > 64) held.pop_front();  // closed by the server long since
    }
  });
  while (opened.load() < 200) std::this_thread::sleep_for(1ms);
  int served = 0;
  for (int i = 0; i < 20; ++i) {
    Client stop(port_, 0, "127.0.0.2");
    ASSERT_TRUE(stop.send(post("/stop", "{}")));
    auto s = stop.read_response(3000);
    if (s && s->status == 200) ++served;
  }
  const int opened_during = opened.load();
  done = true;
  flood.join();
  EXPECT_EQ(served, 20);
  EXPECT_GT(opened_during, 200);
  // The flood forced evictions (how many depends on how fast the server accepts: a connection
  // the flood closed again before its accept needs none).
  EXPECT_GT(server_->stats().evicted_idle, 0u);
  ASSERT_TRUE(authed.send(get("/echo")));  // never evicted
  auto ra = authed.read_response(3000);
  ASSERT_TRUE(ra);
  EXPECT_EQ(ra->status, 200);
}

// Finding F9: a Transfer-Encoding other than exactly "chunked" (RFC 9112 §6.1, §6.3), one in an
// HTTP/1.0 request or with a Content-Length, and obs-fold (§5.2) are 400 and the connection is
// closed: the body is never parsed as a second request. Beast alone took "xchunked" and
// "chunked, identity" as no body and answered the smuggled request.
TEST_F(HttpServerTest, FramingOtherThanTheRfcsIs400AndCloseAndNothingIsSmuggled) {
  start();
  const std::string smuggled = get("/smuggled");
  struct Case {
    std::string head;
    std::string reason;
  };
  const std::vector<Case> cases = {
      {"Transfer-Encoding: xchunked\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: chunked, identity\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: identity\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: gzip, chunked\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: identity\r\nTransfer-Encoding: chunked\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: xchunked\r\nContent-Length: 0\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: chunked\r\nContent-Length: 0\r\n", "bad_request"},
      {"X-Test: a\r\n b\r\n", "obs_fold"},
      {"X-Test: a\r\n\tb\r\n", "obs_fold"},
  };
  for (const auto& c : cases) {
    Client cl(port_);
    ASSERT_TRUE(cl.send("POST /echo HTTP/1.1\r\nHost: x\r\n" + c.head + "\r\n" + smuggled));
    auto r = cl.read_response(3000);
    ASSERT_TRUE(r) << c.head;
    EXPECT_EQ(r->status, 400) << c.head;
    EXPECT_EQ(r->error_code(), "MALFORMED_JSON") << c.head;
    EXPECT_EQ(r->error_reason(), c.reason) << c.head;
    EXPECT_EQ(r->header("connection"), "close") << c.head;
    EXPECT_TRUE(cl.wait_closed(3000)) << c.head;
    EXPECT_EQ(cl.buffer(), "") << c.head;  // no second answer
  }
  {
    Client cl(port_);
    ASSERT_TRUE(cl.send("POST /echo HTTP/1.0\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n"));
    auto r = cl.read_response(3000);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400);
    EXPECT_EQ(r->error_reason(), "bad_transfer_encoding");
  }
  EXPECT_EQ(http_.calls.load(), 0);
  // Exactly "chunked", in any case and with whitespace around it, is the one coding served.
  Client ok(port_);
  ASSERT_TRUE(
      ok.send("POST /echo HTTP/1.1\r\nHost: x\r\nTransfer-Encoding:  ChUnKeD \r\n\r\n"
              "2\r\nhi\r\n0\r\n\r\n"));
  auto r = ok.read_response(3000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->json().get("body")->as_string(), "hi");
}

TEST_F(HttpServerTest, HandlerThatDropsRespondOrThrowsGets500) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(get("/drop")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 500);
  EXPECT_EQ(r->error_code(), "INTERNAL_ERROR");
  ASSERT_TRUE(c.send(get("/throw")));
  auto r2 = c.read_response();
  ASSERT_TRUE(r2);
  EXPECT_EQ(r2->status, 500);
  ASSERT_TRUE(c.send(get("/status?s=42")));  // not a valid status
  auto r3 = c.read_response();
  ASSERT_TRUE(r3);
  EXPECT_EQ(r3->status, 500);
}

TEST_F(HttpServerTest, HandlerHeadersAreSanitised) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(get("/headers")));
  auto r = c.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->header("x-good"), "yes");
  EXPECT_EQ(r->header("x-bad"), "");
  EXPECT_EQ(r->header("injected"), "");
  EXPECT_EQ(r->header("content-length"), "2");
  EXPECT_EQ(r->header("connection"), "keep-alive");
  EXPECT_EQ(r->header("content-type"), "text/plain");
  EXPECT_EQ(r->body, "hi");
  ASSERT_TRUE(c.send(get("/status?s=204")));
  auto r2 = c.read_response();
  ASSERT_TRUE(r2);
  EXPECT_EQ(r2->status, 204);
  EXPECT_EQ(r2->header("content-length"), "");
  ASSERT_TRUE(c.send(get("/echo")));  // 204 carried no body bytes
  auto r3 = c.read_response();
  ASSERT_TRUE(r3);
  EXPECT_EQ(r3->status, 200);
}

// The transport writes its own bytes (one buffer): status line with its reason phrase, then
// Server and Date, the handler's headers, the transport's; a handler's Cache-Control replaces
// the default.
TEST_F(HttpServerTest, ResponseBytesAreExactlyTheAnswer) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.send(get("/headers")));
  while (c.buffer().find("\r\n\r\nhi") == std::string::npos) ASSERT_TRUE(c.fill(5000));
  const std::string raw = c.buffer();
  c.buffer().clear();
  EXPECT_EQ(raw.rfind("HTTP/1.1 200 OK\r\nServer: rcand\r\nDate: ", 0), 0u) << raw;
  auto count = [&](std::string_view needle) {
    size_t n = 0;
    for (size_t at = raw.find(needle); at != std::string::npos; at = raw.find(needle, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("\r\nCache-Control: "), 1u) << raw;
  EXPECT_EQ(count("\r\nCache-Control: max-age=5\r\n"), 1u) << raw;
  EXPECT_EQ(count("\r\nContent-Length: "), 1u) << raw;
  EXPECT_EQ(count("\r\nContent-Length: 2\r\n"), 1u) << raw;
  EXPECT_EQ(count("\r\nX-Content-Type-Options: nosniff\r\n"), 1u) << raw;
  EXPECT_EQ(count("\r\nConnection: "), 1u) << raw;
  EXPECT_EQ(raw.size() - raw.find("\r\nConnection: keep-alive\r\n\r\nhi"),
            std::string_view("\r\nConnection: keep-alive\r\n\r\nhi").size())
      << raw;
  // The reason phrase follows the status (HEAD is covered by its own test above).
  ASSERT_TRUE(c.send(get("/status?s=404")));
  while (c.buffer().find("\r\n\r\n{}") == std::string::npos) ASSERT_TRUE(c.fill(5000));
  EXPECT_EQ(c.buffer().rfind("HTTP/1.1 404 Not Found\r\n", 0), 0u) << c.buffer();
}

TEST_F(HttpServerTest, GarbageFloodLeavesTheServerServing) {
  start();
  uint32_t seed = 12345;
  for (int i = 0; i < 60; ++i) {
    Client c(port_);
    std::string junk;
    const int n = 1 + static_cast<int>(seed % 3000);
    for (int k = 0; k < n; ++k) {
      seed = seed * 1103515245u + 12345u;
      junk.push_back(static_cast<char>(seed >> 16));
    }
    if (i % 3 == 0) junk = "GET /" + junk;
    if (i % 3 == 1) junk = "POST /echo HTTP/1.1\r\nContent-Length: 5\r\n" + junk;
    c.send(junk);
    auto r = c.read_response(1000);
    if (r) {
      EXPECT_LT(r->status, 500) << i;
    }
  }
  Client ok(port_);
  ASSERT_TRUE(ok.send(get("/echo")));
  auto r = ok.read_response();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
}

// ---- WebSocket -------------------------------------------------------------------------------

TEST_F(HttpServerTest, WebSocketTextFramesBothWaysAndServerClose) {
  start();
  Client c(port_);
  std::optional<Resp> hs;
  ASSERT_TRUE(c.ws_handshake("/ws?token=x", &hs));
  EXPECT_EQ(hs->header("server"), "rcand");
  ASSERT_TRUE(c.ws_send(0x1, R"({"type":"PING"})"));
  auto f = c.ws_read();
  ASSERT_TRUE(f);
  EXPECT_EQ(f->opcode, 0x1);
  EXPECT_EQ(f->payload, R"(echo:{"type":"PING"})");
  // A fragmented message arrives whole.
  ASSERT_TRUE(c.ws_send(0x1, "frag", false));
  ASSERT_TRUE(c.ws_send(0x0, "ment", true));
  auto f2 = c.ws_read();
  ASSERT_TRUE(f2);
  EXPECT_EQ(f2->payload, "echo:fragment");
  EXPECT_EQ(server_->stats().ws_streams_open, 1u);
  ASSERT_TRUE(c.ws_send(0x1, "close"));
  auto cl = c.ws_read();
  ASSERT_TRUE(cl);
  EXPECT_EQ(cl->opcode, 0x8);
  EXPECT_EQ(cl->close_code(), 4001);
  EXPECT_EQ(cl->payload.substr(2), "bye");
  c.ws_send(0x8, cl->payload.substr(0, 2));  // echo the close
  EXPECT_TRUE(c.wait_closed(3000));
  c.close();
  ASSERT_TRUE(streams_.ev.wait([&] { return streams_.ev.closed == 1; }));
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(streams_.ev.closed, 1);
  EXPECT_EQ(http_.calls.load(), 0);
}

// Finding R6: a WebSocket from the reserve opens (the handler admits its path) and is closed
// with 1013 after read_timeout_ms, so it cannot hold a reserve slot.
TEST_F(HttpServerTest, AReserveWebSocketIsClosedAfterTheReadTimeout) {
  ServerOptions o;
  o.max_connections = 1;
  o.read_timeout_ms = 400;
  start(o);
  Client held(port_, 0, "127.0.0.2");
  ASSERT_TRUE(held.send(get("/auth")));
  ASSERT_TRUE(held.read_response());
  Client refused(port_);
  EXPECT_FALSE(refused.ws_handshake("/other"));  // not admitted on the reserve
  Client c(port_);
  ASSERT_TRUE(c.ws_handshake("/ws"));
  ASSERT_TRUE(c.ws_send(0x1, "hello"));
  auto f = c.ws_read();
  ASSERT_TRUE(f);
  EXPECT_EQ(f->payload, "echo:hello");
  const auto t0 = std::chrono::steady_clock::now();
  auto cl = c.ws_read(3000);
  ASSERT_TRUE(cl);
  EXPECT_EQ(cl->opcode, 0x8);
  EXPECT_EQ(cl->close_code(), 1013);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 2s);
}

TEST_F(HttpServerTest, WebSocketFramesQueuedDuringOpenAreDelivered) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.ws_handshake("/greet"));
  auto f = c.ws_read();
  ASSERT_TRUE(f);
  EXPECT_EQ(f->payload, "welcome");
}

TEST_F(HttpServerTest, WebSocketPeerCloseCallsOnClosedOnce) {
  start();
  {
    Client c(port_);
    ASSERT_TRUE(c.ws_handshake("/ws"));
    const std::string payload("\x03\xe8", 2);  // 1000
    ASSERT_TRUE(c.ws_send(0x8, payload));
    auto cl = c.ws_read();
    ASSERT_TRUE(cl);
    EXPECT_EQ(cl->opcode, 0x8);
  }
  {
    Client c(port_);  // and one that just vanishes
    ASSERT_TRUE(c.ws_handshake("/ws"));
  }
  ASSERT_TRUE(streams_.ev.wait([&] { return streams_.ev.closed == 2; }));
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(streams_.ev.closed, 2);
  EXPECT_EQ(server_->stats().ws_streams_open, 0u);
}

TEST_F(HttpServerTest, WebSocketRefusalIsAnsweredWithTheNodesResponse) {
  start();
  Client c(port_);
  std::optional<Resp> hs;
  EXPECT_FALSE(c.ws_handshake("/refuse", &hs));
  ASSERT_TRUE(hs);
  EXPECT_EQ(hs->status, 401);
  Resp full = *hs;  // read_response(head) left the body in the buffer
  EXPECT_TRUE(c.wait_closed(3000));
  EXPECT_EQ(c.buffer(), R"({"refused":true})");
  EXPECT_EQ(streams_.ev.opened, 0);
}

TEST_F(HttpServerTest, MalformedWebSocketUpgradesAreRejected) {
  start();
  {
    Client c(port_);
    ASSERT_TRUE(
        c.send("GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: short\r\nSec-WebSocket-Version: 13\r\n\r\n"));
    auto r = c.read_response();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400);
    EXPECT_EQ(r->error_code(), "MALFORMED_JSON");
  }
  {
    Client c(port_);
    ASSERT_TRUE(
        c.send("GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 8\r\n\r\n"));
    auto r = c.read_response();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 426);
    EXPECT_EQ(r->header("sec-websocket-version"), "13");
  }
  {
    Client c(port_);
    ASSERT_TRUE(
        c.send("POST /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
               "Content-Length: 0\r\n\r\n"));
    auto r = c.read_response();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400);
  }
  EXPECT_EQ(streams_.ev.opened, 0);
}

TEST_F(HttpServerTest, WebSocketBinaryFrameReachesOnBinary) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.ws_handshake("/ws"));
  ASSERT_TRUE(c.ws_send(0x2, std::string("\x00\x01\x02", 3)));
  auto cl = c.ws_read();
  ASSERT_TRUE(cl);
  EXPECT_EQ(cl->opcode, 0x8);
  EXPECT_EQ(cl->close_code(), 1003);
  EXPECT_EQ(streams_.ev.binaries, 1);
}

TEST_F(HttpServerTest, WebSocketOversizeMessageIsClosed1009) {
  ServerOptions o;
  o.ws_max_message_bytes = 1024;
  start(o);
  Client c(port_);
  ASSERT_TRUE(c.ws_handshake("/ws"));
  ASSERT_TRUE(c.ws_send(0x1, std::string(1024, 'a')));  // at the limit: fine
  auto ok = c.ws_read();
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->opcode, 0x1);
  ASSERT_TRUE(c.ws_send(0x1, std::string(1025, 'a')));
  auto cl = c.ws_read();
  ASSERT_TRUE(cl);
  EXPECT_EQ(cl->opcode, 0x8);
  EXPECT_EQ(cl->close_code(), 1009);
  c.ws_send(0x8, cl->payload.substr(0, 2));
  EXPECT_TRUE(c.wait_closed(3000));
  c.close();
  ASSERT_TRUE(streams_.ev.wait([&] { return streams_.ev.closed == 1; }));
  EXPECT_EQ(streams_.ev.texts.size(), 1u);
}

TEST_F(HttpServerTest, WebSocketInvalidUtf8IsClosed1007) {
  start();
  Client c(port_);
  ASSERT_TRUE(c.ws_handshake("/ws"));
  ASSERT_TRUE(c.ws_send(0x1, "\xff\xfe"));
  auto cl = c.ws_read();
  ASSERT_TRUE(cl);
  EXPECT_EQ(cl->opcode, 0x8);
  EXPECT_EQ(cl->close_code(), 1007);
  EXPECT_TRUE(streams_.ev.texts.empty());
}

TEST_F(HttpServerTest, WebSocketSlowReaderHitsTheSendQueueLimit) {
  ServerOptions o;
  o.ws_send_queue_limit = 8;
  o.ws_handshake_timeout_ms = 300;
  start(o);
  Client c(port_, /*rcvbuf=*/4096);
  ASSERT_TRUE(c.ws_handshake("/ws"));
  ASSERT_TRUE(c.ws_send(0x1, "flood"));  // the session floods; this client never reads
  ASSERT_TRUE(streams_.ev.wait([&] { return streams_.ev.flood_done; }, 10000));
  EXPECT_FALSE(streams_.ev.flood_last_result);
  EXPECT_LT(streams_.ev.flood_sent, 100000);
  // The connection is torn down (close frame or, when it cannot get through, the watchdog).
  ASSERT_TRUE(streams_.ev.wait([&] { return streams_.ev.closed == 1; }, 10000));
  EXPECT_GE(server_->stats().rejected_limits, 1u);
}

TEST_F(HttpServerTest, WebSocketDeadPeerIsDetectedByIdleTimeout) {
  ServerOptions o;
  o.idle_timeout_ms = 300;
  start(o);
  Client c(port_);
  ASSERT_TRUE(c.ws_handshake("/ws"));
  // The client answers nothing (not even pings): the server gives up.
  ASSERT_TRUE(streams_.ev.wait([&] { return streams_.ev.closed == 1; }, 5000));
}

// ---- shutdown --------------------------------------------------------------------------------

TEST_F(HttpServerTest, GracefulStopFinishesInFlightRequestsAndRefusesNewOnes) {
  start();
  Client idle(port_);
  ASSERT_TRUE(idle.send(get("/echo")));
  ASSERT_TRUE(idle.read_response());
  Client ws(port_);
  ASSERT_TRUE(ws.ws_handshake("/ws"));
  Client busy(port_);
  ASSERT_TRUE(busy.send(get("/delay?ms=300&n=inflight")));
  std::this_thread::sleep_for(50ms);  // the request is with the handler

  std::thread stopper([&] { server_->stop(3000); });
  // WebSocket: 1001 going away.
  auto cl = ws.ws_read();
  ASSERT_TRUE(cl);
  EXPECT_EQ(cl->opcode, 0x8);
  EXPECT_EQ(cl->close_code(), 1001);
  ws.ws_send(0x8, cl->payload.substr(0, 2));
  // Idle keep-alive connection: closed.
  EXPECT_TRUE(idle.wait_closed(3000));
  // New connections are refused.
  std::this_thread::sleep_for(50ms);
  Client late(port_);
  EXPECT_FALSE(late.connected() && late.send(get("/echo")) && late.read_response(500));
  // The in-flight request completes, with Connection: close.
  auto r = busy.read_response(5000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->body, R"({"delayed":true,"n":"inflight"})");
  EXPECT_EQ(r->header("connection"), "close");
  EXPECT_TRUE(busy.wait_closed(3000));
  stopper.join();
  EXPECT_EQ(streams_.ev.closed, 1);
  EXPECT_EQ(server_->stats().connections_open, 0u);
  server_->stop(0);  // idempotent
}

TEST_F(HttpServerTest, StopClosesRequestsThatOutliveTheDrain) {
  start();
  Client busy(port_);
  ASSERT_TRUE(busy.send(get("/delay?ms=1500")));
  std::this_thread::sleep_for(50ms);
  server_->stop(100);
  EXPECT_TRUE(busy.wait_closed(3000));
  // respond() after the server stopped is harmless.
  http_.join();
}

TEST_F(HttpServerTest, RespondAfterServerDestroyedIsHarmless) {
  start();
  {
    Client busy(port_);
    ASSERT_TRUE(busy.send(get("/delay?ms=300")));
    std::this_thread::sleep_for(50ms);
    server_.reset();  // stop(0) in the destructor
  }
  http_.join();  // the delayed respond() runs against a destroyed server
}

TEST(HttpServerStart, FailsCleanlyOnBadAddressBusyPortOrMissingTlsFiles) {
  rcan::set_log_level(rcan::LogLevel::kError);
  FakeHttp h;
  FakeStreams s;
  {
    ServerOptions o;
    o.bind_address = "not-an-ip";
    o.port = 0;
    HttpServer srv(o, h, s);
    EXPECT_FALSE(srv.start().ok());
  }
  {
    ServerOptions o;
    o.port = 0;
    HttpServer a(o, h, s);
    auto p = a.start();
    ASSERT_TRUE(p.ok());
    o.port = *p;
    HttpServer b(o, h, s);
    EXPECT_FALSE(b.start().ok());
  }
  {
    ServerOptions o;
    o.port = 0;
    o.tls = true;
    o.cert_file = "/nonexistent/cert.pem";
    o.key_file = "/nonexistent/key.pem";
    HttpServer srv(o, h, s);
    auto r = srv.start();
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().field, "cert_file");
  }
}

// ---- TLS -------------------------------------------------------------------------------------

TEST_F(HttpServerTest, TlsServesHttpsAndWss) {
  test::TempDir dir;
  const std::string cert = dir.file("cert.pem");
  const std::string key = dir.file("key.pem");
  auto gen = test::run({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                        "ec_paramgen_curve:prime256v1", "-nodes", "-days", "1", "-subj",
                        "/CN=localhost", "-keyout", key, "-out", cert});
  ASSERT_EQ(gen.exit_code, 0) << gen.err;
  ServerOptions o;
  o.tls = true;
  o.cert_file = cert;
  o.key_file = key;
  start(o);

  SSL_CTX* ctx = SSL_CTX_new(TLS_client_method());
  ASSERT_NE(ctx, nullptr);
  SSL_CTX_set_verify(ctx, SSL_VERIFY_NONE, nullptr);
  auto tls_exchange = [&](const std::string& request, size_t want_substr_count,
                          const std::string& want) {
    Client c(port_);
    SSL* ssl = SSL_new(ctx);
    SSL_set_fd(ssl, c.fd());
    EXPECT_EQ(SSL_connect(ssl), 1);
    EXPECT_EQ(SSL_write(ssl, request.data(), static_cast<int>(request.size())),
              static_cast<int>(request.size()));
    std::string got;
    char buf[4096];
    for (int i = 0; i < 50 && got.find(want) == std::string::npos; ++i) {
      pollfd p{c.fd(), POLLIN, 0};
      if (SSL_pending(ssl) == 0 && ::poll(&p, 1, 100) <= 0) continue;
      const int n = SSL_read(ssl, buf, sizeof buf);
      if (n <= 0) break;
      got.append(buf, static_cast<size_t>(n));
    }
    (void)want_substr_count;
    SSL_shutdown(ssl);
    SSL_free(ssl);
    return got;
  };
  const std::string https =
      tls_exchange(get("/echo?over=tls", "Connection: close\r\n"), 1, "\"tls\":true");
  EXPECT_NE(https.find("HTTP/1.1 200"), std::string::npos) << https;
  EXPECT_NE(https.find("\"tls\":true"), std::string::npos) << https;
  const std::string wss = tls_exchange(
      "GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
      1, "\r\n\r\n");
  EXPECT_NE(wss.find("HTTP/1.1 101"), std::string::npos) << wss;
  SSL_CTX_free(ctx);

  // Plain HTTP on the TLS port is dropped, and the server keeps serving.
  Client plain(port_);
  ASSERT_TRUE(plain.send(get("/echo")));
  EXPECT_TRUE(plain.wait_closed(5000));
  EXPECT_EQ(http_.last().path, "/echo");
}

// ---- log -------------------------------------------------------------------------------------

TEST(NodeLog, WritesOneJsonObjectPerLineAndFiltersByLevel) {
  std::vector<std::string> lines;
  rcan::set_log_sink([&](std::string_view l) { lines.emplace_back(l); });
  rcan::set_log_level(rcan::LogLevel::kInfo);
  rcan::log(rcan::LogLevel::kDebug, "dropped");
  rcan::log(rcan::LogLevel::kWarn, "http.test",
            {{"status", 413}, {"level", "spoof"}, {"why", "a\"b\nc"}});
  rcan::set_log_sink({});
  rcan::set_log_level(rcan::LogLevel::kError);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].find('\n'), std::string::npos);
  auto v = json::parse(lines[0]);
  ASSERT_TRUE(v.ok()) << lines[0];
  EXPECT_EQ(v->get("level")->as_string(), "warn");
  EXPECT_EQ(v->get("event")->as_string(), "http.test");
  EXPECT_EQ(v->get("status")->as_int(), 413);
  EXPECT_EQ(v->get("why")->as_string(), "a\"b\nc");
  EXPECT_EQ(v->get("ts")->as_string().size(), 24u);  // 2025-06-15T12:34:56.789Z
  EXPECT_EQ(rcan::parse_log_level("warning"), rcan::LogLevel::kWarn);
  EXPECT_FALSE(rcan::parse_log_level("loud").has_value());
}

}  // namespace
}  // namespace rcan::transport
