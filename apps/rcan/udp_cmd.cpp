// rcan udp-discover / udp-heartbeat — the node's UDP datagrams (docs/TRANSPORT.md §UDP).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <thread>
#include <vector>

#include "base/clock.h"
#include "cli.h"
#include "rcan/encoding.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "rcan/udp_wire.h"

namespace rcan::cli {
namespace {

constexpr const char* kDiscoverHelp =
    "usage: rcan udp-discover [--host ADDR] [--port N] [--timeout-ms MS]\n"
    "  Sends one DISCOVER datagram to ADDR:N (default 255.255.255.255:8082, broadcast on the\n"
    "  local segment; a unicast address asks one node) and prints each ANNOUNCE received within\n"
    "  the timeout (default 1000 ms) as one JSON line {\"from\":\"ip:port\",\"announce\":{…}}.\n"
    "  The DISCOVER is padded to 1200 bytes: a node never answers with more bytes than it was\n"
    "  sent, and one whose ANNOUNCE is longer says how long a DISCOVER must be; it is then asked\n"
    "  again, alone, with one that long. Exits 0 when at least one node answered, 1 when none\n"
    "  did.\n";

constexpr const char* kHeartbeatHelp =
    "usage: rcan udp-heartbeat --port N --key-id HEX --key-b64 KEY [--host ADDR] [--count N]\n"
    "                          [--interval-ms MS] [--first-seq N]\n"
    "  Keeps a control session's deadman alive: sends COUNT (default 1) HEARTBEAT datagrams,\n"
    "  INTERVAL apart (default 500 ms), with the key of the claim answer's udp_heartbeat object.\n"
    "  Sequence numbers start at FIRST-SEQ (default: the current time in microseconds, so\n"
    "  successive runs keep increasing).\n";

int parse_port(const std::string& s, uint16_t& out) {
  char* end = nullptr;
  long v = std::strtol(s.c_str(), &end, 10);
  if (s.empty() || !end || *end || v < 1 || v > 65535) return 2;
  out = static_cast<uint16_t>(v);
  return 0;
}

bool to_addr(const std::string& host, uint16_t port, sockaddr_in& a) {
  a = sockaddr_in{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  return inet_pton(AF_INET, host.c_str(), &a.sin_addr) == 1;
}

// An ANNOUNCE that only says how long a DISCOVER must be (`payload.discover_size`): asks that
// node again, unicast, with a DISCOVER that long. True when `body` was such an answer.
bool ask_again(int fd, const udp::Nonce& nonce, const sockaddr_in& from, const json::Value& body,
               std::vector<std::string>& asked) {
  const json::Value* p = body.get("payload");
  const json::Value* need = p ? p->get("discover_size") : nullptr;
  if (!need || !need->is_int() || p->get("ruri")) return false;
  std::string who = std::to_string(from.sin_addr.s_addr) + ":" + std::to_string(from.sin_port);
  if (std::find(asked.begin(), asked.end(), who) != asked.end() || asked.size() >= 256) return true;
  asked.push_back(who);
  std::string d = udp::encode_discover_padded(
      nonce, static_cast<size_t>(std::clamp<int64_t>(need->as_int(), 0, udp::kMaxAnnounceSize)));
  (void)::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<const sockaddr*>(&from), sizeof from);
  return true;
}

int discover_main(const Args& args) {
  Options o(args, {"help"}, {"host", "port", "timeout-ms"});
  if (!o.ok()) return usage_error("udp-discover", o.error());
  if (o.has("help")) {
    std::fputs(kDiscoverHelp, stdout);
    return 0;
  }
  uint16_t port = 8082;
  if (o.has("port") && parse_port(o.get("port"), port))
    return usage_error("udp-discover", "--port must be 1..65535");
  std::string host = o.get("host", "255.255.255.255");
  int timeout_ms = std::atoi(o.get("timeout-ms", "1000").c_str());
  if (timeout_ms <= 0 || timeout_ms > 60000)
    return usage_error("udp-discover", "--timeout-ms must be 1..60000");
  sockaddr_in to{};
  if (!to_addr(host, port, to))
    return usage_error("udp-discover", "--host must be an IPv4 address");
  int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return usage_error("udp-discover", "cannot open a UDP socket");
  int on = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_BROADCAST, &on, sizeof on);
  udp::Nonce nonce{};
  random_bytes(nonce.data(), nonce.size());
  std::string d = udp::encode_discover_padded(nonce);
  if (::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to) < 0) {
    ::close(fd);
    std::fprintf(stderr, "rcan udp-discover: cannot send to %s:%u: %s\n", host.c_str(), port,
                 std::strerror(errno));
    return 1;
  }
  int found = 0;
  std::vector<std::string> asked_again;  // each node is asked a second time at most once
  auto until = steady_now() + std::chrono::milliseconds(timeout_ms);
  while (true) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - steady_now()).count();
    if (left <= 0) break;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left)) <= 0) break;
    uint8_t buf[udp::kMaxAnnounceSize + 1];
    sockaddr_in from{};
    socklen_t len = sizeof from;
    ssize_t n = ::recvfrom(fd, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &len);
    if (n <= 0) continue;
    udp::Parsed pr = udp::parse({buf, static_cast<size_t>(n)});
    if (!pr.ok() || pr.d.kind != udp::Kind::kAnnounce || pr.d.nonce != nonce)
      continue;  // not our answer
    auto body = json::parse(pr.d.body, {.max_depth = 16, .max_bytes = udp::kMaxAnnounceSize});
    if (!body.ok()) continue;
    if (ask_again(fd, nonce, from, *body, asked_again)) continue;
    char ip[INET_ADDRSTRLEN] = {0};
    inet_ntop(AF_INET, &from.sin_addr, ip, sizeof ip);
    json::Object line{{"from", std::string(ip) + ":" + std::to_string(ntohs(from.sin_port))},
                      {"announce", *body}};
    std::cout << json::dump(json::Value(line)) << "\n" << std::flush;
    ++found;
  }
  ::close(fd);
  return found > 0 ? 0 : 1;
}

int heartbeat_main(const Args& args) {
  Options o(args, {"help"},
            {"host", "port", "key-id", "key-b64", "count", "interval-ms", "first-seq"});
  if (!o.ok()) return usage_error("udp-heartbeat", o.error());
  if (o.has("help")) {
    std::fputs(kHeartbeatHelp, stdout);
    return 0;
  }
  uint16_t port = 0;
  if (parse_port(o.get("port"), port))
    return usage_error("udp-heartbeat", "--port must be 1..65535");
  auto id = from_hex(o.get("key-id"));
  auto key = base64_decode(o.get("key-b64"));
  if (!id || id->size() != udp::kKeyIdSize)
    return usage_error("udp-heartbeat", "--key-id must be 32 hex digits");
  if (!key || key->size() != udp::kKeySize)
    return usage_error("udp-heartbeat", "--key-b64 must hold 32 bytes");
  long count = std::atol(o.get("count", "1").c_str());
  long interval = std::atol(o.get("interval-ms", "500").c_str());
  if (count < 1 || interval < 1)
    return usage_error("udp-heartbeat", "--count and --interval-ms must be positive");
  uint64_t seq = o.has("first-seq") ? std::strtoull(o.get("first-seq").c_str(), nullptr, 10)
                                    : static_cast<uint64_t>(unix_us());
  sockaddr_in to{};
  if (!to_addr(o.get("host", "127.0.0.1"), port, to))
    return usage_error("udp-heartbeat", "--host must be an IPv4 address");
  udp::KeyId kid{};
  udp::Key k{};
  std::memcpy(kid.data(), id->data(), kid.size());
  std::memcpy(k.data(), key->data(), k.size());
  secure_wipe(key->data(), key->size());
  int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return usage_error("udp-heartbeat", "cannot open a UDP socket");
  int rc = 0;
  for (long i = 0; i < count; ++i) {
    auto hb = udp::encode_heartbeat(kid, seq + static_cast<uint64_t>(i), k);
    if (::sendto(fd, hb.data(), hb.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to) < 0)
      rc = 1;
    if (i + 1 < count) std::this_thread::sleep_for(std::chrono::milliseconds(interval));
  }
  secure_wipe(k.data(), k.size());
  ::close(fd);
  return rc;
}

const Registration kDiscoverReg{
    "udp-discover", "find nodes with a UDP DISCOVER (broadcast or unicast)", &discover_main};
const Registration kHeartbeatReg{
    "udp-heartbeat", "send authenticated UDP heartbeats for a control session", &heartbeat_main};

}  // namespace
}  // namespace rcan::cli
