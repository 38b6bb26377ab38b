// A real rcand started by a test (RCAND_PATH) on an ephemeral loopback port, with its
// data directory, URL and the OWNER token it wrote on first run. Header-only.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <string>
#include <vector>

#include "rcan/crypto/jwt.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan::test {

class RcandDaemon {
 public:
  explicit RcandDaemon(const std::string& data_dir, std::vector<std::string> extra = {},
                       std::vector<std::string> env = {})
      : dir_(data_dir) {
    std::vector<std::string> argv{RCAND_PATH, "--data-dir", dir_, "--port", "0"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    proc_.start(argv, env);
    auto line = proc_.wait_for_line("\"event\":\"listening\"", 30000);
    if (!line) {
      ADD_FAILURE() << "rcand did not start:\n" << proc_.err();
      return;
    }
    auto v = json::parse(*line);
    if (!v.ok()) {
      ADD_FAILURE() << *line;
      return;
    }
    url_ = v->get("url")->as_string();
    port_ = static_cast<uint16_t>(std::stoi(url_.substr(url_.rfind(':') + 1)));
    ruri_ = v->get("ruri")->as_string();
    token_file_ = dir_ + "/owner.token";
  }
  ~RcandDaemon() {
    if (proc_.running()) proc_.stop(SIGTERM, 10000);
  }
  const std::string& url() const { return url_; }
  uint16_t port() const { return port_; }
  const std::string& ruri() const { return ruri_; }
  const std::string& dir() const { return dir_; }
  const std::string& owner_token_file() const { return token_file_; }
  Process& proc() { return proc_; }

  // A token from the daemon's local issuer, written to `path` (mode 0600).
  std::string token(const std::string& role, const std::vector<std::string>& scopes,
                    const std::string& sub) const {
    auto key = jwt::SigningKey::from_file(dir_ + "/issuer/ed25519.seed");
    EXPECT_TRUE(key.ok());
    int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                      std::chrono::system_clock::now().time_since_epoch())
                      .count();
    json::Array sc;
    for (const auto& s : scopes) sc.emplace_back(s);
    json::Object claims{{"iss", "rcand-local"}, {"sub", sub},  {"aud", ruri_},
                        {"role", role},         {"scope", sc}, {"iat", now - 5},
                        {"exp", now + 3600}};
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }

 private:
  std::string dir_;
  Process proc_;
  std::string url_;
  uint16_t port_ = 0;
  std::string ruri_;
  std::string token_file_;
};

}  // namespace rcan::test
