// HttpServer: Boost.Beast HTTP/1.1 + WebSocket over one io_context.
//
// Shape (Beast's advanced server, with C++20 coroutines):
//   Impl::accept_loop      accepts; admit() counts it per address and against
//                          max_connections — over either, the oldest connection that never
//                          authenticated and waits for a request is closed to make room, else
//                          the reserve (for a stop); refused → reject() writes 503 and closes
//   Conn<Stream>::serve    per connection, on its own strand:
//                            [TLS handshake] → loop { idle wait → serve_one() } → close
//   Conn<Stream>::serve_one  read one request under the read deadline (read_header checks
//                            the framing, http_parse.h) → limits/errors →
//                            handler → wait for respond() → write → keep-alive?
//   Conn<Stream>::serve_websocket  node's open() → accept → read loop; pump() writes the
//                            sink's queue, then the close frame
// Stream is beast::tcp_stream or beast::ssl_stream<beast::tcp_stream> (TLS).
#include "transport/http_server.h"

// GCC 12 at -O3 reports -Wnull-dereference from inside Asio's scheduler and libstdc++'s
// shared_ptr once they are inlined into this file; those are middle-end false positives that
// `#pragma GCC system_header` (transport/beast.h) does not silence. Off for this file only.
#pragma GCC diagnostic ignored "-Wnull-dereference"

#include <pthread.h>
#include <sys/ioctl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <ctime>
#include <deque>
#include <exception>
#include <optional>
#include <set>
#include <thread>
#include <type_traits>
#include <unordered_map>
#include <utility>
#include <vector>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "runtime/log.h"
#include "transport/beast.h"
#include "transport/http_parse.h"

namespace rcan::transport {
namespace beast = boost::beast;
namespace detail {

namespace asio = boost::asio;
namespace websocket = boost::beast::websocket;
namespace ssl = boost::asio::ssl;
using tcp = boost::asio::ip::tcp;
using SteadyClock = std::chrono::steady_clock;
using Ms = std::chrono::milliseconds;

constexpr auto kNoThrow = asio::as_tuple(asio::use_awaitable);
constexpr std::string_view kServerName = "rcand";
// Lingering close after an error answer (nginx's lingering_close): the server half-closes and
// reads and discards what the client still sends — a client that writes its whole body before
// reading (Python's http.client) then reads the 413 instead of a broken pipe. Bounded in bytes,
// in total time and by a pause in the client's sending.
constexpr size_t kLingerBytes = 64 * 1024 * 1024;
constexpr int kLingerMs = 1000;        // the longest pause in the client's sending
constexpr int kLingerTotalMs = 10000;  // the longest lingering close
constexpr int kRejectTimeoutMs = 500;
constexpr int kMaxConcurrentRejects = 64;
// Reserve connections (over max_connections, for a stop) one address may hold at once: an
// attacker holding its per-address share of ordinary slots gets none, and many addresses
// together take at most two each.
constexpr size_t kReservePerAddress = 2;
constexpr std::string_view kQueueFullReason = "send queue limit exceeded";

using PlainStream = beast::tcp_stream;
using TlsStream = beast::ssl_stream<beast::tcp_stream>;

// The Date header changes once a second: formatted once per second per thread.
inline std::string http_date() {
  thread_local std::time_t cached_t = -1;
  thread_local std::string cached;
  const std::time_t t = static_cast<std::time_t>(unix_seconds());
  if (t != cached_t) {
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[64];
    const size_t n = std::strftime(buf, sizeof buf, "%a, %d %b %Y %H:%M:%S GMT", &tm);
    cached.assign(buf, n);
    cached_t = t;
  }
  return cached;
}

inline std::string endpoint_string(const tcp::endpoint& ep) {
  auto addr = ep.address();
  if (addr.is_v6() && addr.to_v6().is_v4_mapped())
    addr = asio::ip::make_address_v4(asio::ip::v4_mapped, addr.to_v6());
  if (addr.is_v6()) return "[" + addr.to_string() + "]:" + std::to_string(ep.port());
  return addr.to_string() + ":" + std::to_string(ep.port());
}

// The address a connection is counted under for max_connections_per_address: the IP without
// the port (IPv4-mapped IPv6 as IPv4).
inline std::string address_key(const tcp::endpoint& ep) {
  auto addr = ep.address();
  if (addr.is_v6() && addr.to_v6().is_v4_mapped())
    addr = asio::ip::make_address_v4(asio::ip::v4_mapped, addr.to_v6());
  return addr.to_string();
}

inline bool is_token_char(char c) {
  if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9')) return true;
  return std::string_view("!#$%&'*+-.^_`|~").find(c) != std::string_view::npos;
}

inline bool valid_header(std::string_view name, std::string_view value) {
  if (name.empty()) return false;
  for (char c : name)
    if (!is_token_char(c)) return false;
  for (char c : value)
    if (c == '\r' || c == '\n' || c == '\0') return false;
  return true;
}

// Headers the transport owns; a handler's copies are dropped.
inline bool reserved_header(std::string_view name) {
  const std::string n = ascii_lower(name);
  return n == "content-length" || n == "connection" || n == "transfer-encoding" ||
         n == "content-type" || n == "date" || n == "upgrade" || n == "keep-alive";
}

// A WebSocket close reason fits in 123 bytes; cut at a UTF-8 boundary.
inline std::string close_reason_text(std::string s) {
  if (s.size() <= 123) return s;
  size_t n = 123;
  while (n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0) == 0x80) --n;
  s.resize(n);
  return s;
}

// The response as written: the handler's answer plus the transport's headers.
// The response as written, status line to body: the handler's answer plus the transport's
// headers, serialised here in one buffer (cheaper than Beast's fields and serializer, and
// written with a single write).
inline std::string response_bytes(HttpResponse r, unsigned version, bool head, bool keep_alive) {
  if (r.status < 200 || r.status > 599) {
    rcan::log(LogLevel::kError, "http.bad_handler_status", {{"status", r.status}});
    r.status = 500;
    r.content_type = "application/json";
    r.body = error_json({500, ErrorCode::kInternal, "bad_status", "internal error"});
    r.headers.clear();
  }
  const bool no_body = r.status == 204 || r.status == 304;
  const std::string date = http_date();
  const std::string_view reason =
      http::obsolete_reason(http::int_to_status(static_cast<unsigned>(r.status)));
  std::string out;
  out.reserve(192 + r.body.size() + r.content_type.size());
  out += version == 10 ? "HTTP/1.0 " : "HTTP/1.1 ";
  out += std::to_string(r.status);
  out += ' ';
  out += reason;
  out += "\r\nServer: ";
  out += kServerName;
  out += "\r\nDate: ";
  out += date;
  out += "\r\n";
  bool cache_control = false;
  for (const auto& [name, value] : r.headers) {
    if (!valid_header(name, value) || reserved_header(name)) {
      rcan::log(LogLevel::kDebug, "http.header_dropped", {{"name", name}});
      continue;
    }
    if (beast::iequals(name, "cache-control")) cache_control = true;
    out += name;
    out += ": ";
    out += value;
    out += "\r\n";
  }
  if (!no_body) {
    if (!r.content_type.empty() && valid_header("content-type", r.content_type)) {
      out += "Content-Type: ";
      out += r.content_type;
      out += "\r\n";
    }
    out += "Content-Length: ";
    out += std::to_string(r.body.size());
    out += "\r\n";
  }
  out += "X-Content-Type-Options: nosniff\r\n";
  if (!cache_control) out += "Cache-Control: no-store\r\n";
  out += keep_alive ? "Connection: keep-alive\r\n\r\n" : "Connection: close\r\n\r\n";
  if (!head && !no_body) out += r.body;
  return out;
}

inline HttpResponse error_response(const TransportError& err) {
  HttpResponse r;
  r.status = err.status;
  r.body = error_json(err);
  if (err.status == 426) r.headers.emplace_back("Sec-WebSocket-Version", "13");
  if (err.status == 503) r.headers.emplace_back("Retry-After", "1");
  return r;
}

// A connection, as the server sees it for shutdown. Both calls are thread-safe (they post).
class ConnBase {
 public:
  virtual ~ConnBase() = default;
  // Stop after the current request: close now if idle, 1001 for a WebSocket.
  virtual void begin_shutdown() = 0;
  // Close the socket now; pending waits end.
  virtual void force_close() = 0;
};

// The one `respond` of one request. Fires at most once; when the handler drops it unanswered
// the request is answered 500 so the connection never hangs. It holds no executor: a handler
// may keep it past the server's life, and an executor (a strand) must not be destroyed after
// its io_context. `post` runs only while the server is alive and posts to the connection.
class ResponseSlot {
 public:
  ResponseSlot(std::weak_ptr<HttpServer::Impl> srv, std::function<void(HttpResponse)> post)
      : srv_(std::move(srv)), post_(std::move(post)) {}
  ResponseSlot(const ResponseSlot&) = delete;
  ResponseSlot& operator=(const ResponseSlot&) = delete;
  ~ResponseSlot() {
    bool answered;
    {
      MutexLock lock(mu_);
      answered = done_;
    }
    if (!answered) {
      rcan::log(LogLevel::kError, "http.handler_dropped_response");
      fire(error_response({500, ErrorCode::kInternal, "no_response", "internal error"}));
    }
  }
  void fire(HttpResponse r) {
    {
      MutexLock lock(mu_);
      if (done_) return;
      done_ = true;
    }
    // Holding the server keeps the io_context alive while posting to it.
    auto srv = srv_.lock();
    if (!srv) return;
    post_(std::move(r));
  }

 private:
  Mutex mu_;
  bool done_ GUARDED_BY(mu_) = false;
  std::weak_ptr<HttpServer::Impl> srv_;
  std::function<void(HttpResponse)> post_;
};

// The transport's StreamSink: a bounded queue the connection's strand drains.
class WsSink final : public StreamSink {
 public:
  using Kick = std::function<void()>;
  using Closer = std::function<void(uint16_t, std::string, bool overflow)>;
  WsSink(std::string remote, size_t limit, Kick kick, Closer closer)
      : remote_(std::move(remote)),
        limit_(limit),
        kick_(std::move(kick)),
        closer_(std::move(closer)) {}

  bool send_text(std::string text) override {
    enum class Outcome { kQueued, kQueuedKick, kOverflow } outcome;
    {
      MutexLock lock(mu_);
      if (closed_) return false;
      if (queue_.size() >= limit_) {
        closed_ = true;
        close_requested_ = true;
        queue_.clear();
        outcome = Outcome::kOverflow;
      } else {
        queue_.push_back(std::move(text));
        outcome = kick_posted_ ? Outcome::kQueued : Outcome::kQueuedKick;
        kick_posted_ = true;
      }
    }
    if (outcome == Outcome::kOverflow) {
      closer_(1008, std::string(kQueueFullReason), true);
      return false;
    }
    if (outcome == Outcome::kQueuedKick) kick_();
    return true;
  }

  void close(uint16_t code, std::string reason) override {
    {
      MutexLock lock(mu_);
      if (close_requested_) return;
      close_requested_ = true;
      closed_ = true;  // frames already queued still go out before the close frame
    }
    closer_(code, std::move(reason), false);
  }

  const std::string& remote_addr() const override { return remote_; }

  // Connection side (strand).
  bool pop(std::string& out) {
    MutexLock lock(mu_);
    if (queue_.empty()) {
      kick_posted_ = false;
      return false;
    }
    out = std::move(queue_.front());
    queue_.pop_front();
    return true;
  }
  void mark_closed(bool drop_queue) {
    MutexLock lock(mu_);
    closed_ = true;
    close_requested_ = true;
    if (drop_queue) queue_.clear();
  }

 private:
  const std::string remote_;
  const size_t limit_;
  Kick kick_;
  Closer closer_;
  Mutex mu_;
  std::deque<std::string> queue_ GUARDED_BY(mu_);
  bool closed_ GUARDED_BY(mu_) = false;
  bool close_requested_ GUARDED_BY(mu_) = false;
  bool kick_posted_ GUARDED_BY(mu_) = false;
};

}  // namespace detail

class HttpServer::Impl : public std::enable_shared_from_this<HttpServer::Impl> {
 public:
  Impl(ServerOptions o, HttpHandler& h, StreamHandler& s)
      : opt(std::move(o)), http(h), streams(s), ioc(std::max(opt.io_threads, 1)) {}

  Result<uint16_t> start() EXCLUDES(lifecycle_mu, mu);
  void stop(int drain_ms) EXCLUDES(lifecycle_mu, mu);
  ServerStats stats() const EXCLUDES(mu);

  detail::asio::awaitable<void> accept_loop();
  detail::asio::awaitable<void> reject(detail::tcp::socket sock, detail::TransportError err);
  template <class Stream>
  void spawn_conn(detail::tcp::socket sock, std::string remote, std::string addr, bool reserve)
      EXCLUDES(mu);

  // Where a new connection from `addr` goes: an ordinary slot, the reserve, or nowhere. Over
  // max_connections_per_address, or over max_connections, the oldest evictable connection (never
  // authenticated, waiting for a request: mark_idle) — of that address, or of any — is closed and
  // its slot taken (docs/TRANSPORT.md "Connection limits"): a client cannot hold slots with idle
  // connections against one that comes to send a request, and cannot evict one that presented a
  // credential. With nothing to evict, the reserve (at most kReservePerAddress per address) takes
  // it for a stop. Counts it when taken.
  enum class Admit { kOrdinary, kReserve, kPerAddress, kFull };
  struct Admission {
    Admit admit = Admit::kFull;
    bool over_address = false;                       // the reserve taken over the per-address limit
    bool evicted = false;                            // a connection was evicted for it
    std::shared_ptr<detail::ConnBase> evicted_conn;  // to close (its slot is handed over already)
    std::string evicted_remote;
  };
  Admission admit(const std::string& addr) EXCLUDES(mu) {
    MutexLock lock(mu);
    Admission out;
    auto it = per_address.find(addr);
    const PerAddress have = it == per_address.end() ? PerAddress{} : it->second;
    const bool reserve_room =
        reserve_open < opt.reserved_connections && have.reserve < detail::kReservePerAddress;
    if (opt.max_connections_per_address != 0 && have.total >= opt.max_connections_per_address) {
      if (!evict_oldest_idle(&addr, out)) {
        if (!reserve_room) {
          out.admit = Admit::kPerAddress;
          return out;
        }
        out.over_address = true;
      }
    } else if (ordinary_open >= opt.max_connections) {
      evict_oldest_idle(nullptr, out);
    }
    if (!out.over_address && ordinary_open < opt.max_connections) {
      ++ordinary_open;
      out.admit = Admit::kOrdinary;
    } else if (reserve_room) {
      ++reserve_open;
      out.admit = Admit::kReserve;
    } else {
      out.admit = Admit::kFull;
      return out;
    }
    PerAddress& slot = per_address[addr];
    ++slot.total;
    if (out.admit == Admit::kReserve) ++slot.reserve;
    return out;
  }
  // Closes (through `out`) the oldest idle connection, of `addr` when given, and hands its
  // ordinary slot over now: the connection no longer counts, though it ends a moment later.
  bool evict_oldest_idle(const std::string* addr, Admission& out) REQUIRES(mu) {
    for (auto i = idle.begin(); i != idle.end(); ++i) {
      ConnEntry& e = conns.at(*i);
      if (addr != nullptr && e.addr != *addr) continue;
      // A request's first bytes are waiting for the connection's strand: not idle any more.
      int pending = 0;
      if (e.fd >= 0 && ::ioctl(e.fd, FIONREAD, &pending) == 0 && pending > 0) continue;
      e.evicted = true;
      idle.erase(i);
      release_slot(e.addr, false);
      out.evicted = true;
      out.evicted_conn = e.conn.lock();  // null when it is ending already
      out.evicted_remote = e.remote;
      return true;
    }
    return false;
  }
  void release_slot(const std::string& addr, bool reserve) REQUIRES(mu) {
    if (reserve) {
      --reserve_open;
    } else {
      --ordinary_open;
    }
    auto it = per_address.find(addr);
    if (it != per_address.end()) {
      if (reserve && it->second.reserve > 0) --it->second.reserve;
      if (--it->second.total == 0) per_address.erase(it);
    }
  }
  // A connection that never authenticated starts (true) or ends (false) waiting for a request:
  // only then may admit() evict it. False when it was evicted meanwhile: it must close, its slot
  // belongs to another connection now.
  bool mark_idle(uint64_t id, bool waiting) EXCLUDES(mu) {
    MutexLock lock(mu);
    auto it = conns.find(id);
    if (it == conns.end() || it->second.evicted) return false;
    if (waiting) {
      idle.insert(id);
    } else {
      idle.erase(id);
    }
    return true;
  }
  void conn_gone(uint64_t id) EXCLUDES(mu) {
    {
      MutexLock lock(mu);
      --connections_open;
      idle.erase(id);
      auto it = conns.find(id);
      if (it != conns.end()) {
        if (!it->second.evicted) release_slot(it->second.addr, it->second.reserve);
        conns.erase(it);
      }
    }
    cv.notify_all();
  }
  std::vector<std::shared_ptr<detail::ConnBase>> snapshot() EXCLUDES(mu) {
    std::vector<std::shared_ptr<detail::ConnBase>> out;
    MutexLock lock(mu);
    for (auto& [id, e] : conns)
      if (auto c = e.conn.lock()) out.push_back(std::move(c));
    return out;
  }

  const ServerOptions opt;
  HttpHandler& http;
  StreamHandler& streams;

  std::atomic<bool> stopping{false};
  std::atomic<uint64_t> connections_open{0};
  std::atomic<uint64_t> connections_total{0};
  std::atomic<uint64_t> ws_streams_open{0};
  std::atomic<uint64_t> ws_streams_total{0};
  std::atomic<uint64_t> requests_total{0};
  std::atomic<uint64_t> rejected_connections{0};
  std::atomic<uint64_t> rejected_per_address{0};
  std::atomic<uint64_t> reserve_connections{0};
  std::atomic<uint64_t> reserve_refused{0};
  std::atomic<uint64_t> evicted_idle{0};
  std::atomic<uint64_t> rejected_limits{0};
  std::atomic<uint64_t> bad_requests{0};
  std::atomic<int> rejecting{0};

  mutable Mutex mu;
  CondVar cv;  // signalled when a connection or an I/O thread ends
  struct ConnEntry {
    std::weak_ptr<detail::ConnBase> conn;
    std::string addr;  // counted under (max_connections_per_address)
    std::string remote;
    int fd = -1;  // the socket, for the bytes waiting in it (evict_oldest_idle)
    bool reserve = false;
    bool evicted = false;  // closed by admit(): its slot was handed over
  };
  std::unordered_map<uint64_t, ConnEntry> conns GUARDED_BY(mu);
  // Connections admit() may evict, by id: the oldest first.
  std::set<uint64_t> idle GUARDED_BY(mu);
  uint64_t next_id GUARDED_BY(mu) = 0;
  struct PerAddress {
    size_t total = 0;    // open connections from the address, ordinary and reserve
    size_t reserve = 0;  // of which from the reserve
  };
  std::unordered_map<std::string, PerAddress> per_address GUARDED_BY(mu);
  size_t ordinary_open GUARDED_BY(mu) = 0;
  size_t reserve_open GUARDED_BY(mu) = 0;
  int running_threads GUARDED_BY(mu) = 0;

  Mutex lifecycle_mu;
  bool started GUARDED_BY(lifecycle_mu) = false;
  bool stopped GUARDED_BY(lifecycle_mu) = false;
  std::vector<std::thread> threads;

  // Declared after everything connections touch, so that it is destroyed first (frames still
  // suspended in it are destroyed with it and may update the counters above).
  std::unique_ptr<detail::ssl::context> ssl_ctx;
  // Concurrency hint = io_threads. (A hint of 1 tells asio that one thread runs it: it then
  // keeps work posted from an I/O thread on that thread and never wakes the other for it.)
  detail::asio::io_context ioc;
  std::optional<detail::tcp::acceptor> acceptor;  // destroyed before ioc
};

namespace detail {

// The keep-alive wait of a connection not (yet) answered as authenticated.
inline int short_idle_ms(const ServerOptions& o) {
  return std::min(o.unauthenticated_idle_timeout_ms, o.idle_timeout_ms);
}

template <class Stream>
Stream make_stream(HttpServer::Impl& srv, tcp::socket&& sock);
template <>
inline PlainStream make_stream<PlainStream>(HttpServer::Impl&, tcp::socket&& sock) {
  return PlainStream(std::move(sock));
}
template <>
inline TlsStream make_stream<TlsStream>(HttpServer::Impl& srv, tcp::socket&& sock) {
  return TlsStream(beast::tcp_stream(std::move(sock)), *srv.ssl_ctx);
}

template <class Stream>
class Conn final : public ConnBase, public std::enable_shared_from_this<Conn<Stream>> {
 public:
  static constexpr bool kTls = std::is_same_v<Stream, TlsStream>;

  Conn(HttpServer::Impl& srv, uint64_t id, tcp::socket sock, std::string remote, bool reserve)
      : srv_(srv),
        opt_(srv.opt),
        id_(id),
        ex_(sock.get_executor()),
        stream_(make_stream<Stream>(srv, std::move(sock))),
        remote_(std::move(remote)),
        reserve_(reserve),
        read_timeout_ms_(reserve ? std::min(opt_.read_timeout_ms, short_idle_ms(opt_))
                                 : opt_.read_timeout_ms),
        buf_(srv.opt.max_header_bytes + 64 * 1024),
        deadline_(ex_),
        response_timer_(ex_),
        close_timer_(ex_),
        started_(SteadyClock::now()) {}
  ~Conn() override { srv_.conn_gone(id_); }
  Conn(const Conn&) = delete;
  Conn& operator=(const Conn&) = delete;

  const asio::any_io_executor& executor() const { return ex_; }

  static asio::awaitable<void> run(std::shared_ptr<Conn> self) { co_await self->serve(); }

  void begin_shutdown() override {
    asio::post(ex_, [self = this->shared_from_this()] {
      self->shutdown_requested_ = true;
      if (self->phase_ == Phase::kIdle) self->lowest().cancel();
      if (self->phase_ == Phase::kWebSocket) self->request_ws_close(1001, "going away", false);
    });
  }

  void force_close() override {
    asio::post(ex_, [self = this->shared_from_this()] {
      self->shutdown_requested_ = true;
      self->deadline_.cancel();
      self->response_timer_.cancel();
      self->close_timer_.cancel();
      self->lowest().close();
    });
  }

 private:
  enum class Phase { kIdle, kReading, kHandling, kWriting, kWebSocket, kClosing };

  beast::tcp_stream& lowest() {
    return ws_ ? beast::get_lowest_layer(*ws_) : beast::get_lowest_layer(stream_);
  }

  asio::awaitable<void> serve() {
    if constexpr (kTls) {
      // Evictable until the client's first byte, as a plain connection is.
      if (!reserve_) {
        if (!srv_.mark_idle(id_, true)) co_return;
        arm_read_deadline(started_ + Ms(read_timeout_ms_));
        auto [wec] = co_await lowest().socket().async_wait(tcp::socket::wait_read, kNoThrow);
        disarm_read_deadline();
        if (!srv_.mark_idle(id_, false) || wec) co_return;
      }
      lowest().expires_at(started_ + Ms(read_timeout_ms_));
      auto [ec] = co_await stream_.async_handshake(ssl::stream_base::server, kNoThrow);
      if (ec) {
        rcan::log(LogLevel::kDebug, "tls.handshake_failed",
                  {{"remote", remote_}, {"error", ec.message()}});
        co_return;
      }
    }
    bool first = true;
    for (;;) {
      phase_ = Phase::kIdle;
      if (srv_.stopping.load() || shutdown_requested_) break;
      SteadyClock::time_point request_start = started_;
      if (buf_.size() == 0) {
        // The first request must arrive whole within read_timeout of the accept; later ones
        // may take idle_timeout to start — the long one only once an answer said the client
        // presented a credential.
        const SteadyClock::time_point until =
            first ? started_ + Ms(read_timeout_ms_)
                  : SteadyClock::now() +
                        Ms(authenticated_ ? opt_.idle_timeout_ms : short_idle_ms(opt_));
        // Idle timeout, peer closed, shutdown, evicted: close quietly.
        if (!co_await wait_for_request(until)) break;
        if (!first) request_start = SteadyClock::now();
      } else if (!first) {
        request_start = SteadyClock::now();  // pipelined: the next request is already here
      }
      lowest().expires_never();
      phase_ = Phase::kReading;
      const bool again = co_await serve_one(request_start);
      first = false;
      if (!again) break;
    }
    phase_ = Phase::kClosing;
    co_await close_connection();
  }

  // Waits for the first byte of the next request. Until it has authenticated, a connection doing
  // so may be closed to make room for a new one (Impl::admit); once a byte is here it may not.
  // A plain connection waits for readability and leaves the byte in the socket, where admit()
  // sees it (ConnEntry::fd): a request that has arrived is never evicted, even before this
  // strand has run again. False when the connection is to close.
  asio::awaitable<bool> wait_for_request(SteadyClock::time_point until) {
    const bool evictable = !authenticated_ && !reserve_;
    if (evictable && !srv_.mark_idle(id_, true)) co_return false;
    bool ok;
    if constexpr (kTls) {  // the TLS layer may hold a record already read: read through it
      lowest().expires_at(until);
      auto [ec, n] = co_await stream_.async_read_some(buf_.prepare(4096), kNoThrow);
      lowest().expires_never();
      if (!ec) buf_.commit(n);
      ok = !ec;
    } else {
      arm_read_deadline(until);
      auto [ec] = co_await lowest().socket().async_wait(tcp::socket::wait_read, kNoThrow);
      ok = !disarm_read_deadline() && !ec;
    }
    if (evictable && !srv_.mark_idle(id_, false)) co_return false;  // its slot is another's
    co_return ok;
  }

  // Hands the request to the node, whose answer is posted back to this connection (deliver)
  // from any thread. The handler's copies of the slot keep it; a respond dropped unanswered, or
  // a handler that throws, answers 500.
  void hand_to_node(HttpRequest req, uint64_t seq) {
    auto slot = std::make_shared<ResponseSlot>(
        srv_.weak_from_this(), [weak = this->weak_from_this(), seq](HttpResponse r) {
          auto self = weak.lock();
          if (!self) return;
          asio::post(self->ex_,
                     [self, seq, r = std::move(r)]() mutable { self->deliver(seq, std::move(r)); });
        });
    try {
      srv_.http.handle(std::move(req), [slot](HttpResponse r) { slot->fire(std::move(r)); });
    } catch (const std::exception& e) {
      rcan::log(LogLevel::kError, "http.handler_exception", {{"error", e.what()}});
      slot->fire(
          error_response({500, ErrorCode::kInternal, "handler_exception", "internal error"}));
    } catch (...) {
      rcan::log(LogLevel::kError, "http.handler_exception");
      slot->fire(
          error_response({500, ErrorCode::kInternal, "handler_exception", "internal error"}));
    }
  }

  // Reads, handles and answers one request. Returns whether to keep the connection.
  asio::awaitable<bool> serve_one(SteadyClock::time_point request_start) {
    http::request_parser<http::string_body> parser;
    apply_limits(parser, opt_.max_header_bytes, opt_.max_body_bytes);
    arm_read_deadline(request_start + Ms(read_timeout_ms_));
    std::optional<TransportError> framing;
    beast::error_code ec = co_await read_header(parser, framing);
    if (!ec && !framing) framing = check_framing(parser.get());
    if (!ec && framing) {
      disarm_read_deadline();
      co_await answer_error(*framing, parser.get().version());
      co_return false;
    }
    if (!ec && !parser.is_done()) {
      if (has_token(parser.get()[http::field::expect], "100-continue")) {
        static constexpr std::string_view k100 = "HTTP/1.1 100 Continue\r\n\r\n";
        auto [wec, wn] =
            co_await asio::async_write(stream_, asio::buffer(k100.data(), k100.size()), kNoThrow);
        ec = wec;
      }
      if (!ec) {
        auto [rec, rn] = co_await http::async_read(stream_, buf_, parser, kNoThrow);
        ec = rec;
      }
    }
    const bool timed_out = disarm_read_deadline();
    const int64_t received_us = steady_us();
    if (ec) {
      std::optional<TransportError> err =
          timed_out ? std::optional<TransportError>(read_timeout_error()) : classify_read_error(ec);
      if (err) co_await answer_error(*err, parser.is_header_done() ? parser.get().version() : 11);
      co_return false;
    }

    auto msg = parser.release();
    const unsigned version = msg.version();
    const bool head = msg.method() == http::verb::head;
    bool keep_alive = msg.keep_alive();
    HttpRequest req;
    if (auto err = to_http_request(msg, remote_, kTls, req)) {
      co_await answer_error(*err, version);
      co_return false;
    }
    req.received_mono_us = received_us;
    req.reserve = reserve_;
    if (reserve_ && !serve_on_reserve(req)) {
      ++srv_.reserve_refused;
      rcan::log(LogLevel::kWarn, "http.reserve_refused",
                {{"remote", remote_}, {"method", req.method}, {"path", req.path}});
      co_await answer_error(reserve_only_error(), version);
      co_return false;
    }
    if (wants_websocket(req)) {
      if (auto err = check_websocket_upgrade(req, version)) {
        co_await answer_error(*err, version);
        co_return false;
      }
      co_await serve_websocket(std::move(req), std::move(msg));
      co_return false;
    }

    // Hand the request to the node and wait for its answer (posted from any thread).
    ++srv_.requests_total;
    const SteadyClock::time_point t0 = SteadyClock::now();
    const std::string method = req.method;
    const std::string path = req.path;
    response_.reset();
    const uint64_t seq = ++seq_;
    phase_ = Phase::kHandling;
    response_timer_.expires_at(SteadyClock::time_point::max());
    hand_to_node(std::move(req), seq);
    if (!response_) co_await response_timer_.async_wait(kNoThrow);
    if (!response_) co_return false;  // force-closed while waiting

    // A reserve connection serves one request.
    keep_alive = keep_alive && !reserve_ && !srv_.stopping.load() && !shutdown_requested_;
    phase_ = Phase::kWriting;
    const int status = response_->status;
    if (response_->authenticated) authenticated_ = true;
    if (response_->answered_mono_us > 0)
      srv_.http.answer_waited(std::max<int64_t>(0, steady_us() - response_->answered_mono_us));
    const std::string wire = response_bytes(std::move(*response_), version, head, keep_alive);
    response_.reset();
    lowest().expires_after(Ms(opt_.read_timeout_ms));
    auto [wec, wn] = co_await asio::async_write(stream_, asio::buffer(wire), kNoThrow);
    lowest().expires_never();
    if (rcan::log_enabled(LogLevel::kDebug)) {
      const auto ms = std::chrono::duration_cast<Ms>(SteadyClock::now() - t0).count();
      rcan::log(LogLevel::kDebug, "http.request",
                {{"remote", remote_},
                 {"method", method},
                 {"path", path},
                 {"status", status},
                 {"ms", static_cast<int64_t>(ms)}});
    }
    co_return !wec && keep_alive;
  }

  // http::async_read_header, with the raw header block checked (check_header_block) while it
  // is still in the buffer: the parser takes the header in one piece, once it is whole, so the
  // bytes of the put() that completes it start at the request line.
  asio::awaitable<beast::error_code> read_header(http::request_parser<http::string_body>& parser,
                                                 std::optional<TransportError>& framing) {
    for (;;) {
      if (buf_.size() != 0) {
        beast::error_code ec;
        const auto data = buf_.data();
        const size_t used = parser.put(data, ec);
        if (used != 0 && parser.is_header_done())
          framing = check_header_block({static_cast<const char*>(data.data()), used});
        buf_.consume(used);
        if (ec != http::error::need_more) co_return ec;
      }
      const size_t size = beast::read_size(buf_, 65536);
      if (size == 0) co_return beast::error_code(http::error::buffer_overflow);
      auto [rec, n] = co_await stream_.async_read_some(buf_.prepare(size), kNoThrow);
      buf_.commit(n);
      if (rec == asio::error::eof)
        co_return beast::error_code(parser.got_some() ? http::error::partial_message
                                                      : http::error::end_of_stream);
      if (rec) co_return rec;
    }
  }

  bool serve_on_reserve(const HttpRequest& req) {
    try {
      return srv_.http.serve_on_reserve(req);
    } catch (const std::exception& e) {
      rcan::log(LogLevel::kError, "http.handler_exception", {{"error", e.what()}});
      return false;
    }
  }

  void deliver(uint64_t seq, HttpResponse r) {
    if (seq != seq_ || phase_ != Phase::kHandling || response_) return;
    response_ = std::move(r);
    response_timer_.cancel();
  }

  // The read deadline cancels (rather than closes) the socket, so that 408 can still be sent.
  void arm_read_deadline(SteadyClock::time_point at) {
    read_timed_out_ = false;
    const uint64_t gen = ++read_gen_;
    deadline_.expires_at(at);
    deadline_.async_wait([self = this->shared_from_this(), gen](beast::error_code ec) {
      if (ec || gen != self->read_gen_) return;
      self->read_timed_out_ = true;
      self->lowest().cancel();
    });
  }
  bool disarm_read_deadline() {
    ++read_gen_;
    deadline_.cancel();
    return read_timed_out_;
  }

  // Answers a transport-level failure and lets serve() close the connection.
  asio::awaitable<void> answer_error(const TransportError& err, unsigned version) {
    if (err.status == 400 || err.status == 426) {
      ++srv_.bad_requests;
    } else if (err.status != 503) {  // a reserve refusal is counted as reserve_refused
      ++srv_.rejected_limits;
    }
    rcan::log(LogLevel::kInfo, "http.rejected",
              {{"remote", remote_}, {"status", err.status}, {"reason", std::string(err.reason)}});
    const std::string wire = response_bytes(error_response(err), version, false, false);
    lowest().expires_after(Ms(opt_.read_timeout_ms));
    co_await asio::async_write(stream_, asio::buffer(wire), kNoThrow);
    lowest().expires_never();
  }

  // Closes the connection. After answering, a plain connection half-closes and discards what
  // the client still sends for a moment, so that the answer is not lost to a TCP reset.
  asio::awaitable<void> close_connection() {
    if (ws_) {
      lowest().close();
      co_return;
    }
    if (!lowest().socket().is_open()) co_return;
    if constexpr (kTls) {
      lowest().expires_after(Ms(kLingerMs));
      co_await stream_.async_shutdown(kNoThrow);
    } else {
      beast::error_code ec;
      lowest().socket().shutdown(tcp::socket::shutdown_send, ec);
      if (!ec) {
        const SteadyClock::time_point until = SteadyClock::now() + Ms(kLingerTotalMs);
        const Ms pause(std::min(kLingerMs, opt_.read_timeout_ms));
        std::vector<char> scratch(16 * 1024);
        size_t total = 0;
        while (total < kLingerBytes) {
          const auto left = std::chrono::duration_cast<Ms>(until - SteadyClock::now());
          if (left.count() <= 0) break;
          lowest().expires_after(std::min(pause, left));
          auto [rec, n] = co_await lowest().async_read_some(asio::buffer(scratch), kNoThrow);
          if (rec) break;
          total += n;
        }
      }
    }
    lowest().close();
  }

  // ---- WebSocket -------------------------------------------------------------------------

  // The stream's sink: frames the node sends, and a close it asks for, are posted to this
  // connection's strand (pump, request_ws_close) for as long as the server lives.
  void make_ws_sink() {
    auto weak = this->weak_from_this();
    auto srv_weak = srv_.weak_from_this();
    auto ex = ex_;
    sink_ = std::make_shared<WsSink>(
        remote_, opt_.ws_send_queue_limit,
        [weak, srv_weak, ex] {
          auto srv = srv_weak.lock();
          if (!srv) return;
          asio::post(ex, [weak] {
            if (auto self = weak.lock()) self->pump();
          });
        },
        [weak, srv_weak, ex](uint16_t code, std::string reason, bool overflow) {
          auto srv = srv_weak.lock();
          if (!srv) return;
          asio::post(ex, [weak, code, reason = std::move(reason), overflow]() mutable {
            if (auto self = weak.lock()) self->request_ws_close(code, std::move(reason), overflow);
          });
        });
  }

  // The upgraded connection as a WebSocket stream: its own timeouts (a ping at half the idle
  // timeout), the server's name, the message size limit, text frames.
  void start_ws() {
    ws_.emplace(std::move(stream_));
    websocket::stream_base::timeout timeouts{};
    timeouts.handshake_timeout = Ms(opt_.ws_handshake_timeout_ms);
    timeouts.idle_timeout = Ms(opt_.idle_timeout_ms);
    timeouts.keep_alive_pings = true;  // a ping at half the idle timeout detects dead peers
    ws_->set_option(timeouts);
    ws_->set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, kServerName); }));
    ws_->read_message_max(opt_.ws_max_message_bytes);
    ws_->text(true);
  }

  // The stream ended (`code`: the peer's close code, 0 when the handshake failed): the node is
  // told once, the counters and the log say so.
  void end_ws(int code) {
    ws_open_ = false;
    ws_done_ = true;
    sink_->mark_closed(true);
    close_timer_.cancel();
    deadline_.cancel();
    try {
      receiver_->on_closed();
    } catch (const std::exception& e) {
      rcan::log(LogLevel::kError, "ws.stream_exception", {{"error", e.what()}});
    }
    receiver_.reset();
    --srv_.ws_streams_open;
    rcan::log(LogLevel::kInfo, "ws.closed", {{"remote", remote_}, {"peer_close_code", code}});
  }

  asio::awaitable<void> serve_websocket(HttpRequest req, http::request<http::string_body> msg) {
    make_ws_sink();

    HttpResponse refusal = error_response(
        {403, ErrorCode::kInsufficientPrivileges, "websocket_refused", "WebSocket refused"});
    std::unique_ptr<StreamReceiver> receiver;
    try {
      receiver = srv_.streams.open(req, sink_, refusal);
    } catch (const std::exception& e) {
      rcan::log(LogLevel::kError, "ws.open_exception", {{"error", e.what()}});
      refusal = error_response({500, ErrorCode::kInternal, "open_exception", "internal error"});
      receiver.reset();
    }
    if (!receiver) {
      sink_->mark_closed(true);
      const std::string wire = response_bytes(std::move(refusal), msg.version(), false, false);
      lowest().expires_after(Ms(opt_.read_timeout_ms));
      co_await asio::async_write(stream_, asio::buffer(wire), kNoThrow);
      lowest().expires_never();
      co_return;
    }
    receiver_ = std::move(receiver);
    phase_ = Phase::kWebSocket;
    ++srv_.ws_streams_open;
    ++srv_.ws_streams_total;

    lowest().expires_never();  // the websocket stream runs its own timeouts
    start_ws();
    auto [aec] = co_await ws_->async_accept(msg, kNoThrow);
    if (!aec) {
      ws_open_ = true;
      rcan::log(LogLevel::kInfo, "ws.open", {{"remote", remote_}, {"path", req.path}});
      pump();          // frames queued during open(), or a close requested meanwhile
      if (reserve_) {  // a reserve WebSocket lives read_timeout_ms: long enough for a stop
        deadline_.expires_after(Ms(opt_.read_timeout_ms));
        deadline_.async_wait([self = this->shared_from_this()](beast::error_code ec) {
          if (!ec) self->request_ws_close(1013, "reserved connection: try again later", false);
        });
      }
      beast::flat_buffer in;
      for (;;) {
        in.clear();
        auto [rec, rn] = co_await ws_->async_read(in, kNoThrow);
        if (rec) {
          rcan::log(LogLevel::kDebug, "ws.read_end",
                    {{"remote", remote_}, {"error", rec.message()}});
          if (rec == websocket::error::message_too_big) ++srv_.rejected_limits;
          break;
        }
        if (close_pending_) continue;  // closing: late frames are dropped
        try {
          if (ws_->got_text()) {
            receiver_->on_text(beast::buffers_to_string(in.data()));
          } else {
            receiver_->on_binary();
          }
        } catch (const std::exception& e) {
          rcan::log(LogLevel::kError, "ws.stream_exception", {{"error", e.what()}});
          request_ws_close(1011, "internal error", false);
        }
      }
    }
    end_ws(aec ? 0 : static_cast<int>(ws_->reason().code));
  }

  // Writes queued frames one at a time, then the close frame once one is pending (strand).
  void pump() {
    if (!ws_open_ || ws_writing_ || ws_close_started_) return;
    if (sink_->pop(ws_out_)) {
      ws_writing_ = true;
      ws_->async_write(asio::buffer(ws_out_),
                       [self = this->shared_from_this()](beast::error_code ec, size_t) {
                         self->ws_writing_ = false;
                         if (ec) {
                           self->sink_->mark_closed(true);
                           self->lowest().close();
                           return;
                         }
                         self->pump();
                       });
      return;
    }
    if (close_pending_) {
      ws_close_started_ = true;
      ws_->async_close(
          websocket::close_reason(static_cast<websocket::close_code>(close_pending_->first),
                                  close_pending_->second),
          [self = this->shared_from_this()](beast::error_code ec) {
            rcan::log(LogLevel::kDebug, "ws.close_done",
                      {{"remote", self->remote_}, {"error", ec.message()}});
          });
    }
  }

  // A close from the node, the send-queue limit or shutdown (strand). Queued frames go out
  // first unless the queue overflowed; the close handshake is bounded by a watchdog.
  void request_ws_close(uint16_t code, std::string reason, bool overflow) {
    if (!sink_ || close_pending_) return;
    sink_->mark_closed(overflow);
    if (phase_ != Phase::kWebSocket || !ws_ || ws_done_) return;
    if (overflow) {
      ++srv_.rejected_limits;
      rcan::log(LogLevel::kWarn, "ws.send_queue_full", {{"remote", remote_}});
    }
    close_pending_.emplace(code, close_reason_text(std::move(reason)));
    close_timer_.expires_after(Ms(opt_.ws_handshake_timeout_ms));
    close_timer_.async_wait([self = this->shared_from_this()](beast::error_code ec) {
      if (!ec && self->ws_) self->lowest().close();
    });
    pump();
  }

  HttpServer::Impl& srv_;
  const ServerOptions& opt_;
  const uint64_t id_;
  asio::any_io_executor ex_;
  Stream stream_;  // moved into ws_ on upgrade
  std::optional<websocket::stream<Stream>> ws_;
  const std::string remote_;
  const bool reserve_;  // accepted from the reserve, over max_connections
  const int read_timeout_ms_;
  bool authenticated_ = false;  // an answer said the client presented a valid credential
  beast::flat_buffer buf_;
  asio::steady_timer deadline_;
  asio::steady_timer response_timer_;
  asio::steady_timer close_timer_;
  const SteadyClock::time_point started_;

  Phase phase_ = Phase::kIdle;
  bool shutdown_requested_ = false;
  bool read_timed_out_ = false;
  uint64_t read_gen_ = 0;
  uint64_t seq_ = 0;
  std::optional<HttpResponse> response_;

  std::shared_ptr<WsSink> sink_;
  std::unique_ptr<StreamReceiver> receiver_;
  bool ws_open_ = false;
  bool ws_writing_ = false;
  bool ws_close_started_ = false;
  bool ws_done_ = false;  // the read loop has ended
  std::optional<std::pair<uint16_t, std::string>> close_pending_;
  std::string ws_out_;
};

inline void log_coroutine_exception(std::exception_ptr e) {
  if (!e) return;
  try {
    std::rethrow_exception(e);
  } catch (const std::exception& ex) {
    rcan::log(LogLevel::kError, "http.connection_exception", {{"error", ex.what()}});
  } catch (...) {
    rcan::log(LogLevel::kError, "http.connection_exception");
  }
}

}  // namespace detail

// ---- HttpServer::Impl ------------------------------------------------------------------------

template <class Stream>
void HttpServer::Impl::spawn_conn(detail::tcp::socket sock, std::string remote, std::string addr,
                                  bool reserve) {
  uint64_t id;
  {
    MutexLock lock(mu);
    id = ++next_id;
    ++connections_open;
    conns[id] = ConnEntry{{}, addr, remote, sock.native_handle(), reserve, false};
  }
  ++connections_total;
  auto conn = std::make_shared<detail::Conn<Stream>>(*this, id, std::move(sock), std::move(remote),
                                                     reserve);
  {
    MutexLock lock(mu);
    conns[id].conn = conn;
  }
  auto ex = conn->executor();
  detail::asio::co_spawn(ex, detail::Conn<Stream>::run(std::move(conn)),
                         detail::log_coroutine_exception);
}

detail::asio::awaitable<void> HttpServer::Impl::accept_loop() {
  namespace asio = detail::asio;
  detail::SteadyClock::time_point last_evicted_log{};
  uint64_t evicted_unlogged = 0;
  for (;;) {
    auto [ec, peer] = co_await acceptor->async_accept(asio::make_strand(ioc), detail::kNoThrow);
    if (stopping.load()) co_return;
    if (ec) {
      if (ec == asio::error::operation_aborted) co_return;
      rcan::log(rcan::LogLevel::kWarn, "http.accept_failed", {{"error", ec.message()}});
      // Out of descriptors and the like: back off instead of spinning.
      asio::steady_timer pause(co_await asio::this_coro::executor, detail::Ms(50));
      co_await pause.async_wait(detail::kNoThrow);
      continue;
    }
    detail::tcp::socket sock(std::move(peer));
    beast::error_code rec;
    const auto ep = sock.remote_endpoint(rec);
    std::string remote = rec ? std::string("unknown") : detail::endpoint_string(ep);
    std::string addr = rec ? std::string("unknown") : detail::address_key(ep);
    sock.set_option(detail::tcp::no_delay(true), rec);
    Admission admission = admit(addr);
    const Admit admitted = admission.admit;
    if (admission.evicted) {  // its slot is this connection's now
      ++evicted_idle;
      // At most one line a second: a client re-opening connections must not set the pace of
      // the log (the count says how many since the last line).
      ++evicted_unlogged;
      const auto now = detail::SteadyClock::now();
      if (now - last_evicted_log >= std::chrono::seconds(1)) {
        rcan::log(rcan::LogLevel::kWarn, "http.connection_evicted",
                  {{"remote", remote},
                   {"evicted", admission.evicted_remote},
                   {"evicted_since_last", evicted_unlogged},
                   {"open", connections_open.load()}});
        evicted_unlogged = 0;
        last_evicted_log = now;
      }
      if (admission.evicted_conn) admission.evicted_conn->force_close();
    }
    if (admitted == Admit::kPerAddress || admitted == Admit::kFull) {
      const bool by_address = admitted == Admit::kPerAddress;
      ++(by_address ? rejected_per_address : rejected_connections);
      rcan::log(rcan::LogLevel::kWarn,
                by_address ? "http.address_connection_limit" : "http.connection_limit",
                {{"remote", remote}, {"open", connections_open.load()}});
      auto ex = sock.get_executor();
      asio::co_spawn(ex,
                     reject(std::move(sock), by_address ? detail::too_many_from_address_error()
                                                        : detail::too_many_connections_error()),
                     detail::log_coroutine_exception);
      continue;
    }
    const bool reserve = admitted == Admit::kReserve;
    if (reserve) {
      ++reserve_connections;
      rcan::log(
          rcan::LogLevel::kWarn, "http.reserve_connection",
          {{"remote", remote},
           {"over", admission.over_address ? "max_connections_per_address" : "max_connections"},
           {"open", connections_open.load()}});
    }
    if (opt.tls) {
      spawn_conn<detail::TlsStream>(std::move(sock), std::move(remote), std::move(addr), reserve);
    } else {
      spawn_conn<detail::PlainStream>(std::move(sock), std::move(remote), std::move(addr), reserve);
    }
  }
}

// Over max_connections (and the reserve) or max_connections_per_address: answer 503 with the
// error body and close. TLS connections are closed without an answer (a TLS handshake per
// refused connection would defeat the limit's purpose).
detail::asio::awaitable<void> HttpServer::Impl::reject(detail::tcp::socket sock,
                                                       detail::TransportError err) {
  namespace asio = detail::asio;
  namespace http = detail::http;
  if (opt.tls || rejecting.load() >= detail::kMaxConcurrentRejects) {
    beast::error_code ec;
    sock.close(ec);
    co_return;
  }
  ++rejecting;
  {
    beast::tcp_stream s(std::move(sock));
    s.expires_after(detail::Ms(detail::kRejectTimeoutMs));
    const std::string wire = detail::response_bytes(detail::error_response(err), 11, false, false);
    auto [wec, wn] = co_await asio::async_write(s, asio::buffer(wire), detail::kNoThrow);
    if (!wec) {
      beast::error_code ec;
      s.socket().shutdown(detail::tcp::socket::shutdown_send, ec);
      char scratch[1024];
      for (;;) {
        auto [rec, n] = co_await s.async_read_some(asio::buffer(scratch), detail::kNoThrow);
        if (rec) break;
      }
    }
    s.close();
  }
  --rejecting;
}

Result<uint16_t> HttpServer::Impl::start() {
  namespace asio = detail::asio;
  MutexLock life(lifecycle_mu);
  if (started) return Error(ErrorCode::kInternal, "server already started");
  if (opt.io_threads < 1 || opt.read_timeout_ms <= 0 || opt.idle_timeout_ms <= 0 ||
      opt.ws_handshake_timeout_ms <= 0 || opt.unauthenticated_idle_timeout_ms <= 0 ||
      opt.max_connections == 0 || opt.max_header_bytes == 0 || opt.ws_max_message_bytes == 0 ||
      opt.ws_send_queue_limit == 0)
    return Error(ErrorCode::kSchemaValidationFailed, "invalid server options");
  uint16_t port = 0;
  try {
    beast::error_code ec;
    if (opt.tls) {
      ssl_ctx = std::make_unique<detail::ssl::context>(detail::ssl::context::tls_server);
      ssl_ctx->set_options(detail::ssl::context::default_workarounds |
                           detail::ssl::context::no_sslv2 | detail::ssl::context::no_sslv3 |
                           detail::ssl::context::no_tlsv1 | detail::ssl::context::no_tlsv1_1 |
                           detail::ssl::context::single_dh_use);
      ssl_ctx->use_certificate_chain_file(opt.cert_file, ec);
      if (ec)
        return Error(ErrorCode::kSchemaValidationFailed,
                     "cannot load TLS certificate: " + ec.message(), "cert_file");
      ssl_ctx->use_private_key_file(opt.key_file, detail::ssl::context::pem, ec);
      if (ec)
        return Error(ErrorCode::kSchemaValidationFailed, "cannot load TLS key: " + ec.message(),
                     "key_file");
    }
    const auto addr = asio::ip::make_address(opt.bind_address, ec);
    if (ec)
      return Error(ErrorCode::kSchemaValidationFailed, "invalid bind address", "bind_address");
    const detail::tcp::endpoint ep(addr, opt.port);
    acceptor.emplace(asio::make_strand(ioc));
    acceptor->open(ep.protocol(), ec);
    if (!ec) acceptor->set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor->bind(ep, ec);
    if (!ec) acceptor->listen(asio::socket_base::max_listen_connections, ec);
    if (ec) {
      acceptor.reset();
      return Error(ErrorCode::kInternal, "cannot listen on " + opt.bind_address + ":" +
                                             std::to_string(opt.port) + ": " + ec.message());
    }
    port = acceptor->local_endpoint().port();
  } catch (const std::exception& e) {
    acceptor.reset();
    return Error(ErrorCode::kInternal, std::string("cannot start server: ") + e.what());
  }
  asio::co_spawn(acceptor->get_executor(), accept_loop(), detail::log_coroutine_exception);
  {
    MutexLock lock(mu);
    running_threads = opt.io_threads;
  }
  for (int i = 0; i < opt.io_threads; ++i) {
    threads.emplace_back([this] {
      pthread_setname_np(pthread_self(), "http-io");
      for (;;) {
        try {
          ioc.run();
          break;
        } catch (const std::exception& e) {
          rcan::log(rcan::LogLevel::kError, "http.io_exception", {{"error", e.what()}});
        } catch (...) {
          rcan::log(rcan::LogLevel::kError, "http.io_exception");
        }
      }
      {
        MutexLock lock(mu);
        --running_threads;
      }
      cv.notify_all();
    });
  }
  started = true;
  rcan::log(rcan::LogLevel::kInfo, "http.listening",
            {{"address", opt.bind_address},
             {"port", static_cast<int>(port)},
             {"tls", opt.tls},
             {"io_threads", opt.io_threads}});
  return port;
}

void HttpServer::Impl::stop(int drain_ms) {
  {
    MutexLock life(lifecycle_mu);
    if (!started || stopped) return;
    stopped = true;
  }
  rcan::log(rcan::LogLevel::kInfo, "http.stopping",
            {{"open_connections", connections_open.load()}, {"drain_ms", drain_ms}});
  stopping = true;
  detail::asio::post(acceptor->get_executor(), [this] {
    beast::error_code ec;
    acceptor->close(ec);
  });
  for (auto& c : snapshot()) c->begin_shutdown();
  const auto deadline = detail::SteadyClock::now() + detail::Ms(drain_ms < 0 ? 0 : drain_ms);
  {
    MutexLock lock(mu);
    while (connections_open.load() != 0) {
      if (cv.wait_until(mu, deadline) == std::cv_status::timeout) break;
    }
  }
  const uint64_t left = connections_open.load();
  for (auto& c : snapshot()) c->force_close();
  bool threads_ended;
  {
    MutexLock lock(mu);
    const auto until = steady_now() + std::chrono::seconds(3);
    while (running_threads != 0) {
      if (cv.wait_until(mu, until) == std::cv_status::timeout) break;
    }
    threads_ended = running_threads == 0;
  }
  if (!threads_ended) {
    rcan::log(rcan::LogLevel::kWarn, "http.stop_forced");
    ioc.stop();
  }
  for (auto& t : threads)
    if (t.joinable()) t.join();
  threads.clear();
  rcan::log(rcan::LogLevel::kInfo, "http.stopped", {{"closed_in_flight", left}});
}

ServerStats HttpServer::Impl::stats() const {
  ServerStats s;
  s.connections_open = connections_open.load();
  s.connections_total = connections_total.load();
  s.ws_streams_open = ws_streams_open.load();
  s.ws_streams_total = ws_streams_total.load();
  s.requests_total = requests_total.load();
  s.rejected_connections = rejected_connections.load();
  s.rejected_per_address = rejected_per_address.load();
  s.reserve_connections = reserve_connections.load();
  s.reserve_refused = reserve_refused.load();
  s.evicted_idle = evicted_idle.load();
  s.rejected_limits = rejected_limits.load();
  s.bad_requests = bad_requests.load();
  {
    MutexLock lock(mu);
    s.evictable_now = idle.size();
  }
  return s;
}

// ---- HttpServer ------------------------------------------------------------------------------

HttpServer::HttpServer(ServerOptions options, HttpHandler& http, StreamHandler& stream)
    : impl_(std::make_shared<Impl>(std::move(options), http, stream)) {}

HttpServer::~HttpServer() {
  if (impl_) impl_->stop(0);
}

Result<uint16_t> HttpServer::start() { return impl_->start(); }
void HttpServer::stop(int drain_ms) { impl_->stop(drain_ms); }
ServerStats HttpServer::stats() const { return impl_->stats(); }

}  // namespace rcan::transport
