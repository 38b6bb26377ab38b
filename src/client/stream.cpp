// rcan::client::Stream — the WebSocket binding (spec Appendix B) with reconnect and backoff.
#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <chrono>
#include <cstring>

#include "client/net.h"
#include "rcan/client.h"
#include "rcan/errors.h"
#include "rcan/hash.h"

namespace rcan::client {
using net::mono_ms;
using net::wall_ms;

Stream::Stream(StreamOptions options) : opts_(std::move(options)) {
  if (::pipe2(wake_fd_, O_CLOEXEC | O_NONBLOCK) != 0) wake_fd_[0] = wake_fd_[1] = -1;
}

Stream::~Stream() {
  for (int fd : wake_fd_)
    if (fd >= 0) ::close(fd);
}

void Stream::send(const json::Value& message) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    outbox_.push_back(json::dump(message));
  }
  if (wake_fd_[1] >= 0) (void)!::write(wake_fd_[1], "x", 1);
}

std::string Stream::send_command(const Command& c) {
  json::Value m = command_message(c, wall_ms());
  std::string id = m.get("message_id")->as_string();
  send(m);
  return id;
}

void Stream::stop() {
  stop_.store(true);
  if (wake_fd_[1] >= 0) (void)!::write(wake_fd_[1], "x", 1);
}

std::string Stream::session_id() const {
  std::lock_guard<std::mutex> lock(mu_);
  return session_id_;
}

// One connection's life (spec Appendix B): handshake, CONNECT and CONNECT_ACK, frames in,
// PING/PONG timers, queued frames out. run() returns how it ended.
class Stream::Connection {
 public:
  struct End {
    ClientError error;
    bool connected = false;  // CONNECT_ACK was received
    bool refused = false;    // do not retry (authentication refused)
  };

  // `failures` (the stream's count of failed attempts in a row) is reset on CONNECT_ACK.
  Connection(Stream& stream, int& failures) : s_(stream), failures_(failures) {}
  End run();

 private:
  bool open();  // connect, WebSocket handshake, CONNECT; false: end_ says why
  bool send_text(const std::string& text);
  void send_control(uint8_t op, const std::string& payload);
  // The frames already buffered; false when the connection ended.
  bool handle_buffered_frames();
  // A close frame: ends the connection with the node's code and reason.
  void handle_close(const std::string& payload);
  // One whole text message; false when the connection ended.
  bool handle_message(const json::Value& v);
  // CONNECT_ACK and PONG deadlines, the PING interval; false when the connection ended.
  bool handle_timers(int64_t now);
  // Waits for data, a queued frame or a timer, then sends what is queued; false when the
  // connection ended. `readable`: data is waiting to be read.
  bool wait_and_flush(int64_t now, bool& readable);
  bool fail(const char* code, const std::string& message) {
    end_.error = net::transport_error(code, message);
    return false;
  }

  Stream& s_;
  int& failures_;
  End end_;
  net::Conn conn_;
  int timeout_ = 0;
  std::string buf_;
  uint8_t mask_[4] = {0, 0, 0, 0};
  int64_t last_send_ = 0;
  int64_t ack_deadline_ = 0;
  int64_t pong_deadline_ = 0;
  std::string ping_id_;
  std::string partial_;
  uint8_t partial_op_ = 0;
};

bool Stream::Connection::send_text(const std::string& text) {
  random_bytes(mask_, sizeof mask_);
  return conn_.write_all(wire::ws_frame(1, text, mask_), timeout_).ok();
}

void Stream::Connection::send_control(uint8_t op, const std::string& payload) {
  random_bytes(mask_, sizeof mask_);
  (void)conn_.write_all(wire::ws_frame(op, payload, mask_), timeout_);
}

bool Stream::Connection::open() {
  auto ep = parse_endpoint(s_.opts_.client.url);
  if (!ep.ok()) {
    end_.error = ep.error();
    end_.refused = true;
    return false;
  }
  timeout_ = s_.opts_.client.timeout_ms;
  if (auto o = conn_.open(*ep, timeout_, s_.opts_.client.ca_file, s_.opts_.client.insecure);
      !o.ok()) {
    end_.error = o.error();
    end_.refused = o.error().code == "TLS_FAILED";
    return false;
  }
  if (auto h =
          net::ws_handshake(conn_, *ep, "/rcan/v1/stream", s_.opts_.client.token, timeout_, buf_);
      !h.ok()) {
    end_.error = h.error();
    end_.refused = h.error().http_status == 401 || h.error().http_status == 403 ||
                   h.error().http_status == 404;
    return false;
  }
  json::Object connect{{"type", "CONNECT"},
                       {"version", "1.0.0"},
                       {"token", s_.opts_.client.token},
                       {"caps", json::Object{{"client", "rcan-client"}}}};
  last_send_ = mono_ms();
  if (!send_text(json::dump(json::Value(connect))))
    return fail("CONNECTION_FAILED", "could not send CONNECT");
  ack_deadline_ = mono_ms() + 10000;
  return true;
}

Stream::Connection::End Stream::Connection::run() {
  if (!open()) return end_;
  while (!s_.stop_.load()) {
    if (!handle_buffered_frames()) return end_;
    const int64_t now = mono_ms();
    if (!handle_timers(now)) return end_;
    bool readable = false;
    if (!wait_and_flush(now, readable)) return end_;
    if (!readable) continue;
    auto r = conn_.read_some(buf_, 1000);
    if (!r.ok()) {
      if (r.error().code == "TIMEOUT") continue;
      end_.error = r.error();
      return end_;
    }
    if (*r == 0) {
      fail("CONNECTION_CLOSED", "the node closed the connection");
      return end_;
    }
  }
  send_control(8, std::string("\x03\xe8", 2));  // 1000 normal closure
  return end_;
}

bool Stream::Connection::handle_buffered_frames() {
  while (true) {
    wire::WsFrame f;
    size_t used = 0;
    std::string err;
    wire::Parse p = wire::ws_parse(buf_, f, used, err);
    if (p == wire::Parse::kIncomplete) return true;
    if (p == wire::Parse::kError) {
      send_control(8, std::string("\x03\xef", 2));  // 1007
      return fail("BAD_RESPONSE", "bad WebSocket frame: " + err);
    }
    buf_.erase(0, used);
    if (f.opcode == 9) {
      send_control(10, f.payload);
      continue;
    }
    if (f.opcode == 10) continue;
    if (f.opcode == 8) {
      handle_close(f.payload);
      return false;
    }
    if (f.opcode == 0) {
      partial_ += f.payload;
    } else {
      partial_ = f.payload;
      partial_op_ = f.opcode;
    }
    if (!f.fin) continue;
    if (partial_op_ != 1) {
      partial_.clear();
      continue;
    }
    auto v = json::parse(partial_, {.max_depth = 64, .max_bytes = 16u << 20});
    partial_.clear();
    if (!v.ok()) continue;
    if (!handle_message(*v)) return false;
  }
}

void Stream::Connection::handle_close(const std::string& payload) {
  int code = payload.size() >= 2
                 ? (static_cast<uint8_t>(payload[0]) << 8) | static_cast<uint8_t>(payload[1])
                 : 1005;
  std::string reason = payload.size() > 2 ? payload.substr(2) : "";
  send_control(8, payload.substr(0, 2));
  end_.error =
      net::transport_error("CONNECTION_CLOSED", "closed by the node: " + std::to_string(code) +
                                                    (reason.empty() ? "" : " " + reason));
  // 4001 ConnectionRefused / 4002 AuthExpired / 1008 policy: retrying cannot help.
  if (code == 4001 || code == 4002 || code == 1008) end_.refused = !end_.connected || code == 4002;
  if (code == 4001 || code == 4002) {
    end_.error.code = code == 4001 ? "ConnectionRefused" : "AuthExpired";
    end_.error.http_status = 401;  // refused by the node (Appendix B 8001 / 8002)
  }
}

bool Stream::Connection::handle_message(const json::Value& v) {
  std::string t;
  if (const json::Value* tv = v.get("type"); tv && tv->is_string()) t = tv->as_string();
  if (!end_.connected) {
    if (t == "CONNECT_ACK") {
      end_.connected = true;
      s_.connected_.store(true);
      {
        std::lock_guard<std::mutex> lock(s_.mu_);
        if (const json::Value* sid = v.get("session_id"); sid && sid->is_string())
          s_.session_id_ = sid->as_string();
      }
      failures_ = 0;
      if (s_.opts_.on_state) s_.opts_.on_state("connected");
      if (s_.opts_.on_message) s_.opts_.on_message(v);
      if (s_.opts_.telemetry_hz > 0) {
        json::Object sub{{"type", "SUBSCRIBE"},
                         {"topics", json::Array{"telemetry"}},
                         {"hz", s_.opts_.telemetry_hz}};
        send_text(json::dump(json::Value(sub)));
      }
      if (s_.wake_fd_[1] >= 0) (void)!::write(s_.wake_fd_[1], "x", 1);  // flush the outbox
    } else if (t == "ERROR") {
      end_.error = error_from_response(401, json::dump(v));
      if (const json::Value* n = v.get("name"); n && n->is_string())
        end_.error.code = n->as_string();
      if (const json::Value* m = v.get("message"); m && m->is_string())
        end_.error.message = m->as_string();
      end_.error.http_status = 401;  // refused by the node (not a transport failure)
      end_.refused = true;
      return false;
    }
    return true;
  }
  if (t == "PONG") {
    pong_deadline_ = 0;
    return true;
  }
  if (s_.opts_.on_message) s_.opts_.on_message(v);
  return true;
}

bool Stream::Connection::handle_timers(int64_t now) {
  if (!end_.connected && now >= ack_deadline_) return fail("TIMEOUT", "no CONNECT_ACK within 10 s");
  if (pong_deadline_ && now >= pong_deadline_)
    return fail("TIMEOUT", "no PONG within " + std::to_string(s_.opts_.pong_timeout_ms) + " ms");
  if (end_.connected && !pong_deadline_ && now - last_send_ >= s_.opts_.ping_interval_ms) {
    ping_id_ = new_uuid_v4();
    json::Object ping{{"type", "PING"}, {"msg_id", ping_id_}, {"timestamp_us", wall_ms() * 1000}};
    if (!send_text(json::dump(json::Value(ping)))) return fail("CONNECTION_FAILED", "send failed");
    last_send_ = now;
    pong_deadline_ = now + s_.opts_.pong_timeout_ms;
  }
  return true;
}

bool Stream::Connection::wait_and_flush(int64_t now, bool& readable) {
  int64_t wait =
      end_.connected ? s_.opts_.ping_interval_ms - (now - last_send_) : ack_deadline_ - now;
  if (pong_deadline_) wait = std::min(wait, pong_deadline_ - now);
  wait = std::max<int64_t>(1, std::min<int64_t>(wait, 1000));
  readable = conn_.pending();
  if (!readable) {
    pollfd fds[2] = {{conn_.fd(), POLLIN, 0}, {s_.wake_fd_[0], POLLIN, 0}};
    int n = ::poll(fds, s_.wake_fd_[0] >= 0 ? 2 : 1, static_cast<int>(wait));
    if (n < 0 && errno != EINTR) return fail("CONNECTION_FAILED", std::strerror(errno));
    if (n > 0 && (fds[1].revents & POLLIN)) {
      char drain[64];
      while (::read(s_.wake_fd_[0], drain, sizeof drain) > 0) {
      }
    }
    readable = n > 0 && (fds[0].revents & (POLLIN | POLLHUP | POLLERR));
  }
  if (!end_.connected) return true;  // queued frames go out once connected
  std::vector<std::string> out;
  {
    std::lock_guard<std::mutex> lock(s_.mu_);
    out.swap(s_.outbox_);
  }
  for (size_t i = 0; i < out.size(); ++i) {
    if (!send_text(out[i])) {
      std::lock_guard<std::mutex> lock(s_.mu_);
      s_.outbox_.insert(s_.outbox_.begin(), out.begin() + static_cast<std::ptrdiff_t>(i),
                        out.end());
      return fail("CONNECTION_FAILED", "send failed");
    }
    last_send_ = mono_ms();
  }
  return true;
}

ClientError Stream::run() {
  auto state = [&](const std::string& s) {
    if (opts_.on_state) opts_.on_state(s);
  };
  uint64_t seed = 0;
  random_bytes(&seed, sizeof seed);
  std::mt19937_64 rng(seed);
  int failures = 0;
  ClientError last;
  last.code = "STOPPED";
  last.message = "stopped";
  while (!stop_.load()) {
    state("connecting");
    Connection::End end = Connection(*this, failures).run();
    connected_.store(false);
    if (stop_.load()) break;
    last = end.error;
    if (end.refused) {
      state("refused: " + end.error.message);
      return last;
    }
    state("disconnected: " + end.error.message);
    ++failures;
    if (opts_.max_attempts >= 0 && failures >= opts_.max_attempts) return last;
    auto delay = backoff_delay(failures - 1, rng);
    state("retrying in " + std::to_string(delay.count()) + " ms");
    int64_t until = mono_ms() + delay.count();
    while (!stop_.load()) {
      int64_t left = until - mono_ms();
      if (left <= 0) break;
      pollfd p{wake_fd_[0], POLLIN, 0};
      if (::poll(&p, wake_fd_[0] >= 0 ? 1 : 0, static_cast<int>(std::min<int64_t>(left, 1000))) >
          0) {
        char drain[64];
        while (::read(wake_fd_[0], drain, sizeof drain) > 0) {
        }
      }
    }
  }
  state("stopped");
  ClientError e;
  e.code = "STOPPED";
  e.message = "stopped";
  return e;
}

}  // namespace rcan::client
