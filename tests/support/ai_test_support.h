// Helpers for the §16 end-to-end tests: a configured rcand with gates and layers, the
// built-in simulated layer as a child process, a webhook receiver, stream helpers.
#pragma once

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/watermark.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "rcan/message.h"
#include "test_support.h"

namespace rcan::ai_test {

inline int64_t wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline json::Value parse(const std::string& s) {
  auto v = json::parse(s, {.max_depth = 128, .max_bytes = 64u << 20});
  EXPECT_TRUE(v.ok()) << s.substr(0, 300);
  return v.ok() ? *v : json::Value(json::Object{});
}

inline std::string error_code(const test::HttpReply& r) {
  json::Value v = parse(r.body);
  const json::Value* p = v.get("payload");
  const json::Value* c = p ? p->get("error_code") : nullptr;
  return c && c->is_string() ? c->as_string() : "";
}

inline json::Object ai_block(const std::string& provider, const std::string& model,
                             double confidence, const std::string& layer,
                             const std::string& thought_id = "") {
  json::Object o{{"provider", provider},
                 {"model", model},
                 {"confidence", confidence},
                 {"layer", layer},
                 {"escalated", false}};
  if (!thought_id.empty()) o.set("thought_id", thought_id);
  return o;
}

// A seed-shape COMMAND; `ai` empty = none; `extra` is appended as top-level members.
inline std::string cmd(const std::string& id, const std::string& action, json::Object params,
                       json::Object ai = {}, const std::string& extra = "") {
  json::Object payload{{"action", action}};
  for (auto& m : params) payload.set(m.first, m.second);
  json::Object m{{"version", "1.0.0"},
                 {"message_id", id},
                 {"type", "COMMAND"},
                 {"timestamp_ms", wall_ms()},
                 {"payload", payload}};
  if (!ai.empty()) m.set("ai", ai);
  std::string s = json::dump(json::Value(m));
  if (!extra.empty()) s = s.substr(0, s.size() - 1) + extra + "}";
  return s;
}

inline uint16_t port_of(const std::string& listening_line) {
  json::Value v = parse(listening_line);
  std::string url = v.get("url")->as_string();
  return static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
}

// `rcand --sim-layer` as a child process.
class SimLayerProc {
 public:
  SimLayerProc(const std::string& layer, double confidence, int delay_ms = 0) {
    proc_.start({RCAND_PATH, "--sim-layer", "--port", "0", "--layer", layer, "--confidence",
                 std::to_string(confidence), "--delay-ms", std::to_string(delay_ms)});
    auto line = proc_.wait_for_line("\"event\":\"listening\"", 30000);
    if (!line) {
      ADD_FAILURE() << "the sim layer did not start: " << proc_.err();
      return;
    }
    port_ = port_of(*line);
  }
  ~SimLayerProc() {
    if (proc_.running()) proc_.stop(SIGTERM, 5000);
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_) + "/"; }
  // Requests the layer logged so far.
  int requests_seen() {
    proc_.drain(50);
    int n = 0;
    for (size_t at = 0;
         (at = proc_.err().find("\"event\":\"layer_request\"", at)) != std::string::npos; ++at)
      ++n;
    return n;
  }

 private:
  test::Process proc_;
  uint16_t port_ = 0;
};

// A loopback HTTP server that records POST bodies and answers 200.
class WebhookReceiver {
 public:
  WebhookReceiver() {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a);
    ::listen(fd_, 16);
    socklen_t len = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { loop(); });
  }
  ~WebhookReceiver() {
    quit_ = true;
    thread_.join();
    ::close(fd_);
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_) + "/hook"; }
  bool wait_for(const std::string& needle, int timeout_ms = 5000) {
    for (int waited = 0; waited < timeout_ms; waited += 20) {
      {
        std::lock_guard<std::mutex> lock(mu_);
        for (const auto& b : bodies_)
          if (b.find(needle) != std::string::npos) return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }

 private:
  void loop() {
    while (!quit_) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      int c = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (c < 0) continue;
      std::string req;
      char buf[8192];
      for (int i = 0; i < 100; ++i) {
        pollfd q{c, POLLIN, 0};
        if (::poll(&q, 1, 50) <= 0) continue;
        ssize_t n = ::recv(c, buf, sizeof buf, 0);
        if (n <= 0) break;
        req.append(buf, static_cast<size_t>(n));
        size_t he = req.find("\r\n\r\n");
        if (he != std::string::npos) {
          size_t cl = req.find("Content-Length: ");
          size_t want = cl == std::string::npos ? 0 : std::stoul(req.substr(cl + 16));
          if (req.size() >= he + 4 + want) break;
        }
      }
      const char* ok = "HTTP/1.1 200 OK\r\nContent-Length: 0\r\nConnection: close\r\n\r\n";
      ::send(c, ok, std::strlen(ok), MSG_NOSIGNAL);
      ::close(c);
      size_t he = req.find("\r\n\r\n");
      std::lock_guard<std::mutex> lock(mu_);
      bodies_.push_back(he == std::string::npos ? req : req.substr(he + 4));
    }
  }
  int fd_ = -1;
  uint16_t port_ = 0;
  std::atomic<bool> quit_{false};
  std::thread thread_;
  std::mutex mu_;
  std::vector<std::string> bodies_;
};

// A configured rcand in `dir` (data in dir/data) with the given `agent:` YAML block.
class AiNode {
 public:
  static constexpr const char* kRuri = "rcan://local.rcan/acme/ai-rover/0a1b2c3d";
  static constexpr const char* kRrn = "RRN-000000000042";

  // `expect_start` false: the daemon is expected to refuse its configuration (exit 1).
  AiNode(const std::string& dir, const std::string& agent_yaml, bool fresh = true,
         bool expect_start = true)
      : dir_(dir) {
    std::string data = dir_ + "/data";
    if (fresh) {
      std::filesystem::create_directories(data);
      std::filesystem::permissions(data, std::filesystem::perms::owner_all);
      EXPECT_TRUE(test::generate_robot_keys(data + "/keys"));
      EXPECT_TRUE(test::create_audit_secret(data + "/audit.secret"));
      Bytes seed(32);
      EXPECT_TRUE(random_bytes(seed.data(), seed.size()));
      {
        std::ofstream out(dir_ + "/issuer.seed", std::ios::binary);
        out.write(reinterpret_cast<const char*>(seed.data()),
                  static_cast<std::streamsize>(seed.size()));
      }
      std::filesystem::permissions(dir_ + "/issuer.seed", std::filesystem::perms::owner_read |
                                                              std::filesystem::perms::owner_write);
      auto pk = ed25519::public_key_from_seed(seed);
      auto pem = ed25519::public_key_to_pem(*pk);
      std::ofstream(dir_ + "/issuer.pub.pem") << *pem;
      std::ofstream cfg(dir_ + "/robot.rcan.yaml");
      cfg << "rcan_version: \"1.2\"\nruri: " << kRuri << "\nrrn: " << kRrn
          << "\nrobot: {name: ai-rover, manufacturer: acme, model: ai-rover, type: "
             "mobile_differential_with_arm}\n"
             "capabilities: [status, chat, teleop, nav, arm]\n"
             "safety: {local_safety_wins: true, max_linear_speed_mps: 0.5}\n"
             "security:\n  jwt:\n    issuers: [{issuer: ai-test, key_file: "
          << dir_ << "/issuer.pub.pem}]\n"
          << agent_yaml;
    }
    owner_ = token("owner", {"status", "control", "config"});
    leasee_ = token("leasee", {"status", "chat", "control"});
    write_token(owner_file(), owner_);
    write_token(leasee_file(), leasee_);
    proc_.start(
        {RCAND_PATH, "--config", dir_ + "/robot.rcan.yaml", "--data-dir", data, "--port", "0"});
    if (!expect_start) {
      exit_code_ = proc_.stop(0, 15000);
      return;
    }
    auto line = proc_.wait_for_line("\"event\":\"listening\"", 30000);
    if (!line) {
      ADD_FAILURE() << "rcand did not start:\n" << proc_.err();
      return;
    }
    port_ = port_of(*line);
  }
  ~AiNode() {
    if (proc_.running()) proc_.stop(SIGTERM, 10000);
  }
  int terminate() { return proc_.stop(SIGTERM, 15000); }
  int exit_code() const { return exit_code_; }
  const std::string& log() const { return proc_.err(); }
  uint16_t port() const { return port_; }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  std::string rrn() const { return kRrn; }
  const std::string& owner() const { return owner_; }
  const std::string& leasee() const { return leasee_; }
  std::string owner_file() const { return dir_ + "/owner.token"; }
  std::string leasee_file() const { return dir_ + "/leasee.token"; }

  std::string token(const std::string& role, std::vector<std::string> scopes) const {
    auto key = jwt::SigningKey::from_file(dir_ + "/issuer.seed");
    EXPECT_TRUE(key.ok());
    int64_t now = wall_ms() / 1000;
    json::Array sc;
    for (auto& s : scopes) sc.emplace_back(s);
    json::Object claims{{"iss", "ai-test"}, {"sub", role + "-1"}, {"aud", kRuri},
                        {"role", role},     {"scope", sc},        {"iat", now - 5},
                        {"exp", now + 3600}};
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }

  test::HttpReply get(const std::string& path, const std::string& token = "") const {
    std::vector<std::pair<std::string, std::string>> h;
    if (!token.empty()) h.emplace_back("Authorization", "Bearer " + token);
    return test::http(port_, "GET", path, "", h);
  }
  test::HttpReply post(const std::string& path, const std::string& body,
                       const std::string& token) const {
    std::vector<std::pair<std::string, std::string>> h;
    if (!token.empty()) h.emplace_back("Authorization", "Bearer " + token);
    return test::http(port_, "POST", path, body, h, 20000);
  }
  test::HttpReply command(const std::string& token, const std::string& body) const {
    return post("/rcan/v1/command", body, token);
  }
  test::HttpReply authorize(const std::string& token, const std::string& id,
                            const std::string& decision, const std::string& reason = "") const {
    json::Object payload{{"message_id", id}, {"decision", decision}};
    if (!reason.empty()) payload.set("reason", reason);
    json::Object m{{"type", "AUTHORIZE"}, {"message_id", new_uuid_v4()}, {"payload", payload}};
    return post("/rcan/v1/authorize", json::dump(json::Value(m)), token);
  }

  // Audit records with this message_id and event, waiting (up to 5 s) until at least
  // `at_least` are durable.
  std::vector<json::Value> records(const std::string& id, const std::string& event,
                                   size_t at_least = 0) const {
    std::vector<json::Value> out;
    for (int i = 0; i < 100; ++i) {
      out.clear();
      test::HttpReply r = get("/api/audit?limit=1000", owner_);
      json::Value v = parse(r.body);
      if (const json::Value* es = v.get("entries"); es && es->is_array())
        for (const auto& e : es->as_array()) {
          const json::Value* mid = e.get("message_id");
          const json::Value* ev = e.get("event");
          if (mid && mid->is_string() && mid->as_string() == id && ev && ev->as_string() == event)
            out.push_back(e);
        }
      if (out.size() >= at_least) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return out;
  }
  json::Value record(const std::string& id, const std::string& event) const {
    auto r = records(id, event, 1);
    EXPECT_FALSE(r.empty()) << "no " << event << " record for " << id;
    return r.empty() ? json::Value(json::Object{}) : r.front();
  }

  std::string expected_watermark(const std::string& thought_id, const std::string& ts) const {
    auto key = watermark::load_key(dir_ + "/data/keys");
    EXPECT_TRUE(key.ok());
    if (!key.ok()) return {};
    return watermark::compute(*key, kRrn, thought_id, ts);
  }

 private:
  static void write_token(const std::string& path, const std::string& tok) {
    std::ofstream(path) << tok << "\n";
    std::filesystem::permissions(
        path, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  }
  std::string dir_;
  test::Process proc_;
  uint16_t port_ = 0;
  int exit_code_ = -1;
  std::string owner_, leasee_;
};

inline bool connect_stream(test::WsClient& ws, uint16_t port, const std::string& token) {
  if (ws.connect(port, "/rcan/v1/stream") != 101) return false;
  ws.send_text(json::dump(json::Value(json::Object{{"type", "CONNECT"}, {"token", token}})));
  auto ack = ws.recv_text(5000);
  return ack && ack->find("CONNECT_ACK") != std::string::npos;
}

// The next frame of `type` (and, when given, whose reply_to or payload.message_id is `id`).
inline std::optional<json::Value> wait_frame(test::WsClient& ws, const std::string& type,
                                             const std::string& id = "", int timeout_ms = 8000) {
  auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    auto f = ws.recv_text(static_cast<int>(std::max<int64_t>(left.count(), 1)));
    if (!f) return std::nullopt;
    json::Value v = parse(*f);
    const json::Value* t = v.get("type");
    if (!type.empty() && (!t || !t->is_string() || t->as_string() != type)) continue;
    if (id.empty()) return v;
    const json::Value* r = v.get("reply_to");
    const json::Value* p = v.get("payload");
    const json::Value* pm = p ? p->get("message_id") : nullptr;
    if ((r && r->is_string() && r->as_string() == id) ||
        (pm && pm->is_string() && pm->as_string() == id))
      return v;
  }
  return std::nullopt;
}

}  // namespace rcan::ai_test
