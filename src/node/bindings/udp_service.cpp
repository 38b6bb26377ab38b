// UDP service: heartbeats and discovery (udp_service.h, docs/TRANSPORT.md §UDP).
#include "node/bindings/udp_service.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>
#include <unordered_map>

#include "base/thread_annotations.h"
#include "node/services/node_services.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/udp_wire.h"
#include "runtime/log.h"

namespace rcan::node {

namespace {

struct Counters {
  std::atomic<uint64_t> hb_ok{0}, hb_forged{0}, hb_replayed{0}, hb_stale{0}, malformed{0},
      disc_ok{0}, disc_limited{0}, disc_short{0};
};

struct KeyEntry {
  std::string session_id;
  udp::Key key{};
  uint64_t last_seq = 0;
  bool audited = false;
};

struct Bucket {
  double tokens = 0;
  int64_t last_ms = 0;
};

// Refills `b` at `per_s` tokens per second up to `cap` and takes one if it can.
bool take(Bucket& b, int64_t now_ms, double per_s, double cap) {
  if (b.last_ms == 0) {
    b.tokens = cap;
  } else {
    b.tokens = std::min(cap, b.tokens + static_cast<double>(now_ms - b.last_ms) * per_s / 1000.0);
  }
  b.last_ms = now_ms;
  if (b.tokens < 1.0) return false;
  b.tokens -= 1.0;
  return true;
}

std::string addr_ip(const sockaddr_storage& ss) {
  char buf[INET6_ADDRSTRLEN] = {0};
  if (ss.ss_family == AF_INET)
    inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in&>(ss).sin_addr, buf, sizeof buf);
  else if (ss.ss_family == AF_INET6)
    inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6&>(ss).sin6_addr, buf, sizeof buf);
  return buf;
}

}  // namespace

struct UdpService::Impl {
  Impl(UdpOptions o, NodeServices& s) : opt(std::move(o)), svc(s) {}
  UdpOptions opt;
  NodeServices& svc;
  int fd = -1;
  uint16_t port = 0;
  std::thread thread;
  std::atomic<bool> running{false};
  std::shared_ptr<Counters> counters = std::make_shared<Counters>();

  Mutex mu;
  std::map<udp::KeyId, KeyEntry> keys GUARDED_BY(mu);
  std::map<std::string, udp::KeyId> by_session GUARDED_BY(mu);
  std::unordered_map<std::string, Bucket> buckets GUARDED_BY(mu);
  Bucket global GUARDED_BY(mu);
  int64_t last_sweep_ms = 0;  // the receive thread's

  void loop() EXCLUDES(mu);
  void on_datagram(const uint8_t* data, size_t n, const sockaddr_storage& from, socklen_t from_len)
      EXCLUDES(mu);
  void heartbeat(std::span<const uint8_t> bytes, const udp::Datagram& d) EXCLUDES(mu);
  void discover(const udp::Datagram& d, const sockaddr_storage& from, socklen_t from_len)
      EXCLUDES(mu);
  void sweep() EXCLUDES(mu);
  json::Object grant(const std::string& session_id) EXCLUDES(mu);
};

void UdpService::Impl::loop() {
  std::array<uint8_t, 2048> buf{};
  while (running.load()) {
    pollfd pfd{fd, POLLIN, 0};
    int r = ::poll(&pfd, 1, 200);
    if (r > 0 && (pfd.revents & POLLIN)) {
      for (int i = 0; i < 64; ++i) {  // drain what is there, then look at the clock
        sockaddr_storage from{};
        socklen_t len = sizeof from;
        ssize_t n = ::recvfrom(fd, buf.data(), buf.size(), MSG_DONTWAIT,
                               reinterpret_cast<sockaddr*>(&from), &len);
        if (n < 0) break;
        on_datagram(buf.data(), static_cast<size_t>(n), from, len);
      }
    }
    int64_t now = svc.clock.mono_ms();
    if (now - last_sweep_ms >= 1000) {
      last_sweep_ms = now;
      sweep();
    }
  }
}

void UdpService::Impl::on_datagram(const uint8_t* data, size_t n, const sockaddr_storage& from,
                                   socklen_t from_len) {
  std::span<const uint8_t> bytes(data, n);
  udp::Parsed p = udp::parse(bytes);
  if (!p.ok()) {
    counters->malformed.fetch_add(1);
    return;
  }
  if (p.d.kind == udp::Kind::kHeartbeat && opt.heartbeat) return heartbeat(bytes, p.d);
  if (p.d.kind == udp::Kind::kDiscover && opt.discovery) return discover(p.d, from, from_len);
  counters->malformed.fetch_add(1);  // an ANNOUNCE, or a kind this node has switched off
}

void UdpService::Impl::heartbeat(std::span<const uint8_t> bytes, const udp::Datagram& d) {
  std::string session_id;
  bool first = false;
  uint64_t seq = d.seq;
  {
    MutexLock lock(mu);
    auto it = keys.find(d.key_id);
    if (it == keys.end() || !udp::verify_heartbeat(bytes, it->second.key)) {
      counters->hb_forged.fetch_add(1);
      return;
    }
    if (d.seq <= it->second.last_seq) {
      counters->hb_replayed.fetch_add(1);
      return;
    }
    it->second.last_seq = d.seq;
    session_id = it->second.session_id;
    first = !it->second.audited;
  }
  auto session = svc.control.sessions().find(session_id, svc.clock.mono_ms());
  if (!session) {
    counters->hb_stale.fetch_add(1);
    MutexLock lock(mu);
    keys.erase(d.key_id);
    by_session.erase(session_id);
    return;
  }
  svc.act.feed_deadman(session_id);
  counters->hb_ok.fetch_add(1);
  if (first) {
    {
      MutexLock lock(mu);
      if (auto it = keys.find(d.key_id); it != keys.end()) it->second.audited = true;
    }
    // The first heartbeat of a key is audited; later ones are counted (rcan_udp_heartbeats_*).
    svc.trail.record("HEARTBEAT")
        .by_subject(session->sub)
        .detail("transport", "udp")
        .detail("route", "udp/heartbeat")
        .detail("session_id", session_id)
        .detail("udp_seq", static_cast<int64_t>(seq & 0x7fffffffffffffffULL))
        .detail("first", true)
        .write();
  }
}

void UdpService::Impl::discover(const udp::Datagram& d, const sockaddr_storage& from,
                                socklen_t from_len) {
  int64_t now = svc.clock.mono_ms();
  std::string ip = addr_ip(from);
  bool allowed;
  {
    MutexLock lock(mu);
    if (buckets.size() >= 4096 && !buckets.count(ip)) {
      for (auto it = buckets.begin(); it != buckets.end();)
        it = now - it->second.last_ms > 60'000 ? buckets.erase(it) : std::next(it);
    }
    double per_min = opt.discovery_per_source_per_min;
    allowed = buckets.size() < 4096 || buckets.count(ip);
    allowed = allowed && take(global, now, opt.discovery_global_per_s, opt.discovery_global_per_s);
    if (allowed)
      allowed = take(buckets[ip], now, per_min / 60.0, std::max(1.0, std::min(per_min, 5.0)));
  }
  if (!allowed) {
    counters->disc_limited.fetch_add(1);
    return;
  }
  json::Object info = svc.discovery_info().as_object();
  info.set("udp_port", static_cast<int64_t>(port));
  std::string body = json::dump(svc.envelope(MessageType::kAnnounce, std::move(info)));
  std::string out = udp::encode_announce(d.nonce, body);
  if (out.size() > udp::kMaxAnnounceSize) return;
  const bool full = out.size() <= d.size;
  if (!full) {
    // No amplification: the answer is never longer than the question. A DISCOVER too short for
    // the record learns how long one must be, if even that fits; else it gets nothing.
    counters->disc_short.fetch_add(1);
    json::Object need{{"discover_size", static_cast<int64_t>(out.size())}};
    out = udp::encode_announce(
        d.nonce, json::dump(json::Value(json::Object{{"type", "ANNOUNCE"}, {"payload", need}})));
    if (out.size() > d.size) return;
  }
  if (::sendto(fd, out.data(), out.size(), 0, reinterpret_cast<const sockaddr*>(&from), from_len) >=
          0 &&
      full)
    counters->disc_ok.fetch_add(1);
}

void UdpService::Impl::sweep() {
  std::vector<std::pair<udp::KeyId, std::string>> all;
  {
    MutexLock lock(mu);
    for (const auto& [id, k] : keys) all.emplace_back(id, k.session_id);
  }
  int64_t now = svc.clock.mono_ms();
  for (const auto& [id, sid] : all) {
    if (svc.control.sessions().find(sid, now)) continue;
    MutexLock lock(mu);
    keys.erase(id);
    if (auto it = by_session.find(sid); it != by_session.end() && it->second == id)
      by_session.erase(it);
  }
}

json::Object UdpService::Impl::grant(const std::string& session_id) {
  udp::KeyId id{};
  udp::Key key{};
  if (!random_bytes(id.data(), id.size()) || !random_bytes(key.data(), key.size())) return {};
  {
    MutexLock lock(mu);
    if (auto it = by_session.find(session_id); it != by_session.end()) keys.erase(it->second);
    KeyEntry e;
    e.session_id = session_id;
    e.key = key;
    keys[id] = e;
    by_session[session_id] = id;
  }
  int64_t interval = std::max<int64_t>(50, svc.settings.heartbeat_timeout_ms / 4);
  json::Object o{{"port", static_cast<int64_t>(port)},
                 {"session_id", session_id},
                 {"key_id", to_hex(id.data(), id.size())},
                 {"key_b64", base64_encode(key.data(), key.size())},
                 {"interval_ms", interval},
                 {"format", "rcan-udp-heartbeat-v1"}};
  secure_wipe(key.data(), key.size());
  return o;
}

UdpService::UdpService(UdpOptions opt, NodeServices& svc)
    : impl_(std::make_shared<Impl>(std::move(opt), svc)) {}

UdpService::~UdpService() { stop(); }

Result<uint16_t> UdpService::start() {
  Impl& im = *impl_;
  bool v6 = im.opt.bind_address.find(':') != std::string::npos;
  int fd = ::socket(v6 ? AF_INET6 : AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0)
    return Error(ErrorCode::kInternal, std::string("udp socket: ") + std::strerror(errno));
  sockaddr_storage ss{};
  socklen_t len = 0;
  if (v6) {
    auto& a = reinterpret_cast<sockaddr_in6&>(ss);
    a.sin6_family = AF_INET6;
    a.sin6_port = htons(im.opt.port);
    if (inet_pton(AF_INET6, im.opt.bind_address.c_str(), &a.sin6_addr) != 1) {
      ::close(fd);
      return Error(ErrorCode::kInternal, "udp.bind: not an IPv6 address: " + im.opt.bind_address);
    }
    len = sizeof a;
  } else {
    auto& a = reinterpret_cast<sockaddr_in&>(ss);
    a.sin_family = AF_INET;
    a.sin_port = htons(im.opt.port);
    if (inet_pton(AF_INET, im.opt.bind_address.c_str(), &a.sin_addr) != 1) {
      ::close(fd);
      return Error(ErrorCode::kInternal, "udp.bind: not an IPv4 address: " + im.opt.bind_address);
    }
    len = sizeof a;
  }
  if (::bind(fd, reinterpret_cast<sockaddr*>(&ss), len) != 0) {
    std::string why = std::strerror(errno);
    ::close(fd);
    return Error(ErrorCode::kInternal, "cannot bind udp " + im.opt.bind_address + ":" +
                                           std::to_string(im.opt.port) + ": " + why);
  }
  sockaddr_storage bound{};
  socklen_t blen = sizeof bound;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&bound), &blen);
  im.port = ntohs(v6 ? reinterpret_cast<sockaddr_in6&>(bound).sin6_port
                     : reinterpret_cast<sockaddr_in&>(bound).sin_port);
  im.fd = fd;

  auto c = im.counters;
  auto& m = im.svc.metrics;
  m.add_counter_fn("rcan_udp_heartbeats_accepted_total",
                   "UDP heartbeats that fed a session's deadman.",
                   [c] { return static_cast<double>(c->hb_ok.load()); });
  m.add_counter_fn("rcan_udp_heartbeats_forged_total",
                   "UDP heartbeats with an unknown key id or a bad HMAC.",
                   [c] { return static_cast<double>(c->hb_forged.load()); });
  m.add_counter_fn("rcan_udp_heartbeats_replayed_total",
                   "UDP heartbeats whose sequence number was not new.",
                   [c] { return static_cast<double>(c->hb_replayed.load()); });
  m.add_counter_fn("rcan_udp_heartbeats_stale_total",
                   "Valid UDP heartbeats for a session that had ended.",
                   [c] { return static_cast<double>(c->hb_stale.load()); });
  m.add_counter_fn("rcan_udp_malformed_total",
                   "UDP datagrams that are not ours or of a kind switched off.",
                   [c] { return static_cast<double>(c->malformed.load()); });
  m.add_counter_fn("rcan_udp_discover_answered_total", "DISCOVER datagrams answered with ANNOUNCE.",
                   [c] { return static_cast<double>(c->disc_ok.load()); });
  m.add_counter_fn("rcan_udp_discover_limited_total",
                   "DISCOVER datagrams dropped by the rate limits.",
                   [c] { return static_cast<double>(c->disc_limited.load()); });
  m.add_counter_fn("rcan_udp_discover_short_total",
                   "DISCOVER datagrams too short for the ANNOUNCE (answered with the size needed, "
                   "or not at all).",
                   [c] { return static_cast<double>(c->disc_short.load()); });
  if (im.opt.heartbeat) {
    std::weak_ptr<Impl> weak = impl_;
    im.svc.control.set_on_grant([weak](const std::string& session_id, json::Object& payload) {
      if (auto i = weak.lock(); i && i->running.load())
        payload.set("udp_heartbeat", i->grant(session_id));
    });
  }
  im.running.store(true);
  im.thread = std::thread([&im] {
    pthread_setname_np(pthread_self(), "udp");
    im.loop();
  });
  log(LogLevel::kInfo, "udp.listening",
      json::Object{{"address", im.opt.bind_address},
                   {"port", static_cast<int64_t>(im.port)},
                   {"heartbeat", im.opt.heartbeat},
                   {"discovery", im.opt.discovery}});
  return im.port;
}

void UdpService::stop() {
  Impl& im = *impl_;
  if (!im.running.exchange(false)) return;
  if (im.thread.joinable()) im.thread.join();
  if (im.fd >= 0) ::close(im.fd);
  im.fd = -1;
  MutexLock lock(im.mu);
  for (auto& [id, k] : im.keys) secure_wipe(k.key.data(), k.key.size());
  im.keys.clear();
  im.by_session.clear();
}

UdpStats UdpService::stats() const {
  const Counters& c = *impl_->counters;
  return UdpStats{c.hb_ok.load(),     c.hb_forged.load(), c.hb_replayed.load(), c.hb_stale.load(),
                  c.malformed.load(), c.disc_ok.load(),   c.disc_limited.load()};
}

json::Object UdpService::grant(const std::string& session_id) { return impl_->grant(session_id); }

}  // namespace rcan::node
