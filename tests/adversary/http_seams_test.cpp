// The HTTP seam every party crosses (docs/THREATS.md): rcand and rcan-registry share one HTTP
// server (src/transport), tried here as an attacker with only a TCP socket would, against the
// real daemons on loopback.
//   F9  request smuggling: a Transfer-Encoding Beast reads as "no body" (xchunked, chunked
//       followed by another coding), one with a Content-Length, obs-fold header lines.
//   F14 a client on the operator's own address (a shared NAT, a proxy, the same laptop) holding
//       every connection that address may open, while the OWNER sends the stop.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <deque>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "configured_node.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {
namespace {

using namespace std::chrono_literals;

// One raw TCP connection to 127.0.0.1:`port`, from `source` (another loopback address) when
// given, else from 127.0.0.1 (bound at connect: a flood of connections does not run out of
// ports to bind).
class RawConn {
 public:
  explicit RawConn(uint16_t port, const char* source = nullptr) {
    const LoopbackSocket s = loopback_socket(port, source);
    fd_ = s.fd;
    connected_ = s.connected;
  }
  ~RawConn() {
    if (fd_ >= 0) ::close(fd_);
  }
  RawConn(const RawConn&) = delete;
  RawConn& operator=(const RawConn&) = delete;
  bool connected() const { return connected_; }

  bool send(const std::string& bytes) {
    return ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) ==
           static_cast<ssize_t>(bytes.size());
  }
  // Everything the server sends until it closes the connection (or the timeout passes).
  std::string read_until_closed(int timeout_ms, bool* closed) {
    std::string out;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    *closed = false;
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return out;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return out;
      char tmp[16384];
      const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
      if (n <= 0) {
        *closed = true;
        return out;
      }
      out.append(tmp, static_cast<size_t>(n));
    }
  }
  // The status of the one answer to `request` (0 when none came: closed or timed out).
  int exchange(const std::string& request, std::string* body = nullptr) {
    if (!send(request)) return 0;
    std::string buf;
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    for (;;) {
      const size_t end = buf.find("\r\n\r\n");
      if (end != std::string::npos) {
        std::string head = buf.substr(0, end);
        for (char& c : head) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        const size_t cl = head.find("content-length:");
        const size_t len = cl == std::string::npos ? 0 : std::stoul(head.substr(cl + 15));
        if (buf.size() >= end + 4 + len) {
          if (body != nullptr) *body = buf.substr(end + 4, len);
          return std::stoi(buf.substr(9, 3));
        }
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return 0;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return 0;
      char tmp[16384];
      const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
      if (n <= 0) return 0;
      buf.append(tmp, static_cast<size_t>(n));
    }
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
};

// How many whole HTTP answers `wire` holds, one after the other (each framed by its
// Content-Length).
int answers_in(std::string_view wire) {
  int n = 0;
  while (wire.rfind("HTTP/1.", 0) == 0) {
    const size_t end = wire.find("\r\n\r\n");
    if (end == std::string_view::npos) break;
    std::string head(wire.substr(0, end));
    for (char& c : head) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    const size_t cl = head.find("content-length:");
    const size_t len = cl == std::string::npos ? 0 : std::stoul(head.substr(cl + 15));
    if (wire.size() < end + 4 + len) break;
    ++n;
    wire.remove_prefix(end + 4 + len);
  }
  return n;
}

std::string post_with(const std::string& head) {
  return "POST /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n" + head + "\r\n";
}

// F9 (LOW). Before the fix, on both daemons: `Transfer-Encoding: xchunked` or `chunked, identity`
// was read as a request without a body, and the body — here a second request — was answered
// (two answers on the wire, the second 200); an obs-fold header line was unfolded and the request
// answered. After: one answer, 400 with the project's error body and `Connection: close`, and
// the connection closed; the smuggled request never reaches the daemon.
TEST(AdversaryHttpFraming, NeitherDaemonAnswersARequestSmuggledInTheBody) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_NE(reg.port(), 0);
  ConfiguredNode node("", 2000, false);
  ASSERT_NE(node.http_port(), 0);
  const std::string smuggled = "GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  struct Variant {
    std::string head;
    std::string reason;
  };
  const std::vector<Variant> variants = {
      {"Transfer-Encoding: xchunked\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: chunked, identity\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: xchunked\r\nContent-Length: 0\r\n", "bad_transfer_encoding"},
      {"Transfer-Encoding: chunked\r\nContent-Length: 0\r\n", "bad_request"},
      {"Content-Length: 0\r\nTransfer-Encoding: chunked\r\n", "bad_transfer_encoding"},
      {"X-Note: folded\r\n onto two lines\r\nContent-Length: 0\r\n", "obs_fold"},
  };
  for (const uint16_t port : {reg.port(), node.http_port()}) {
    const std::string who = port == reg.port() ? "rcan-registry" : "rcand";
    // The control: the same connection answers pipelined requests when they are framed as such.
    {
      RawConn c(port);
      ASSERT_TRUE(c.connected());
      ASSERT_TRUE(c.send(smuggled + smuggled +
                         "GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"));
      bool closed = false;
      EXPECT_EQ(answers_in(c.read_until_closed(5000, &closed)), 3) << who;
    }
    for (const auto& v : variants) {
      RawConn c(port);
      ASSERT_TRUE(c.connected());
      ASSERT_TRUE(c.send(post_with(v.head) + smuggled));
      bool closed = false;
      const std::string wire = c.read_until_closed(5000, &closed);
      EXPECT_TRUE(closed) << who << ": " << v.head;
      EXPECT_EQ(answers_in(wire), 1) << who << ": " << v.head << "\n" << wire;
      EXPECT_EQ(wire.rfind("HTTP/1.1 400 ", 0), 0u) << who << ": " << v.head << "\n" << wire;
      EXPECT_NE(wire.find("Connection: close\r\n"), std::string::npos) << who << ": " << wire;
      const size_t body_at = wire.find("\r\n\r\n");
      ASSERT_NE(body_at, std::string::npos) << who << ": " << wire;
      const json::Value body = parse_json(wire.substr(body_at + 4));
      const json::Value* payload = body.get("payload");
      ASSERT_NE(payload, nullptr) << who << ": " << wire;
      EXPECT_EQ(json::string_field(*payload, "error_code"), "MALFORMED_JSON") << who;
      EXPECT_EQ(json::string_field(*payload, "reason"), v.reason) << who << ": " << v.head;
    }
  }
}

// `estop_active` of a GET /api/status answer.
bool says_latched(const std::string& status_body) {
  const json::Value v = parse_json(status_body);
  const json::Value* e = v.get("estop_active");
  return e != nullptr && e->is_bool() && e->as_bool();
}

// One metric of /metrics, read from another address than the one the test crowds.
double metric_from(uint16_t port, const char* source, const std::string& name) {
  RawConn c(port, source);
  std::string body;
  EXPECT_EQ(c.exchange("GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", &body), 200);
  return metric_value(body, name);
}

bool estop_latched(uint16_t port, const std::string& token, const char* source) {
  RawConn c(port, source);
  std::string body;
  const int status = c.exchange(
      "GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + token + "\r\n\r\n",
      &body);
  EXPECT_EQ(status, 200) << body;
  return says_latched(body);
}

std::string stop_request(const std::string& token) {
  const std::string body = R"({"reason":"crowded address"})";
  return "POST /api/stop HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + token +
         "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
         "\r\n\r\n" + body;
}

// F14 (MED). A client on the OWNER's own address keeps every connection that address may open
// (server.limits.max_connections_per_address, 64) and re-opens each one as soon as the robot
// closes it, never sending a byte. Before the fix the OWNER's POST /api/stop from that address
// got 503 `too_many_connections_from_address` (or a closed connection) and ESTOP did not latch:
// the stop reserve applied over max_connections only. After: the new connection closes the
// oldest one that never authenticated and waits for a request, and the stop is answered 200.
TEST(AdversaryOperatorToRobot, AnOwnersStopLatchesWhileItsOwnAddressIsFloodedWithIdleConnections) {
  ConfiguredNode node("", 2000, false);
  const uint16_t port = node.http_port();
  ASSERT_NE(port, 0);
  const std::string owner = node.token("owner", {"control", "status"}, "alice");
  // An authenticated session of the OWNER's from the same address, open before the flood.
  RawConn session(port);
  ASSERT_EQ(session.exchange("GET /api/status HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                             owner + "\r\n\r\n"),
            200);
  std::atomic<bool> done{false};
  std::atomic<int> opened{0};
  std::thread attacker([&] {
    std::deque<std::unique_ptr<RawConn>> held;
    while (!done.load()) {
      held.push_back(std::make_unique<RawConn>(port));
      if (held.back()->connected()) ++opened;
      if (held.size() > 256) held.pop_front();  // long since closed by the robot
    }
  });
  // Every slot of the address taken, many times over (bounded: the checks below fail if not).
  // The robot's own count of evictions is awaited too: on a slow machine the attacker may close
  // its oldest connections before the robot has accepted them, and those are not evictions.
  for (int i = 0; i < 600; ++i) {
    if (opened.load() >= 512 &&
        metric_from(port, "127.0.0.5", "rcan_http_connections_evicted_total") > 64)
      break;
    std::this_thread::sleep_for(50ms);
  }
  const int opened_before = opened.load();
  int status = 0;
  std::string answer;
  {
    RawConn stop(port);
    if (stop.connected()) status = stop.exchange(stop_request(owner), &answer);
  }
  // The OWNER's session was not evicted by the flood.
  std::string session_answer;
  const int session_status = session.exchange(
      "GET /api/status HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + owner + "\r\n\r\n",
      &session_answer);
  done = true;
  attacker.join();
  EXPECT_GE(opened_before, 512);
  EXPECT_EQ(status, 200) << answer;
  EXPECT_EQ(session_status, 200) << session_answer;
  EXPECT_TRUE(says_latched(session_answer)) << session_answer;
  EXPECT_TRUE(estop_latched(port, owner, "127.0.0.5"));
  // More than the address's whole share was closed to make room.
  EXPECT_GT(metric_from(port, "127.0.0.5", "rcan_http_connections_evicted_total"), 64);
  EXPECT_TRUE(node.proc().wait_for_line("http.connection_evicted", 5000).has_value());
}

// F14, the other way to hold an address: every connection it may open carries a valid (GUEST)
// credential, so none can be evicted. Before the fix the OWNER's stop from that address got 503
// `too_many_connections_from_address`; after, it is served from the reserve (anything else there
// is 503 `reserve_for_stop_only`).
TEST(AdversaryOperatorToRobot,
     AnOwnersStopLatchesWhileItsAddressHoldsOnlyAuthenticatedConnections) {
  ConfiguredNode node("server:\n  limits:\n    max_connections_per_address: 8\n", 2000, false);
  const uint16_t port = node.http_port();
  ASSERT_NE(port, 0);
  const std::string guest = node.token("guest", {"status"}, "mallory");
  const std::string owner = node.token("owner", {"control", "status"}, "alice");
  std::vector<std::unique_ptr<RawConn>> held;
  for (int i = 0; i < 8; ++i) {
    held.push_back(std::make_unique<RawConn>(port));
    ASSERT_EQ(held.back()->exchange("GET /api/status HTTP/1.1\r\nHost: x\r\nAuthorization: "
                                    "Bearer " +
                                    guest + "\r\n\r\n"),
              200);
  }
  {
    RawConn status(port);
    std::string body;
    EXPECT_EQ(status.exchange("GET /api/status HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                                  owner + "\r\n\r\n",
                              &body),
              503);
    EXPECT_NE(body.find("reserve_for_stop_only"), std::string::npos) << body;
  }
  RawConn stop(port);
  std::string answer;
  EXPECT_EQ(stop.exchange(stop_request(owner), &answer), 200) << answer;
  EXPECT_TRUE(estop_latched(port, owner, "127.0.0.5"));
  for (auto& c : held)  // the GUEST's connections were never closed for it
    EXPECT_EQ(c->exchange("GET /api/status HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + guest +
                          "\r\n\r\n"),
              200);
  EXPECT_EQ(metric_from(port, "127.0.0.5", "rcan_http_connections_evicted_total"), 0);
}

}  // namespace
}  // namespace rcan::test
