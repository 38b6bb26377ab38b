// Review finding R6 against a real rcand: one client could take every connection and lock out
// ESTOP. An attacker holds the whole (lowered) connection limit with idle keep-alive
// connections; the OWNER's stop still latches ESTOP, over HTTP and over a new WebSocket. One
// address gets server.limits.max_connections_per_address connections and no more; a connection
// that never presented a valid credential is closed after the short idle timeout (or, idle, to
// make room for a new one: finding F14, tests/adversary/http_seams_test.cpp), one that did
// keeps the long one. And R4's part here: one address's failed token verifications are
// limited.
//
// The attacker's connections come from other loopback addresses (127.0.0.2, …: all of
// 127.0.0.0/8 reaches the node on Linux), the owner's from 127.0.0.1.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "configured_node.h"

namespace rcan::test {
namespace {

using namespace std::chrono_literals;

// One raw TCP connection to the node from `source` (a loopback address).
class Conn {
 public:
  Conn(uint16_t port, const char* source) {
    const LoopbackSocket s = loopback_socket(port, source);
    fd_ = s.fd;
    connected_ = s.connected;
  }
  ~Conn() {
    if (fd_ >= 0) ::close(fd_);
  }
  Conn(const Conn&) = delete;
  Conn& operator=(const Conn&) = delete;
  bool connected() const { return connected_; }

  bool send(const std::string& method, const std::string& path, const std::string& token = "",
            const std::string& body = "") {
    std::string req = method + " " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n";
    if (!token.empty()) req += "Authorization: Bearer " + token + "\r\n";
    if (method == "POST")
      req += "Content-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
             "\r\n";
    req += "\r\n" + body;
    return ::send(fd_, req.data(), req.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(req.size());
  }
  // The next response (status 0 when none came within the timeout or the socket closed).
  HttpReply read(int timeout_ms = 5000) {
    HttpReply r;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      const size_t end = buf_.find("\r\n\r\n");
      if (end != std::string::npos) {
        size_t len = 0;
        const size_t cl = lower(buf_.substr(0, end)).find("content-length:");
        if (cl != std::string::npos) len = std::stoul(buf_.substr(cl + 15));
        if (buf_.size() >= end + 4 + len) {
          r.status = std::stoi(buf_.substr(9, 3));
          std::string head = lower(buf_.substr(0, end));
          if (head.find("connection: close") != std::string::npos)
            r.headers.emplace_back("connection", "close");
          r.body = buf_.substr(end + 4, len);
          buf_.erase(0, end + 4 + len);
          return r;
        }
      }
      if (!fill(deadline)) return r;
    }
  }
  // True when the node closes the connection within the timeout.
  bool wait_closed(int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (fill(deadline)) {
    }
    return eof_;
  }

 private:
  static std::string lower(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
  }
  bool fill(std::chrono::steady_clock::time_point deadline) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0 || eof_) return false;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return false;
    char tmp[16384];
    const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
    if (n <= 0) {
      eof_ = true;
      return false;
    }
    buf_.append(tmp, static_cast<size_t>(n));
    return true;
  }
  int fd_ = -1;
  bool connected_ = false;
  bool eof_ = false;
  std::string buf_;
};

std::string reason_of(const HttpReply& r) {
  json::Value v = parse_json(r.body);
  const json::Value* p = v.get("payload");
  const json::Value* reason = p ? p->get("reason") : nullptr;
  return reason && reason->is_string() ? reason->as_string() : "";
}

std::string error_code_of(const HttpReply& r) {
  json::Value v = parse_json(r.body);
  const json::Value* p = v.get("payload");
  const json::Value* code = p ? p->get("error_code") : nullptr;
  return code && code->is_string() ? code->as_string() : "";
}

// An attacker with a GUEST token (a valid credential: the connections keep the long keep-alive)
// takes `n` connections from `source`, each answered once and then left idle.
std::vector<std::unique_ptr<Conn>> hold(uint16_t port, const char* source, int n,
                                        const std::string& guest) {
  std::vector<std::unique_ptr<Conn>> held;
  for (int i = 0; i < n; ++i) {
    auto c = std::make_unique<Conn>(port, source);
    EXPECT_TRUE(c->connected());
    EXPECT_TRUE(c->send("GET", "/api/status", guest));
    EXPECT_EQ(c->read().status, 200);
    held.push_back(std::move(c));
  }
  return held;
}

bool estop_active(const ConfiguredNode& node) {
  HttpReply r = node.get("/healthz");
  EXPECT_EQ(r.status, 200) << r.body;
  const json::Value v = parse_json(r.body);  // kept: get() points into it
  const json::Value* e = v.get("estop_active");
  return e && e->is_bool() && e->as_bool();
}

// Only max_connections is lowered: the other limits keep their defaults.
constexpr const char* kSmallLimit = "server:\n  limits:\n    max_connections: 8\n";

TEST(ConnectionLimits, AnOwnersStopLatchesWhileAnAttackerHoldsEveryConnection) {
  ConfiguredNode node(kSmallLimit, 2000, false);
  const uint16_t port = node.http_port();
  const std::string guest = node.token("guest", {"status"}, "mallory");
  const std::string owner = node.token("owner", {"control", "status"}, "alice");
  auto held = hold(port, "127.0.0.2", 8, guest);  // every ordinary connection
  // A ninth client gets nothing but a stop through.
  Conn status(port, "127.0.0.1");
  ASSERT_TRUE(status.send("GET", "/api/status", owner));
  HttpReply refused = status.read();
  EXPECT_EQ(refused.status, 503) << refused.body;
  EXPECT_EQ(error_code_of(refused), "RATE_LIMITED") << refused.body;
  EXPECT_EQ(reason_of(refused), "reserve_for_stop_only") << refused.body;

  Conn stop(port, "127.0.0.1");
  ASSERT_TRUE(stop.connected());
  ASSERT_TRUE(stop.send("POST", "/api/stop", owner, R"({"reason":"connection flood"})"));
  HttpReply r = stop.read();
  EXPECT_EQ(r.status, 200) << r.body;
  // The attacker still holds every slot (authenticated: the long keep-alive).
  for (auto& c : held) ASSERT_TRUE(c->send("GET", "/api/status", guest));
  for (auto& c : held) EXPECT_EQ(c->read().status, 200);
  held.clear();
  bool latched = false;
  for (int i = 0; i < 50 && !latched; ++i) {  // the attacker's slots free as its sockets close
    HttpReply h = node.get("/healthz");
    if (h.status == 200) latched = estop_active(node);
    if (!latched) std::this_thread::sleep_for(50ms);
  }
  EXPECT_TRUE(latched);
  EXPECT_GE(node.metric("rcan_http_reserve_connections_total"), 2);
  EXPECT_GE(node.metric("rcan_http_reserve_refused_total"), 1);
}

TEST(ConnectionLimits, ASafetyFrameOnANewStreamLatchesWhileAnAttackerHoldsEveryConnection) {
  ConfiguredNode node(kSmallLimit, 2000, false);
  const uint16_t port = node.http_port();
  const std::string guest = node.token("guest", {"status"}, "mallory");
  const std::string owner = node.token("owner", {"control", "status"}, "alice");
  auto held = hold(port, "127.0.0.2", 4, guest);
  auto held2 = hold(port, "127.0.0.3", 4, guest);
  auto connect = [&](WsClient& ws) {
    ASSERT_EQ(ws.connect(port, "/rcan/v1/stream"), 101);
    ASSERT_TRUE(ws.send_text(R"({"type":"CONNECT","token":")" + owner + "\"}"));
    auto ack = ws.recv_text(5000);
    ASSERT_TRUE(ack.has_value());
    EXPECT_EQ(parse_json(*ack).get("type")->as_string(), "CONNECT_ACK");
  };
  {  // a reserve stream carries SAFETY messages only
    WsClient ws;
    connect(ws);
    ASSERT_TRUE(ws.send_text(command_json("status")));
    auto err = ws.recv_text(5000);
    ASSERT_TRUE(err.has_value());
    EXPECT_NE(err->find("reserve_for_stop_only"), std::string::npos) << *err;
    EXPECT_FALSE(ws.recv_text(5000).has_value());
    EXPECT_EQ(ws.close_code(), 1008);
  }
  WsClient ws;
  connect(ws);
  json::Object estop{{"version", "1.0.0"},
                     {"message_id", new_uuid_v4()},
                     {"type", "SAFETY"},
                     {"priority", "SAFETY"},
                     {"timestamp_ms", now_wall_ms()},
                     {"payload", json::Object{{"safety_event", "ESTOP"}}}};
  ASSERT_TRUE(ws.send_text(json::dump(json::Value(estop))));
  bool acked = false;  // the ESTOP event may come first
  for (int i = 0; i < 10 && !acked; ++i) {
    auto frame = ws.recv_text(5000);
    ASSERT_TRUE(frame.has_value());
    acked = parse_json(*frame).get("type")->as_string() == "ACK";
  }
  EXPECT_TRUE(acked);
  held.clear();
  held2.clear();
  bool latched = false;
  for (int i = 0; i < 50 && !latched; ++i) {
    HttpReply h = node.get("/healthz");
    if (h.status == 200) latched = estop_active(node);
    if (!latched) std::this_thread::sleep_for(50ms);
  }
  EXPECT_TRUE(latched);
}

// With every connection authenticated (none can be evicted for a new one) and its two reserve
// connections taken, an address gets no more.
TEST(ConnectionLimits, OneAddressGetsMaxConnectionsPerAddressAndNoMore) {
  ConfiguredNode node("", 2000, false);  // the default: 64 per address
  const uint16_t port = node.http_port();
  const std::string guest = node.token("guest", {"status"}, "mallory");
  auto held = hold(port, "127.0.0.2", 64, guest);
  Conn reserve1(port, "127.0.0.2"), reserve2(port, "127.0.0.2");  // accepted first: in order
  Conn extra(port, "127.0.0.2");
  HttpReply r = extra.read();  // answered at once, before any request
  EXPECT_EQ(r.status, 503) << r.body;
  EXPECT_EQ(error_code_of(r), "RATE_LIMITED") << r.body;
  EXPECT_EQ(reason_of(r), "too_many_connections_from_address") << r.body;
  EXPECT_TRUE(extra.wait_closed(5000));
  Conn other(port, "127.0.0.3");  // another address is served
  ASSERT_TRUE(other.send("GET", "/healthz"));
  EXPECT_EQ(other.read().status, 200);
  EXPECT_EQ(node.metric("rcan_http_connections_refused_per_address_total"), 1);
  EXPECT_TRUE(node.proc().wait_for_line("http.address_connection_limit", 5000).has_value());
}

// The lowered limit applies: the third connection from the address closes the one of the two
// that never presented a credential (finding F14), never the authenticated one.
TEST(ConnectionLimits, LoweredPerAddressLimitFromTheConfig) {
  ConfiguredNode node("server:\n  limits:\n    max_connections_per_address: 2\n", 2000, false);
  const std::string guest = node.token("guest", {"status"}, "gina");
  Conn a(node.http_port(), "127.0.0.2"), b(node.http_port(), "127.0.0.2");
  ASSERT_TRUE(a.send("GET", "/api/status", guest));
  ASSERT_EQ(a.read().status, 200);
  ASSERT_TRUE(b.send("GET", "/healthz"));
  ASSERT_EQ(b.read().status, 200);
  // A third connection makes room by closing b once b waits for its next request (until its
  // strand has gone back to waiting after the answer, b is not idle yet: the newcomer then gets
  // the reserve, which serves stops only, and is closed — so it tries again).
  HttpReply r;
  EXPECT_TRUE(test::eventually(
      [&] {
        Conn c(node.http_port(), "127.0.0.2");
        r = c.send("GET", "/healthz") ? c.read() : HttpReply{};
        return r.status == 200;
      },
      5000))
      << r.status << " " << r.body;
  EXPECT_TRUE(b.wait_closed(5000));
  ASSERT_TRUE(a.send("GET", "/healthz"));
  EXPECT_EQ(a.read().status, 200);
  EXPECT_EQ(node.metric("rcan_http_connections_evicted_total"), 1);
  EXPECT_TRUE(node.proc().wait_for_line("http.connection_evicted", 5000).has_value());
}

// The defaults: 5 s of keep-alive before a credential, 60 s after one.
TEST(ConnectionLimits, UnauthenticatedConnectionsIdleOutSoonAuthenticatedOnesKeepTheLongTimeout) {
  ConfiguredNode node("", 2000, false);
  const uint16_t port = node.http_port();
  const std::string guest = node.token("guest", {"status"}, "gina");
  Conn anon(port, "127.0.0.1"), forged(port, "127.0.0.1"), authed(port, "127.0.0.1");
  ASSERT_TRUE(anon.send("GET", "/healthz"));
  ASSERT_EQ(anon.read().status, 200);
  ASSERT_TRUE(forged.send("GET", "/healthz", guest.substr(0, guest.size() - 4) + "AAAA"));
  ASSERT_EQ(forged.read().status, 200);
  ASSERT_TRUE(authed.send("GET", "/api/status", guest));
  ASSERT_EQ(authed.read().status, 200);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(anon.wait_closed(8000));
  EXPECT_TRUE(forged.wait_closed(8000));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 8s);
  std::this_thread::sleep_until(t0 + 7s);
  ASSERT_TRUE(authed.send("GET", "/healthz"));
  EXPECT_EQ(authed.read().status, 200);
}

// R4: tokens failing verification cost the node a signature check each. One address gets
// security.failed_auth_per_address_per_minute of them (lowered to 30 here); past it, a token
// not verified before is refused 429 without being verified. Tokens verified before, stops, and
// other addresses are not held up.
TEST(FailedAuthLimit, AnAddressThatSpentItsBadTokensGetsNoMoreVerifiedButItsStopsAndOthersDo) {
  ConfiguredNode node("", 2000, false, "  failed_auth_per_address_per_minute: 30\n");
  const uint16_t port = node.http_port();
  const std::string known = node.token("user", {"control", "status"}, "known-user");
  const std::string forged = known.substr(0, known.size() - 6) + "AAAAAA";
  Conn c(port, "127.0.0.2");
  ASSERT_TRUE(c.connected());
  // Verified once: the node remembers it.
  ASSERT_TRUE(c.send("POST", "/rcan/v1/command", known, command_json("status")));
  ASSERT_EQ(c.read().status, 200);
  int unauthorized = 0, limited = 0;
  for (int i = 0; i < 45; ++i) {
    ASSERT_TRUE(c.send("POST", "/rcan/v1/command", forged, command_json("status")));
    HttpReply r = c.read();
    if (r.status == 401) {
      ++unauthorized;
    } else {
      ASSERT_EQ(r.status, 429) << r.body;
      EXPECT_EQ(reason_of(r), "failed_auth_rate") << r.body;
      ++limited;
    }
  }
  EXPECT_GE(unauthorized, 30);
  EXPECT_LE(unauthorized, 32);  // the bucket refills at one every 2 s
  EXPECT_GE(limited, 13);
  // A valid token the node has not seen yet is not verified for this address now…
  const std::string fresh = node.token("owner", {"control", "status"}, "fresh-owner");
  ASSERT_TRUE(c.send("POST", "/rcan/v1/command", fresh, command_json("status")));
  HttpReply held = c.read();
  EXPECT_EQ(held.status, 429) << held.body;
  ASSERT_TRUE(c.send("GET", "/api/status", fresh));
  EXPECT_EQ(c.read().status, 429);
  // …but the token verified before still works, and a stop with the fresh one latches.
  ASSERT_TRUE(c.send("POST", "/rcan/v1/command", known, command_json("status")));
  EXPECT_EQ(c.read().status, 200);
  ASSERT_TRUE(c.send("POST", "/api/stop", fresh, R"({"reason":"flooded address"})"));
  HttpReply stop = c.read();
  EXPECT_EQ(stop.status, 200) << stop.body;
  EXPECT_TRUE(estop_active(node));
  // Another address is not held up by this one's failures.
  Conn other(port, "127.0.0.3");
  ASSERT_TRUE(other.send("GET", "/api/status", node.token("guest", {"status"}, "elsewhere")));
  EXPECT_EQ(other.read().status, 200);
}

}  // namespace
}  // namespace rcan::test
