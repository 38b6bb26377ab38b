// UDP transport: the datagram format (udp_wire.h), and end to end against a configured
// rcand — per-session heartbeat keys issued at claim, heartbeats keeping the deadman alive,
// their loss safe-stopping the robot (measured inside the node), forged / replayed / malformed
// datagrams dropped and counted, DISCOVER → ANNOUNCE with per-source rate limiting. Also the
// `grpc` and `udp` config blocks.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstring>
#include <thread>

#include "config/config.h"
#include "configured_node.h"
#include "rcan/encoding.h"
#include "rcan/udp_wire.h"

namespace rcan {
namespace {

using test::ConfiguredNode;
using test::HttpReply;
using test::parse_json;

// ---------------------------------------------------------------------------------------------
// Wire format

udp::Key key_of(uint8_t b) {
  udp::Key k;
  k.fill(b);
  return k;
}

TEST(UdpWire, HeartbeatLayoutIsByteExactAndVerifies) {
  udp::KeyId id;
  for (size_t i = 0; i < id.size(); ++i) id[i] = static_cast<uint8_t>(i);
  auto hb = udp::encode_heartbeat(id, 0x0102030405060708ULL, key_of(7));
  ASSERT_EQ(hb.size(), 64u);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(hb.data()), 4), "RCAN");
  EXPECT_EQ(hb[4], 1);
  EXPECT_EQ(hb[5], 1);
  EXPECT_EQ(hb[6], 0);
  EXPECT_EQ(hb[7], 0);
  EXPECT_EQ(hb[8], 0);
  EXPECT_EQ(hb[23], 15);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(hb[static_cast<size_t>(24 + i)], i + 1);
  // The MAC is HMAC-SHA256(key, bytes 0..31).
  udp::Key k = key_of(7);
  Digest256 mac = hmac_sha256(k.data(), k.size(), hb.data(), 32);
  EXPECT_EQ(0, std::memcmp(mac.data(), hb.data() + 32, 32));
  udp::Parsed p = udp::parse(hb);
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p.d.kind, udp::Kind::kHeartbeat);
  EXPECT_EQ(p.d.seq, 0x0102030405060708ULL);
  EXPECT_EQ(p.d.key_id, id);
  EXPECT_TRUE(udp::verify_heartbeat(hb, key_of(7)));
  EXPECT_FALSE(udp::verify_heartbeat(hb, key_of(8)));
  hb[30] ^= 1;  // the sequence number is covered by the MAC
  EXPECT_FALSE(udp::verify_heartbeat(hb, key_of(7)));
}

TEST(UdpWire, MalformedDatagramsAreNamed) {
  auto hb = udp::encode_heartbeat(udp::KeyId{}, 1, key_of(1));
  auto parse_err = [](std::vector<uint8_t> b) { return udp::parse(b).error; };
  EXPECT_EQ(parse_err({}), udp::ParseError::kTooShort);
  EXPECT_EQ(parse_err({'R', 'C', 'A'}), udp::ParseError::kTooShort);
  std::vector<uint8_t> v(hb.begin(), hb.end());
  auto with = [&](size_t i, uint8_t x) {
    auto c = v;
    c[i] = x;
    return c;
  };
  EXPECT_EQ(parse_err(with(0, 'X')), udp::ParseError::kBadMagic);
  EXPECT_EQ(parse_err(with(4, 2)), udp::ParseError::kBadVersion);
  EXPECT_EQ(parse_err(with(5, 9)), udp::ParseError::kBadKind);
  EXPECT_EQ(parse_err(with(7, 1)), udp::ParseError::kBadFlags);
  auto shorter = v;
  shorter.pop_back();
  EXPECT_EQ(parse_err(shorter), udp::ParseError::kBadLength);
  auto longer = v;
  longer.push_back(0);
  EXPECT_EQ(parse_err(longer), udp::ParseError::kBadLength);
  udp::Nonce n{1, 2, 3, 4, 5, 6, 7, 8};
  auto d = udp::encode_discover(n);
  udp::Parsed pd = udp::parse(d);
  ASSERT_TRUE(pd.ok());
  EXPECT_EQ(pd.d.kind, udp::Kind::kDiscover);
  EXPECT_EQ(pd.d.nonce, n);
  EXPECT_EQ(pd.d.size, 16u);
  // A DISCOVER may be zero-padded up to 8192 bytes (its answer may be as long).
  std::string padded = udp::encode_discover_padded(n);
  ASSERT_EQ(padded.size(), udp::kDiscoverPaddedSize);
  std::vector<uint8_t> pb(padded.begin(), padded.end());
  udp::Parsed pp = udp::parse(pb);
  ASSERT_TRUE(pp.ok()) << udp::parse_error_name(pp.error);
  EXPECT_EQ(pp.d.nonce, n);
  EXPECT_EQ(pp.d.size, udp::kDiscoverPaddedSize);
  pb[600] = 1;
  EXPECT_EQ(parse_err(pb), udp::ParseError::kBadPadding);
  std::string huge = udp::encode_discover_padded(n, 8192);
  std::vector<uint8_t> hb2(huge.begin(), huge.end());
  EXPECT_TRUE(udp::parse(hb2).ok());
  hb2.push_back(0);
  EXPECT_EQ(parse_err(hb2), udp::ParseError::kBadLength);
  std::string a = udp::encode_announce(n, R"({"type":"ANNOUNCE"})");
  udp::Parsed pa = udp::parse({reinterpret_cast<const uint8_t*>(a.data()), a.size()});
  ASSERT_TRUE(pa.ok());
  EXPECT_EQ(pa.d.body, R"({"type":"ANNOUNCE"})");
  std::string bad = udp::encode_announce(n, "[1]");
  EXPECT_EQ(udp::parse({reinterpret_cast<const uint8_t*>(bad.data()), bad.size()}).error,
            udp::ParseError::kBadBody);
}

// ---------------------------------------------------------------------------------------------
// End to end

class UdpSocket {
 public:
  UdpSocket() { fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0); }
  ~UdpSocket() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool send(uint16_t port, const void* data, size_t n) const {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    return ::sendto(fd_, data, n, 0, reinterpret_cast<sockaddr*>(&a), sizeof a) ==
           static_cast<ssize_t>(n);
  }
  template <size_t N>
  bool send(uint16_t port, const std::array<uint8_t, N>& a) const {
    return send(port, a.data(), a.size());
  }
  std::optional<std::string> recv(int timeout_ms) const {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) <= 0) return std::nullopt;
    char buf[9000];
    ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
    if (n < 0) return std::nullopt;
    return std::string(buf, static_cast<size_t>(n));
  }

 private:
  int fd_ = -1;
};

struct Grant {
  std::string session_id;
  udp::KeyId key_id{};
  udp::Key key{};
  uint16_t port = 0;
  int64_t interval_ms = 0;
  int64_t timeout_ms = 0;
};

Grant claim(const ConfiguredNode& n, const std::string& token) {
  Grant g;
  HttpReply r = n.post("/rcan/v1/auth/claim", "{}", token);
  EXPECT_EQ(r.status, 200) << r.body;
  json::Value v = parse_json(r.body);
  const json::Value* p = v.get("payload");
  if (!p) return g;
  g.session_id = p->get("session_id")->as_string();
  g.timeout_ms = p->get("heartbeat_timeout_ms")->as_int();
  const json::Value* u = p->get("udp_heartbeat");
  EXPECT_NE(u, nullptr) << r.body;
  if (!u) return g;
  EXPECT_EQ(u->get("session_id")->as_string(), g.session_id);
  EXPECT_EQ(u->get("format")->as_string(), "rcan-udp-heartbeat-v1");
  g.port = static_cast<uint16_t>(u->get("port")->as_int());
  g.interval_ms = u->get("interval_ms")->as_int();
  auto id = from_hex(u->get("key_id")->as_string());
  auto key = base64_decode(u->get("key_b64")->as_string());
  EXPECT_TRUE(id && id->size() == 16);
  EXPECT_TRUE(key && key->size() == 32);
  if (id && id->size() == 16) std::memcpy(g.key_id.data(), id->data(), 16);
  if (key && key->size() == 32) std::memcpy(g.key.data(), key->data(), 32);
  return g;
}

std::vector<json::Value> events_named(const std::vector<json::Value>& records,
                                      const std::string& event) {
  std::vector<json::Value> out;
  for (const auto& r : records)
    if (r.get("event") && r.get("event")->as_string() == event) out.push_back(r);
  return out;
}

TEST(UdpHeartbeat, HeartbeatsKeepTheSessionAliveAndTheirLossSafeStopsTheRobot) {
  ConfiguredNode n({}, /*heartbeat_timeout_ms=*/1000);
  ASSERT_NE(n.udp_port(), 0) << n.proc().err();
  std::string owner = n.token("owner", {"control", "status", "config"}, "udp-owner");
  Grant g = claim(n, owner);
  ASSERT_EQ(g.port, n.udp_port());
  EXPECT_EQ(g.timeout_ms, 1000);
  EXPECT_EQ(g.interval_ms, 250);
  // Drive (under the session) and keep it alive over UDP for three timeouts.
  HttpReply drive =
      n.post("/rcan/v1/command",
             test::command_json("move", {{"linear", 0.2}, {"duration_ms", 4000}}), owner);
  ASSERT_EQ(drive.status, 200) << drive.body;
  UdpSocket s;
  uint64_t seq = 0;
  auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(3 * g.timeout_ms);
  while (std::chrono::steady_clock::now() < until) {
    ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(g.key_id, ++seq, g.key)));
    std::this_thread::sleep_for(std::chrono::milliseconds(g.interval_ms));
  }
  json::Value st = parse_json(n.get("/rcan/v1/status", owner).body);
  EXPECT_FALSE(st.get("robot")->get("safe_stop")->as_bool())
      << "heartbeats did not keep the session alive";
  EXPECT_TRUE(events_named(n.audit(owner), "NETWORK_LOSS_SAFE_STOP").empty());
  EXPECT_GE(n.metric("rcan_udp_heartbeats_accepted_total"), static_cast<double>(seq) - 1);
  // Silence: the deadman safe-stops the robot.
  bool stopped = false;
  for (int i = 0; i < 100 && !stopped; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    stopped =
        parse_json(n.get("/rcan/v1/status", owner).body).get("robot")->get("safe_stop")->as_bool();
  }
  ASSERT_TRUE(stopped);
  std::vector<json::Value> loss;
  for (int i = 0; i < 40 && loss.empty(); ++i) {
    loss = events_named(n.audit(owner), "NETWORK_LOSS_SAFE_STOP");
    if (loss.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(loss.size(), 1u);
  EXPECT_EQ(loss[0].get("detail")->get("session_id")->as_string(), g.session_id);
  // Measured inside the node: monotonic time from the last accepted heartbeat to the deadman's
  // stop (the safety core's elapsed_ms at the moment it stopped the driver).
  int64_t elapsed = loss[0].get("detail")->get("elapsed_ms")->as_int();
  int64_t overshoot = elapsed - g.timeout_ms;
  std::printf(
      "heartbeat loss -> safe-stop: %lld ms after the last heartbeat (deadline %lld ms, +%lld ms; "
      "%s)\n",
      static_cast<long long>(elapsed), static_cast<long long>(g.timeout_ms),
      static_cast<long long>(overshoot),
      overshoot <= 10 ? "within deadline + 10 ms" : "OVER deadline + 10 ms");
  EXPECT_GT(elapsed, g.timeout_ms);
  EXPECT_LE(overshoot, 250);  // generous: the suite shares two cores
  json::Value robot = *parse_json(n.get("/rcan/v1/status", owner).body).get("robot");
  EXPECT_EQ(robot.get("state")->as_string(), "safe_stop");
  // The first UDP heartbeat of the key is in the audit chain, with its transport.
  auto hb = events_named(n.audit(owner), "HEARTBEAT");
  ASSERT_FALSE(hb.empty());
  EXPECT_EQ(hb[0].get("detail")->get("transport")->as_string(), "udp");
  EXPECT_EQ(hb[0].get("detail")->get("session_id")->as_string(), g.session_id);
  EXPECT_EQ(n.metric("rcan_audit_failures_total"), 0);
}

// Secrets never travel in events: a claim promoted from the queue is told on its own stream
// (PROMOTED, no key), and its holder fetches its heartbeat key by an authenticated request —
// renewing its session with udp_heartbeat: true. Nobody else can.
TEST(UdpHeartbeat, ASessionPromotedFromTheQueueFetchesItsKeyNotFromAnEvent) {
  ConfiguredNode n({}, /*heartbeat_timeout_ms=*/2000);
  ASSERT_NE(n.udp_port(), 0) << n.proc().err();
  std::string a = n.token("user", {"control", "status"}, "udp-user-a");
  std::string b = n.token("user", {"control", "status"}, "udp-user-b");
  std::string c = n.token("user", {"control", "status"}, "udp-user-c");
  Grant ga = claim(n, a);
  ASSERT_FALSE(ga.session_id.empty());
  // B listens on its stream, then queues behind A.
  test::WsClient ws;
  ASSERT_EQ(ws.connect(n.http_port(), "/rcan/v1/stream"), 101);
  ASSERT_TRUE(
      ws.send_text(json::dump(json::Value(json::Object{{"type", "CONNECT"}, {"token", b}}))));
  auto ack = ws.recv_text(5000);
  ASSERT_TRUE(ack && ack->find("CONNECT_ACK") != std::string::npos) << (ack ? *ack : "no answer");
  HttpReply q = n.post("/rcan/v1/auth/claim", "{}", b);
  ASSERT_EQ(q.status, 409) << q.body;
  ASSERT_NE(q.body.find("\"queued\":true"), std::string::npos) << q.body;
  // A releases: B is promoted; its GRANTED event carries no key.
  HttpReply rel = n.post("/rcan/v1/auth/release", "{}", a);
  ASSERT_EQ(rel.status, 200) << rel.body;
  std::optional<json::Value> promoted;
  for (int i = 0; i < 50 && !promoted; ++i) {
    auto f = ws.recv_text(200);
    if (!f) continue;
    EXPECT_EQ(f->find("key_b64"), std::string::npos) << *f;
    json::Value v = parse_json(*f);
    if (v.get("event") && v.get("event")->as_string() == "PROMOTED") promoted = v;
  }
  ASSERT_TRUE(promoted) << "no PROMOTED event on B's stream";
  EXPECT_EQ(promoted->get("udp_heartbeat"), nullptr) << json::dump(*promoted);
  EXPECT_EQ(json::dump(*promoted).find("key_b64"), std::string::npos);
  std::string b_session = promoted->get("session_id")->as_string();
  EXPECT_NE(b_session, ga.session_id);
  const std::string ask =
      json::dump(json::Value(json::Object{{"session_id", b_session}, {"udp_heartbeat", true}}));
  // Another principal — the former holder, or a stranger — cannot fetch B's key.
  for (const std::string* other : {&a, &c}) {
    HttpReply r = n.post("/rcan/v1/auth/renew", ask, *other);
    EXPECT_EQ(r.status, 403) << r.body;
    EXPECT_EQ(r.body.find("key_b64"), std::string::npos) << r.body;
  }
  // B fetches it by renewing its own session.
  HttpReply mine = n.post("/rcan/v1/auth/renew", ask, b);
  ASSERT_EQ(mine.status, 200) << mine.body;
  json::Value mv = parse_json(mine.body);
  const json::Value* u = mv.get("payload") ? mv.get("payload")->get("udp_heartbeat") : nullptr;
  ASSERT_NE(u, nullptr) << mine.body;
  EXPECT_EQ(u->get("session_id")->as_string(), b_session);
  auto id = from_hex(u->get("key_id")->as_string());
  auto key = base64_decode(u->get("key_b64")->as_string());
  ASSERT_TRUE(id && id->size() == 16);
  ASSERT_TRUE(key && key->size() == 32);
  udp::KeyId kid{};
  udp::Key k{};
  std::memcpy(kid.data(), id->data(), 16);
  std::memcpy(k.data(), key->data(), 32);
  // A plain renewal keeps the key (and says nothing of it).
  HttpReply plain = n.post("/rcan/v1/auth/renew",
                           json::dump(json::Value(json::Object{{"session_id", b_session}})), b);
  ASSERT_EQ(plain.status, 200) << plain.body;
  EXPECT_EQ(plain.body.find("key_b64"), std::string::npos) << plain.body;
  // The key works: B's heartbeats are accepted; A's old key no longer is (A released).
  double before = n.metric("rcan_udp_heartbeats_accepted_total");
  UdpSocket s;
  for (uint64_t seq = 1; seq <= 3; ++seq) {
    ASSERT_TRUE(s.send(n.udp_port(), udp::encode_heartbeat(kid, seq, k)));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  double after = before;
  for (int i = 0; i < 40 && after < before + 3; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
    after = n.metric("rcan_udp_heartbeats_accepted_total");
  }
  EXPECT_EQ(after, before + 3);
}

TEST(UdpHeartbeat, ForgedReplayedAndMalformedDatagramsAreIgnoredAndCounted) {
  ConfiguredNode n({}, /*heartbeat_timeout_ms=*/600);
  ASSERT_NE(n.udp_port(), 0) << n.proc().err();
  std::string owner = n.token("owner", {"control", "status", "config"}, "udp-owner");
  Grant g = claim(n, owner);
  UdpSocket s;
  ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(g.key_id, 5, g.key)));  // accepted
  ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(g.key_id, 5, g.key)));  // replayed
  ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(g.key_id, 4, g.key)));  // replayed (older)
  udp::Key wrong = g.key;
  wrong[0] ^= 0xff;
  ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(g.key_id, 6, wrong)));  // forged: bad MAC
  udp::KeyId other = g.key_id;
  other[15] ^= 1;
  ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(other, 7, g.key)));  // forged: unknown key id
  ASSERT_TRUE(s.send(g.port, "hello", 5));                              // malformed
  auto v2 = udp::encode_heartbeat(g.key_id, 8, g.key);
  v2[4] = 2;
  ASSERT_TRUE(s.send(g.port, v2));             // malformed: version
  ASSERT_TRUE(s.send(g.port, v2.data(), 40));  // malformed: length
  double accepted = -1, replayed = -1, forged = -1, malformed = -1;
  for (int i = 0; i < 40; ++i) {
    accepted = n.metric("rcan_udp_heartbeats_accepted_total");
    replayed = n.metric("rcan_udp_heartbeats_replayed_total");
    forged = n.metric("rcan_udp_heartbeats_forged_total");
    malformed = n.metric("rcan_udp_malformed_total");
    if (accepted + replayed + forged + malformed >= 8) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_EQ(accepted, 1);
  EXPECT_EQ(replayed, 2);
  EXPECT_EQ(forged, 2);
  EXPECT_EQ(malformed, 3);
  // Only forged and replayed heartbeats from now on: they do not feed the deadman.
  for (int i = 0; i < 20; ++i) {
    s.send(g.port, udp::encode_heartbeat(g.key_id, 100 + static_cast<uint64_t>(i), wrong));
    s.send(g.port, udp::encode_heartbeat(g.key_id, 5, g.key));
    std::this_thread::sleep_for(std::chrono::milliseconds(75));
  }
  std::vector<json::Value> loss;
  for (int i = 0; i < 40 && loss.empty(); ++i) {
    loss = events_named(n.audit(owner), "NETWORK_LOSS_SAFE_STOP");
    if (loss.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(loss.size(), 1u);
  EXPECT_EQ(loss[0].get("detail")->get("session_id")->as_string(), g.session_id);
  // After release, even a valid heartbeat of the old key is stale.
  HttpReply rel = test::http(n.http_port(), "DELETE", "/rcan/v1/auth/release",
                             "{\"session_id\":\"" + g.session_id + "\"}",
                             {{"Authorization", "Bearer " + owner}});
  ASSERT_EQ(rel.status, 200) << rel.body;
  ASSERT_TRUE(s.send(g.port, udp::encode_heartbeat(g.key_id, 1000, g.key)));
  double stale = -1;
  for (int i = 0; i < 40 && stale < 1; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    stale = n.metric("rcan_udp_heartbeats_stale_total");
  }
  EXPECT_EQ(stale, 1);
}

TEST(UdpDiscovery, DiscoverIsAnsweredWithAnnounceAndRateLimitedPerSource) {
  ConfiguredNode n;
  ASSERT_NE(n.udp_port(), 0) << n.proc().err();
  UdpSocket s;
  udp::Nonce nonce{9, 8, 7, 6, 5, 4, 3, 2};
  const std::string discover = udp::encode_discover_padded(nonce);
  ASSERT_TRUE(s.send(n.udp_port(), discover.data(), discover.size()));
  auto a = s.recv(5000);
  ASSERT_TRUE(a.has_value());
  EXPECT_LE(a->size(), discover.size());
  udp::Parsed p = udp::parse({reinterpret_cast<const uint8_t*>(a->data()), a->size()});
  ASSERT_TRUE(p.ok()) << udp::parse_error_name(p.error);
  EXPECT_EQ(p.d.kind, udp::Kind::kAnnounce);
  EXPECT_EQ(p.d.nonce, nonce);
  json::Value v = parse_json(p.d.body);
  EXPECT_EQ(v.get("type")->as_string(), "ANNOUNCE");
  EXPECT_EQ(v.get("payload")->get("ruri")->as_string(), ConfiguredNode::kRuri);
  EXPECT_EQ(v.get("payload")->get("port")->as_int(), n.http_port());
  EXPECT_EQ(v.get("payload")->get("udp_port")->as_int(), n.udp_port());
  // A burst from one source: a few answers (burst 5), the rest dropped and counted.
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(s.send(n.udp_port(), discover.data(), discover.size()));
  int answers = 0;
  while (s.recv(500)) ++answers;
  EXPECT_GE(answers, 1);
  EXPECT_LE(answers, 5);
  EXPECT_GE(n.metric("rcan_udp_discover_limited_total"), 15);
  EXPECT_EQ(n.metric("rcan_udp_discover_answered_total"), 1 + answers);
}

// No amplification: an unauthenticated DISCOVER never gets more bytes back than it sent. The
// 16-byte one gets nothing; a short padded one learns how long a DISCOVER must be; one that long
// gets the whole record.
TEST(UdpDiscovery, NoAnswerIsLongerThanItsDiscover) {
  ConfiguredNode n;
  ASSERT_NE(n.udp_port(), 0) << n.proc().err();
  UdpSocket s;
  // The answer to the DISCOVER with this nonce (anything else arriving is skipped).
  auto answer_to = [&](const udp::Nonce& nonce, int timeout_ms) -> std::optional<std::string> {
    auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < until) {
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      auto a = s.recv(static_cast<int>(std::max<int64_t>(1, left.count())));
      if (!a) return std::nullopt;
      udp::Parsed p = udp::parse({reinterpret_cast<const uint8_t*>(a->data()), a->size()});
      if (p.ok() && p.d.kind == udp::Kind::kAnnounce && p.d.nonce == nonce) return a;
    }
    return std::nullopt;
  };
  auto metric_at_least = [&](const char* name, double v) {
    double got = 0;
    for (int i = 0; i < 100 && got < v; ++i) {
      got = n.metric(name);
      if (got < v) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return got;
  };
  const udp::Nonce bare{1, 1, 2, 3, 5, 8, 13, 21}, shortish{2, 1, 2, 3, 5, 8, 13, 21},
      padded{3, 1, 2, 3, 5, 8, 13, 21};
  ASSERT_TRUE(s.send(n.udp_port(), udp::encode_discover(bare)));  // 16 bytes
  auto tiny = answer_to(bare, 1000);
  EXPECT_FALSE(tiny.has_value()) << "16 bytes asked, " << (tiny ? tiny->size() : 0) << " answered";
  EXPECT_GE(metric_at_least("rcan_udp_discover_short_total", 1), 1);

  const std::string small = udp::encode_discover_padded(shortish, 100);
  ASSERT_TRUE(s.send(n.udp_port(), small.data(), small.size()));
  auto hint = answer_to(shortish, 5000);
  ASSERT_TRUE(hint.has_value());
  EXPECT_LE(hint->size(), small.size());
  udp::Parsed hp = udp::parse({reinterpret_cast<const uint8_t*>(hint->data()), hint->size()});
  json::Value hv = parse_json(hp.d.body);
  ASSERT_NE(hv.get("payload"), nullptr) << hp.d.body;
  EXPECT_EQ(hv.get("payload")->get("ruri"), nullptr) << hp.d.body;
  const json::Value* need = hv.get("payload")->get("discover_size");
  ASSERT_NE(need, nullptr) << hp.d.body;
  ASSERT_GT(need->as_int(), 100);
  ASSERT_LE(need->as_int(), static_cast<int64_t>(udp::kDiscoverPaddedSize));

  const std::string enough =
      udp::encode_discover_padded(padded, static_cast<size_t>(need->as_int()));
  ASSERT_TRUE(s.send(n.udp_port(), enough.data(), enough.size()));
  auto full = answer_to(padded, 5000);
  ASSERT_TRUE(full.has_value());
  EXPECT_LE(full->size(), enough.size());
  udp::Parsed fp = udp::parse({reinterpret_cast<const uint8_t*>(full->data()), full->size()});
  json::Value fv = parse_json(fp.d.body);
  EXPECT_EQ(fv.get("payload")->get("ruri")->as_string(), ConfiguredNode::kRuri);
  EXPECT_EQ(metric_at_least("rcan_udp_discover_answered_total", 1), 1);
}

TEST(UdpCli, UdpDiscoverAndUdpHeartbeatVerbsTalkToTheNode) {
  ConfiguredNode n({}, /*heartbeat_timeout_ms=*/2000);
  ASSERT_NE(n.udp_port(), 0) << n.proc().err();
  auto r = test::run_cli({"udp-discover", "--host", "127.0.0.1", "--port",
                          std::to_string(n.udp_port()), "--timeout-ms", "3000"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value line = parse_json(r.out.substr(0, r.out.find('\n')));
  EXPECT_EQ(line.get("announce")->get("payload")->get("ruri")->as_string(), ConfiguredNode::kRuri);
  EXPECT_EQ(line.get("from")->as_string(), "127.0.0.1:" + std::to_string(n.udp_port()));
  std::string owner = n.token("owner", {"control", "status", "config"});
  HttpReply c = n.post("/rcan/v1/auth/claim", "{}", owner);
  ASSERT_EQ(c.status, 200);
  json::Value granted = parse_json(c.body);
  const json::Value* u = granted.get("payload")->get("udp_heartbeat");
  ASSERT_NE(u, nullptr);
  auto hb = test::run_cli({"udp-heartbeat", "--port", std::to_string(u->get("port")->as_int()),
                           "--key-id", u->get("key_id")->as_string(), "--key-b64",
                           u->get("key_b64")->as_string(), "--count", "3", "--interval-ms", "20"});
  ASSERT_EQ(hb.exit_code, 0) << hb.err;
  double accepted = 0;
  for (int i = 0; i < 40 && accepted < 3; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    accepted = n.metric("rcan_udp_heartbeats_accepted_total");
  }
  EXPECT_EQ(accepted, 3);
  // Nothing answers on a port with no node: exit 1.
  auto none =
      test::run_cli({"udp-discover", "--host", "127.0.0.1", "--port", "9", "--timeout-ms", "300"});
  EXPECT_EQ(none.exit_code, 1);
  EXPECT_EQ(test::run_cli({"udp-heartbeat", "--port", "1", "--key-id", "zz", "--key-b64", "AA=="})
                .exit_code,
            2);
}

// ---------------------------------------------------------------------------------------------
// Config blocks

constexpr const char* kHead =
    "rcan_version: \"1.2\"\nruri: rcan://local.rcan/rcan/sim-rover/0a1b2c3d\n";

Result<config::NodeConfig> parse_cfg(const std::string& body) {
  config::ConfigOptions o;
  o.default_data_dir = "/var/lib/rcand-test";
  return config::parse_config_text(std::string(kHead) + body, o);
}

TEST(TransportConfig, GrpcAndUdpBlocksAreStrictlyValidated) {
  auto ok = parse_cfg(
      "grpc:\n  enabled: true\n  port: 9443\n  bind: 0.0.0.0\n  max_streams: 8\n"
      "  tls: {enabled: true, cert_file: /etc/rcand/cert.pem, key_file: /etc/rcand/key.pem, "
      "client_ca_file: /etc/rcand/ca.pem}\n"
      "udp:\n  enabled: true\n  port: 8082\n  bind: 0.0.0.0\n  discovery_per_source_per_min: 10\n");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_TRUE(ok->grpc.enabled);
  EXPECT_EQ(ok->grpc.port, 9443);
  EXPECT_EQ(ok->grpc.max_streams, 8u);
  EXPECT_TRUE(ok->grpc.tls.enabled);
  EXPECT_EQ(ok->grpc.client_ca_file, "/etc/rcand/ca.pem");
  EXPECT_TRUE(ok->udp.enabled);
  EXPECT_TRUE(ok->udp.heartbeat);
  EXPECT_EQ(ok->udp.discovery_per_source_per_min, 10u);
  auto def = parse_cfg("");
  ASSERT_TRUE(def.ok());
  EXPECT_FALSE(def->grpc.enabled);
  EXPECT_FALSE(def->udp.enabled);
  struct Bad {
    std::string yaml, field, reason;
  };
  for (const Bad& b : std::vector<Bad>{
           {"grpc:\n  prot: 1\n", "grpc.prot", "unknown_key"},
           {"grpc:\n  port: 70000\n", "grpc.port", "out_of_range"},
           {"grpc:\n  enabled: yes please\n", "grpc.enabled", "wrong_type"},
           {"grpc:\n  tls: {enabled: true, key_file: k.pem}\n", "grpc.tls.cert_file",
            "missing_key"},
           {"grpc:\n  tls: {client_ca_file: ca.pem}\n", "grpc.tls.client_ca_file", "invalid_value"},
           {"grpc:\n  enabled: true\n  port: 8080\n", "grpc.port", "invalid_value"},
           {"udp:\n  enabled: true\n  heartbeat: false\n  discovery: false\n", "udp.enabled",
            "invalid_value"},
           {"udp:\n  discovery_per_source_per_min: 0\n", "udp.discovery_per_source_per_min",
            "out_of_range"},
           {"udp:\n  bind: \"a b\"\n", "udp.bind", "invalid_value"},
       }) {
    auto r = parse_cfg(b.yaml);
    ASSERT_FALSE(r.ok()) << b.yaml;
    EXPECT_EQ(r.error().field, b.field) << b.yaml << r.error().message;
    EXPECT_EQ(r.error().reason, b.reason) << b.yaml << r.error().message;
  }
}

}  // namespace
}  // namespace rcan
