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
namespace {

int64_t mono_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
int64_t wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct SessionEnd {
  ClientError error;
  bool connected = false;  // CONNECT_ACK was received
  bool refused = false;    // do not retry (authentication refused)
};

}  // namespace

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

  auto one_session = [&]() -> SessionEnd {
    SessionEnd end;
    auto ep = parse_endpoint(opts_.client.url);
    if (!ep.ok()) {
      end.error = ep.error();
      end.refused = true;
      return end;
    }
    net::Conn conn;
    int timeout = opts_.client.timeout_ms;
    if (auto o = conn.open(*ep, timeout, opts_.client.ca_file, opts_.client.insecure); !o.ok()) {
      end.error = o.error();
      end.refused = o.error().code == "TLS_FAILED";
      return end;
    }
    std::string buf;
    if (auto h = net::ws_handshake(conn, *ep, "/rcan/v1/stream", opts_.client.token, timeout, buf); !h.ok()) {
      end.error = h.error();
      end.refused = h.error().http_status == 401 || h.error().http_status == 403 || h.error().http_status == 404;
      return end;
    }
    uint8_t mask[4];
    auto send_text = [&](const std::string& text) -> bool {
      random_bytes(mask, sizeof mask);
      return conn.write_all(wire::ws_frame(1, text, mask), timeout).ok();
    };
    auto send_control = [&](uint8_t op, const std::string& payload) {
      random_bytes(mask, sizeof mask);
      (void)conn.write_all(wire::ws_frame(op, payload, mask), timeout);
    };
    json::Object connect{{"type", "CONNECT"},
                         {"version", "1.0.0"},
                         {"token", opts_.client.token},
                         {"caps", json::Object{{"client", "rcan-client"}}}};
    int64_t last_send = mono_ms();
    if (!send_text(json::dump(json::Value(connect)))) {
      end.error = net::transport_error("CONNECTION_FAILED", "could not send CONNECT");
      return end;
    }
    int64_t ack_deadline = mono_ms() + 10000;
    int64_t pong_deadline = 0;
    std::string ping_id;
    std::string partial;
    uint8_t partial_op = 0;
    while (!stop_.load()) {
      // 1. Frames already buffered.
      while (true) {
        wire::WsFrame f;
        size_t used = 0;
        std::string err;
        wire::Parse p = wire::ws_parse(buf, f, used, err);
        if (p == wire::Parse::kIncomplete) break;
        if (p == wire::Parse::kError) {
          send_control(8, std::string("\x03\xef", 2));  // 1007
          end.error = net::transport_error("BAD_RESPONSE", "bad WebSocket frame: " + err);
          return end;
        }
        buf.erase(0, used);
        if (f.opcode == 9) {
          send_control(10, f.payload);
          continue;
        }
        if (f.opcode == 10) continue;
        if (f.opcode == 8) {
          int code = f.payload.size() >= 2 ? (static_cast<uint8_t>(f.payload[0]) << 8) | static_cast<uint8_t>(f.payload[1]) : 1005;
          std::string reason = f.payload.size() > 2 ? f.payload.substr(2) : "";
          send_control(8, f.payload.substr(0, 2));
          end.error = net::transport_error("CONNECTION_CLOSED", "closed by the node: " + std::to_string(code) +
                                                                    (reason.empty() ? "" : " " + reason));
          // 4001 ConnectionRefused / 4002 AuthExpired / 1008 policy: retrying cannot help.
          if (code == 4001 || code == 4002 || code == 1008) end.refused = !end.connected || code == 4002;
          if (code == 4001 || code == 4002) {
            end.error.code = code == 4001 ? "ConnectionRefused" : "AuthExpired";
            end.error.http_status = 401;  // refused by the node (Appendix B 8001 / 8002)
          }
          return end;
        }
        if (f.opcode == 0) {
          partial += f.payload;
        } else {
          partial = f.payload;
          partial_op = f.opcode;
        }
        if (!f.fin) continue;
        if (partial_op != 1) {
          partial.clear();
          continue;
        }
        auto v = json::parse(partial, {.max_depth = 64, .max_bytes = 16u << 20});
        partial.clear();
        if (!v.ok()) continue;
        std::string t;
        if (const json::Value* tv = v->get("type"); tv && tv->is_string()) t = tv->as_string();
        if (!end.connected) {
          if (t == "CONNECT_ACK") {
            end.connected = true;
            connected_.store(true);
            {
              std::lock_guard<std::mutex> lock(mu_);
              if (const json::Value* s = v->get("session_id"); s && s->is_string()) session_id_ = s->as_string();
            }
            failures = 0;
            state("connected");
            if (opts_.on_message) opts_.on_message(*v);
            if (opts_.telemetry_hz > 0) {
              json::Object sub{{"type", "SUBSCRIBE"}, {"topics", json::Array{"telemetry"}}, {"hz", opts_.telemetry_hz}};
              send_text(json::dump(json::Value(sub)));
            }
            if (wake_fd_[1] >= 0) (void)!::write(wake_fd_[1], "x", 1);  // flush the outbox
          } else if (t == "ERROR") {
            end.error = error_from_response(401, json::dump(*v));
            if (const json::Value* n = v->get("name"); n && n->is_string()) end.error.code = n->as_string();
            if (const json::Value* m = v->get("message"); m && m->is_string()) end.error.message = m->as_string();
            end.error.http_status = 401;  // refused by the node (not a transport failure)
            end.refused = true;
            return end;
          }
          continue;
        }
        if (t == "PONG") {
          pong_deadline = 0;
          continue;
        }
        if (opts_.on_message) opts_.on_message(*v);
      }
      // 2. Timers.
      int64_t now = mono_ms();
      if (!end.connected && now >= ack_deadline) {
        end.error = net::transport_error("TIMEOUT", "no CONNECT_ACK within 10 s");
        return end;
      }
      if (pong_deadline && now >= pong_deadline) {
        end.error = net::transport_error("TIMEOUT", "no PONG within " + std::to_string(opts_.pong_timeout_ms) + " ms");
        return end;
      }
      if (end.connected && !pong_deadline && now - last_send >= opts_.ping_interval_ms) {
        ping_id = new_uuid_v4();
        json::Object ping{{"type", "PING"}, {"msg_id", ping_id}, {"timestamp_us", wall_ms() * 1000}};
        if (!send_text(json::dump(json::Value(ping)))) {
          end.error = net::transport_error("CONNECTION_FAILED", "send failed");
          return end;
        }
        last_send = now;
        pong_deadline = now + opts_.pong_timeout_ms;
      }
      // 3. Wait for data, a queued frame or a timer.
      int64_t wait = end.connected ? opts_.ping_interval_ms - (now - last_send) : ack_deadline - now;
      if (pong_deadline) wait = std::min(wait, pong_deadline - now);
      wait = std::max<int64_t>(1, std::min<int64_t>(wait, 1000));
      bool readable = conn.pending();
      if (!readable) {
        pollfd fds[2] = {{conn.fd(), POLLIN, 0}, {wake_fd_[0], POLLIN, 0}};
        int n = ::poll(fds, wake_fd_[0] >= 0 ? 2 : 1, static_cast<int>(wait));
        if (n < 0 && errno != EINTR) {
          end.error = net::transport_error("CONNECTION_FAILED", std::strerror(errno));
          return end;
        }
        if (n > 0 && (fds[1].revents & POLLIN)) {
          char drain[64];
          while (::read(wake_fd_[0], drain, sizeof drain) > 0) {
          }
        }
        readable = n > 0 && (fds[0].revents & (POLLIN | POLLHUP | POLLERR));
      }
      if (end.connected) {  // queued frames go out once connected
        std::vector<std::string> out;
        {
          std::lock_guard<std::mutex> lock(mu_);
          out.swap(outbox_);
        }
        for (size_t i = 0; i < out.size(); ++i) {
          if (!send_text(out[i])) {
            std::lock_guard<std::mutex> lock(mu_);
            outbox_.insert(outbox_.begin(), out.begin() + static_cast<std::ptrdiff_t>(i), out.end());
            end.error = net::transport_error("CONNECTION_FAILED", "send failed");
            return end;
          }
          last_send = mono_ms();
        }
      }
      if (!readable) continue;
      auto r = conn.read_some(buf, 1000);
      if (!r.ok()) {
        if (r.error().code == "TIMEOUT") continue;
        end.error = r.error();
        return end;
      }
      if (*r == 0) {
        end.error = net::transport_error("CONNECTION_CLOSED", "the node closed the connection");
        return end;
      }
    }
    send_control(8, std::string("\x03\xe8", 2));  // 1000 normal closure
    return end;
  };

  while (!stop_.load()) {
    state("connecting");
    SessionEnd end = one_session();
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
      if (::poll(&p, wake_fd_[0] >= 0 ? 1 : 0, static_cast<int>(std::min<int64_t>(left, 1000))) > 0) {
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
