// ControlNode: a configured rcand for the control-session tests (not configured_node.h's
// ConfiguredNode, which the same test program holds): its own data directory, robot keys and
// chain secret made with the library, a test token issuer, and YAML the test adds to. Header-only.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

#include "configured_node.h"  // now_wall_ms, parse_json
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan::test {

// payload.error_code of an error body ("" when absent).
inline std::string error_code_of(const HttpReply& r) {
  json::Value v = parse_json(r.body);
  const json::Value* p = v.get("payload");
  const json::Value* c = p ? p->get("error_code") : nullptr;
  return c && c->is_string() ? c->as_string() : "";
}

inline std::string command_msg(const std::string& action, json::Object params = {}) {
  json::Object payload{{"action", action}};
  for (auto& m : params) payload.set(m.first, m.second);
  json::Object m{{"version", "1.0.0"},
                 {"message_id", new_uuid_v4()},
                 {"type", "COMMAND"},
                 {"timestamp_ms", now_wall_ms()},
                 {"payload", payload}};
  return json::dump(json::Value(m));
}

class ControlNode {
 public:
  static constexpr const char* kRuri = "rcan://local.rcan/acme/rover/0a1b2c3d";

  ControlNode(const std::string& dir, const std::string& extra_yaml) : dir_(dir) {
    namespace fs = std::filesystem;
    fs::create_directories(dir_);
    data_ = dir_ + "/data";
    fs::create_directories(data_);
    fs::permissions(data_, fs::perms::owner_all);
    EXPECT_TRUE(generate_robot_keys(data_ + "/keys"));
    EXPECT_TRUE(create_audit_secret(data_ + "/audit.secret"));
    auto seed = hex("0909090909090909090909090909090909090909090909090909090909090909");
    seed_file_ = dir_ + "/issuer.seed";
    {
      std::ofstream out(seed_file_, std::ios::binary);
      out.write(reinterpret_cast<const char*>(seed.data()),
                static_cast<std::streamsize>(seed.size()));
    }
    fs::permissions(seed_file_, fs::perms::owner_read | fs::perms::owner_write);
    auto pk = ed25519::public_key_from_seed(seed);
    EXPECT_TRUE(pk.ok());
    auto pem = ed25519::public_key_to_pem(*pk);
    EXPECT_TRUE(pem.ok());
    {
      std::ofstream out(dir_ + "/issuer.pub.pem");
      out << *pem;
    }
    std::ofstream cfg(dir_ + "/robot.rcan.yaml");
    cfg << "rcan_version: \"1.2\"\nruri: " << kRuri
        << "\nrobot:\n  name: Robot B\n  manufacturer: acme\n  model: rover\n  type: mobile\n"
           "safety:\n  local_safety_wins: true\n"
           "security:\n  jwt:\n    issuers:\n      - issuer: ops.example\n        key_file: "
        << dir_ << "/issuer.pub.pem\n"
        << extra_yaml;
  }
  ~ControlNode() { stop(); }

  bool start() {
    proc_ = std::make_unique<Process>();
    proc_->start(
        {RCAND_PATH, "--config", dir_ + "/robot.rcan.yaml", "--port", "0", "--data-dir", data_});
    auto line = proc_->wait_for_line("\"event\":\"listening\"", 30000);
    if (!line) {
      ADD_FAILURE() << "rcand did not start:\n" << proc_->err();
      return false;
    }
    json::Value v = parse_json(*line);
    std::string url = v.get("url")->as_string();
    port_ = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
    return true;
  }
  int stop() {
    if (!proc_ || !proc_->running()) return 0;
    return proc_->stop(SIGTERM, 15000);
  }
  uint16_t port() const { return port_; }
  const std::string& data_dir() const { return data_; }
  Process& proc() { return *proc_; }

  std::string token(const std::string& role, const std::string& sub,
                    std::vector<std::string> scopes = {"control"}, int64_t ttl_s = 3600,
                    json::Object extra = {}) const {
    auto key = jwt::SigningKey::from_file(seed_file_);
    EXPECT_TRUE(key.ok());
    int64_t now = now_wall_ms() / 1000;
    json::Array sc;
    for (auto& s : scopes) sc.emplace_back(s);
    json::Object claims{{"iss", "ops.example"}, {"sub", sub},  {"aud", kRuri},
                        {"role", role},         {"scope", sc}, {"iat", now - 5},
                        {"exp", now + ttl_s}};
    for (auto& m : extra) claims.set(m.first, m.second);
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }

  HttpReply call(const std::string& method, const std::string& path, const std::string& body,
                 const std::string& token) const {
    std::vector<std::pair<std::string, std::string>> h;
    if (!token.empty()) h.emplace_back("Authorization", "Bearer " + token);
    return http(port_, method, path, body, h);
  }
  HttpReply get(const std::string& path, const std::string& token = "") const {
    return call("GET", path, "", token);
  }
  HttpReply post(const std::string& path, const std::string& body, const std::string& token) const {
    return call("POST", path, body, token);
  }

  // Audit records (newest last) whose event is `event`.
  std::vector<json::Value> audit(const std::string& event, const std::string& token) const {
    std::vector<json::Value> out;
    HttpReply r = get("/api/audit?limit=1000", token);
    json::Value v = parse_json(r.body);
    if (const json::Value* es = v.get("entries"); es && es->is_array())
      for (const auto& e : es->as_array())
        if (e.get("event") && e.get("event")->as_string() == event) out.push_back(e);
    return out;
  }

  // Audit records of `event` once at least `min` are durable (events on the streams run ahead
  // of the records they announce); what is there after `timeout_ms` otherwise.
  std::vector<json::Value> audit_eventually(const std::string& event, const std::string& token,
                                            size_t min = 1, int timeout_ms = 5000) const {
    std::vector<json::Value> out;
    eventually([&] { return (out = audit(event, token)).size() >= min; }, timeout_ms);
    return out;
  }

  // Polls `pred` (every 20 ms) until it holds or `timeout_ms` passes.
  static bool eventually(const std::function<bool()>& pred, int timeout_ms = 5000) {
    return test::eventually(pred, timeout_ms);
  }

 private:
  std::string dir_, data_, seed_file_;
  std::unique_ptr<Process> proc_;
  uint16_t port_ = 0;
};

// A CONNECTed stream of one principal.
class Stream {
 public:
  Stream(uint16_t port, const std::string& token) {
    EXPECT_EQ(ws_.connect(port, "/rcan/v1/stream"), 101);
    ws_.send_text(json::dump(json::Value(json::Object{{"type", "CONNECT"}, {"token", token}})));
    auto ack = ws_.recv_text(5000);
    EXPECT_TRUE(ack && ack->find("CONNECT_ACK") != std::string::npos) << (ack ? *ack : "no answer");
  }
  // The next frame whose "event" (or "type") equals `name`, within `timeout_ms`.
  std::optional<json::Value> wait_for(const std::string& name, int timeout_ms = 5000) {
    auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      int left = static_cast<int>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                      end - std::chrono::steady_clock::now())
                                      .count());
      if (left <= 0) return std::nullopt;
      auto f = ws_.recv_text(left);
      if (!f) return std::nullopt;
      auto v = json::parse(*f, {.max_depth = 64, .max_bytes = 1u << 20});
      if (!v.ok()) continue;
      frames_.push_back(*f);
      const json::Value* ev = v->get("event");
      const json::Value* ty = v->get("type");
      if ((ev && ev->is_string() && ev->as_string() == name) ||
          (ty && ty->is_string() && ty->as_string() == name))
        return *v;
    }
  }
  const std::vector<std::string>& seen() const { return frames_; }
  WsClient& ws() { return ws_; }

 private:
  WsClient ws_;
  std::vector<std::string> frames_;
};

}  // namespace rcan::test

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <mutex>

namespace rcan::test {

// A small real HTTP server on loopback: answers every request 200 "{}" and keeps the
// request bodies. Stops (and closes its port) on stop() or destruction; start() again on the
// same port.
class TinyHttpServer {
 public:
  TinyHttpServer() = default;
  ~TinyHttpServer() { stop(); }
  bool start(uint16_t port = 0) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    int one = 1;
    ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(port);
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd_, 16) != 0)
      return false;
    socklen_t len = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    running_ = true;
    thread_ = std::thread([this] { loop(); });
    return true;
  }
  void stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  uint16_t port() const { return port_; }
  std::string url(const std::string& path) const {
    return "http://127.0.0.1:" + std::to_string(port_) + path;
  }
  std::vector<std::string> bodies() {
    std::lock_guard<std::mutex> lock(mu_);
    return bodies_;
  }
  int hits() const { return hits_.load(); }

 private:
  void loop() {
    while (running_) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      int c = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (c < 0) continue;
      std::string in;
      char buf[4096];
      for (;;) {
        pollfd q{c, POLLIN, 0};
        if (::poll(&q, 1, 1000) <= 0) break;
        ssize_t n = ::recv(c, buf, sizeof buf, 0);
        if (n <= 0) break;
        in.append(buf, static_cast<size_t>(n));
        size_t h = in.find("\r\n\r\n");
        if (h == std::string::npos) continue;
        size_t cl = 0;
        size_t k = in.find("Content-Length: ");
        if (k != std::string::npos && k < h) cl = std::stoul(in.substr(k + 16));
        if (in.size() >= h + 4 + cl) {
          std::lock_guard<std::mutex> lock(mu_);
          bodies_.push_back(in.substr(h + 4, cl));
          break;
        }
      }
      hits_.fetch_add(1);
      const char* resp =
          "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 2\r\nConnection: "
          "close\r\n\r\n{}";
      (void)::send(c, resp, std::strlen(resp), MSG_NOSIGNAL);
      ::close(c);
    }
  }
  int fd_ = -1;
  uint16_t port_ = 0;
  std::atomic<bool> running_{false};
  std::atomic<int> hits_{0};
  std::thread thread_;
  std::mutex mu_;
  std::vector<std::string> bodies_;
};

}  // namespace rcan::test
