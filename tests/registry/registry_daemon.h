// A real rcan-registry started by a test (RCAN_REGISTRY_PATH) on an ephemeral loopback port,
// with its data directory, URL and the admin key it wrote on first start. Header-only.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>

#include <string>
#include <vector>

#include "rcan/json.h"
#include "test_support.h"

namespace rcan::test {

class RegistryDaemon {
 public:
  explicit RegistryDaemon(const std::string& data_dir, std::vector<std::string> extra = {})
      : dir_(data_dir) {
    std::vector<std::string> argv{RCAN_REGISTRY_PATH, "--data-dir", dir_, "--port", "0"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    proc_.start(argv);
    auto line = proc_.wait_for_line("\"event\":\"listening\"", 30000);
    if (!line) {
      ADD_FAILURE() << "rcan-registry did not start:\n" << proc_.err();
      return;
    }
    auto v = json::parse(*line);
    if (!v.ok()) {
      ADD_FAILURE() << *line;
      return;
    }
    url_ = v->get("url")->as_string();
    port_ = static_cast<uint16_t>(std::stoi(url_.substr(url_.rfind(':') + 1)));
    admin_ = read_file(dir_ + "/admin.key");
  }
  ~RegistryDaemon() {
    if (proc_.running()) proc_.stop(SIGTERM, 10000);
  }
  const std::string& url() const { return url_; }
  uint16_t port() const { return port_; }
  const std::string& admin_key() const { return admin_; }
  Process& proc() { return proc_; }

  HttpReply get(const std::string& target, const std::string& key = {}) const {
    return http(port_, "GET", target, {}, auth(key));
  }
  HttpReply send(const std::string& method, const std::string& target, const std::string& body,
                 const std::string& key = {}) const {
    auto h = auth(key);
    h.emplace_back("Content-Type", "application/json");
    return http(port_, method, target, body, h);
  }

 private:
  static std::vector<std::pair<std::string, std::string>> auth(const std::string& key) {
    if (key.empty()) return {};
    return {{"Authorization", "Bearer " + key}};
  }
  std::string dir_;
  Process proc_;
  std::string url_;
  uint16_t port_ = 0;
  std::string admin_;
};

}  // namespace rcan::test
