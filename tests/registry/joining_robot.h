// A robot that joins a registry, for the tests that start rcan-registry and rcand: its keys,
// chain secret, a token issuer of its own and the `registry` block. Header-only.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {

inline constexpr const char* kRuri = "rcan://local.rcan/acme/rover/0a1b2c3d";

inline json::Value json_of(const std::string& s) {
  auto v = json::parse(s);
  EXPECT_TRUE(v.ok()) << s.substr(0, 300);
  return v.ok() ? *v : json::Value();
}

inline std::string str(const json::Value& v, const char* k) {
  const json::Value* m = v.get(k);
  return m != nullptr && m->is_string() ? m->as_string() : std::string();
}

inline void write_private(const std::string& path, const std::string& text) {
  std::ofstream(path) << text;
  std::filesystem::permissions(
      path, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
}

// A registrant key made with the admin key, in a 0600 file.
// The first line of a file (a key or a token saved with its newline).
inline std::string first_line(const std::string& path) {
  std::string k = read_file(path);
  return k.substr(0, k.find('\n'));
}

inline std::string registrant_key_file(const RegistryDaemon& reg, const std::string& reg_dir,
                                       const std::string& path) {
  auto r = run_cli({"registry", "keys", "create", "--registry", reg.url(), "--label", "fleet-ops",
                    "--save", path},
                   {}, {"RCAN_REGISTRY_KEY_FILE=" + reg_dir + "/admin.key"});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  return path;
}

// A configured robot: keys, chain secret, a token issuer, and the `registry` block.
class JoiningRobot {
 public:
  // `registry_yaml`: more keys of the registry block (indented by two); `extra_yaml`: more
  // top-level blocks.
  JoiningRobot(const std::string& dir, const std::string& registry_url, const std::string& key_file,
               const std::string& ruri = kRuri, const std::string& registry_yaml = {},
               const std::string& extra_yaml = {})
      : dir_(dir), data_(dir + "/data"), ruri_(ruri), port_(free_port()) {
    std::filesystem::create_directories(data_);
    EXPECT_TRUE(generate_robot_keys(data_ + "/keys"));
    EXPECT_TRUE(create_audit_secret(data_ + "/audit.secret"));
    EXPECT_TRUE(create_token_issuer(dir_ + "/issuer"));
    std::ofstream(dir_ + "/robot.rcan.yaml")
        << "rcan_version: \"1.2\"\nruri: " << ruri_ << "\n"
        << "robot:\n  name: join-rover\n  manufacturer: acme\n  model: rover\n  type: mobile\n"
        << "driver:\n  type: sim\n"
        << "security:\n  jwt:\n    issuers:\n      - issuer: test.local\n        key_file: " << dir_
        << "/issuer/ed25519.pub.pem\n"
        << "registry:\n  registry_url: " << registry_url << "\n  key_file: " << key_file
        << "\n  endpoint: " << url() << "\n  refresh_s: 10\n"
        << registry_yaml << extra_yaml;
  }
  // Where it serves (and what it publishes as its endpoint).
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  uint16_t port() const { return port_; }
  // An OWNER token of its test issuer, in a file.
  std::string owner_token_file() const {
    auto t = run_cli({"token", "issue", "--key", dir_ + "/issuer/ed25519.seed", "--iss",
                      "test.local", "--sub", "alice", "--role", "owner", "--aud", ruri_});
    EXPECT_EQ(t.exit_code, 0) << t.err;
    std::string path = dir_ + "/owner.token";
    write_private(path, t.out);
    return path;
  }
  // Starts rcand; returns the RRN of its "listening" line (empty when it did not start).
  std::string start() {
    proc_ = std::make_unique<Process>();
    EXPECT_TRUE(proc_->start({RCAND_PATH, "--config", dir_ + "/robot.rcan.yaml", "--port",
                              std::to_string(port_), "--data-dir", data_}));
    auto line = proc_->wait_for_line("\"event\":\"listening\"", 60000);
    if (!line) {
      ADD_FAILURE() << "rcand did not start:\n" << proc_->err();
      return {};
    }
    return str(json_of(*line), "rrn");
  }
  int stop() { return proc_->stop(SIGTERM, 15000); }
  Process& proc() { return *proc_; }
  const std::string& data() const { return data_; }

 private:
  std::string dir_, data_, ruri_;
  uint16_t port_ = 0;
  std::unique_ptr<Process> proc_;
};

}  // namespace rcan::test
