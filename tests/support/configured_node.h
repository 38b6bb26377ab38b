// A configured rcand (--config) for the transport tests: robot keys and chain secret made with
// the library, a test token issuer (Ed25519) named in the config, gRPC and UDP on ephemeral ports.
// Header-only; include from one test program at a time.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan::test {

inline int64_t now_wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline json::Value parse_json(const std::string& s) {
  auto v = json::parse(s, {.max_depth = 128, .max_bytes = 64u << 20});
  EXPECT_TRUE(v.ok()) << s.substr(0, 300);
  return v.ok() ? *v : json::Value();
}

class ConfiguredNode {
 public:
  static constexpr const char* kRuri = "rcan://local.rcan/acme/rover/0a1b2c3d";

  // `extra_yaml` is appended to the config (top-level blocks); `security_yaml` to its security
  // block (keys indented by two spaces). heartbeat_timeout_ms and the control-loop rate are set
  // here; gRPC and UDP are on (port 0) unless `transports` is false. `driver_yaml`, when given,
  // is the whole `driver:` block instead of the simulator's; it follows the safety block, so
  // lines before `driver:` indented by two spaces are more safety keys.
  explicit ConfiguredNode(std::string extra_yaml = {}, int heartbeat_timeout_ms = 2000,
                          bool transports = true, const std::string& security_yaml = {},
                          const std::string& driver_yaml = {}) {
    data_ = dir_.file("data");
    std::filesystem::create_directories(data_);
    EXPECT_TRUE(generate_robot_keys(data_ + "/keys"));
    EXPECT_TRUE(create_audit_secret(data_ + "/audit.secret"));
    seed_file_ = dir_.file("issuer.seed");
    {
      uint8_t seed[32];
      EXPECT_TRUE(random_bytes(seed, sizeof seed));
      std::ofstream out(seed_file_, std::ios::binary);
      out.write(reinterpret_cast<const char*>(seed), sizeof seed);
    }
    std::filesystem::permissions(
        seed_file_, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
    auto key = jwt::SigningKey::from_file(seed_file_);
    EXPECT_TRUE(key.ok());
    Bytes seed_bytes = to_bytes(read_file(seed_file_));
    auto pk = ed25519::public_key_from_seed(seed_bytes);
    EXPECT_TRUE(pk.ok());
    auto pem = ed25519::public_key_to_pem(*pk);
    EXPECT_TRUE(pem.ok());
    std::string pub_file = dir_.file("issuer.pub.pem");
    {
      std::ofstream out(pub_file);
      out << *pem;
    }
    std::string cfg = dir_.file("robot.rcan.yaml");
    {
      std::ofstream out(cfg);
      out << "rcan_version: \"1.2\"\nruri: " << kRuri << "\n"
          << "robot:\n  name: test-rover\n  manufacturer: acme\n  model: rover\n  type: mobile\n"
          << "safety:\n  local_safety_wins: true\n  heartbeat_timeout_ms: " << heartbeat_timeout_ms
          << "\n"
          << (driver_yaml.empty() ? "driver:\n  type: sim\n  sim:\n    tick_hz: 200\n"
                                  : driver_yaml)
          << "security:\n  jwt:\n    issuers:\n      - issuer: test.local\n        key_file: "
          << pub_file << "\n"
          << security_yaml;
      if (transports)
        out << "grpc:\n  enabled: true\n  port: 0\nudp:\n  enabled: true\n  port: 0\n";
      out << extra_yaml;
    }
    if (!proc_.start({RCAND_PATH, "--config", cfg, "--port", "0", "--data-dir", data_})) {
      ADD_FAILURE() << "cannot start rcand";
      return;
    }
    auto line = proc_.wait_for_line("\"event\":\"listening\"", 60000);
    if (!line) {
      ADD_FAILURE() << "rcand did not start:\n" << proc_.err();
      return;
    }
    json::Value v = parse_json(*line);
    std::string url = v.get("url")->as_string();
    http_port_ = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
    auto port_of = [&](const std::string& event) -> uint16_t {
      size_t at = proc_.err().find("\"event\":\"" + event + "\"");
      if (at == std::string::npos) return 0;
      size_t start = proc_.err().rfind('\n', at);
      size_t end = proc_.err().find('\n', at);
      json::Value l = parse_json(
          proc_.err().substr(start == std::string::npos ? 0 : start + 1,
                             end == std::string::npos ? std::string::npos : end - start - 1));
      const json::Value* p = l.get("port");
      return p && p->is_int() ? static_cast<uint16_t>(p->as_int()) : 0;
    };
    grpc_port_ = port_of("grpc.listening");
    udp_port_ = port_of("udp.listening");
  }
  ~ConfiguredNode() {
    if (proc_.running()) proc_.stop(SIGTERM, 15000);
  }

  uint16_t http_port() const { return http_port_; }
  uint16_t grpc_port() const { return grpc_port_; }
  uint16_t udp_port() const { return udp_port_; }
  const std::string& data_dir() const { return data_; }
  Process& proc() { return proc_; }
  int terminate() { return proc_.stop(SIGTERM, 15000); }

  std::string token(const std::string& role, std::vector<std::string> scopes,
                    const std::string& sub = "", int64_t ttl_s = 3600) const {
    auto key = jwt::SigningKey::from_file(seed_file_);
    EXPECT_TRUE(key.ok());
    int64_t now = now_wall_ms() / 1000;
    json::Array sc;
    for (auto& s : scopes) sc.emplace_back(s);
    json::Object claims{{"iss", "test.local"},
                        {"sub", sub.empty() ? role + "-1" : sub},
                        {"aud", "rcan://local.rcan/acme/rover/*"},
                        {"role", role},
                        {"scope", sc},
                        {"iat", now - 5},
                        {"exp", now + ttl_s}};
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }

  HttpReply get(const std::string& path, const std::string& tok = "") const {
    std::vector<std::pair<std::string, std::string>> h;
    if (!tok.empty()) h.emplace_back("Authorization", "Bearer " + tok);
    return http(http_port_, "GET", path, "", h);
  }
  HttpReply post(const std::string& path, const std::string& body,
                 const std::string& tok = "") const {
    std::vector<std::pair<std::string, std::string>> h;
    if (!tok.empty()) h.emplace_back("Authorization", "Bearer " + tok);
    return http(http_port_, "POST", path, body, h);
  }

  // Every audit record (oldest first), through the API.
  std::vector<json::Value> audit(const std::string& owner_token) const {
    std::vector<json::Value> out;
    HttpReply r = get("/api/audit?limit=1000", owner_token);
    EXPECT_EQ(r.status, 200) << r.body.substr(0, 300);
    json::Value v = parse_json(r.body);
    if (const json::Value* e = v.get("entries"); e && e->is_array())
      for (const auto& x : e->as_array()) out.push_back(x);
    return out;
  }

  // The value of one metric line `name value` on /metrics (-1 when absent).
  double metric(const std::string& name) const { return metric_value(get("/metrics").body, name); }

 private:
  TempDir dir_;
  std::string data_;
  std::string seed_file_;
  Process proc_;
  uint16_t http_port_ = 0, grpc_port_ = 0, udp_port_ = 0;
};

inline std::string command_json(const std::string& action, json::Object params = {},
                                std::string id = "") {
  json::Object payload{{"action", action}};
  for (auto& m : params) payload.set(m.first, m.second);
  json::Object m{{"version", "1.0.0"},
                 {"message_id", id.empty() ? new_uuid_v4() : id},
                 {"type", "COMMAND"},
                 {"timestamp_ms", now_wall_ms()},
                 {"payload", payload}};
  return json::dump(json::Value(m));
}

}  // namespace rcan::test
