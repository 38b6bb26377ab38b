// A real rcan-registry started by a test (RCAN_REGISTRY_PATH) on an ephemeral loopback port,
// with its data directory, URL and the admin key it wrote on first start (empty when the
// database had admin keys already). Header-only.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <string>
#include <vector>

#include "rcan/crypto/keys.h"
#include "rcan/crypto/registry_proof.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/registry.h"
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
    // Only a start that made the database's first admin key writes admin.key.
    if (::access((dir_ + "/admin.key").c_str(), F_OK) == 0) admin_ = read_file(dir_ + "/admin.key");
  }
  ~RegistryDaemon() {
    if (proc_.running()) proc_.stop(SIGTERM, 10000);
  }
  const std::string& url() const { return url_; }
  uint16_t port() const { return port_; }
  const std::string& admin_key() const { return admin_; }

  // Registers manufacturer/model/version/device with `key` as a robot does: a challenge, fresh
  // identity keys (`keys`, when given, receives them) and their proof of possession, and
  // `metadata` (a JSON object's text).
  HttpReply register_proven(const std::string& key, const std::string& manufacturer,
                            const std::string& model, const std::string& version,
                            const std::string& device, const std::string& metadata = "{}",
                            keys::RobotKeys* keys = nullptr) const {
    auto ch = get("/api/v1/challenge");
    EXPECT_EQ(ch.status, 200) << ch.body;
    auto c = json::parse(ch.body);
    auto k = keys::generate();
    auto meta = json::parse(metadata);
    if (!c.ok() || !k.ok() || !meta.ok()) {
      ADD_FAILURE() << "challenge, keys or metadata: " << ch.body << " " << metadata;
      return {};
    }
    const std::string id = json::string_field(*c, "challenge_id");
    auto proof =
        registry::sign_proof(*k, id,
                             registry::proof_message(id, json::string_field(*c, "nonce"),
                                                     manufacturer, model, version, device));
    EXPECT_TRUE(proof.ok());
    json::Object body{{"manufacturer", manufacturer},
                      {"model", model},
                      {"version", version},
                      {"device_id", device},
                      {"metadata", *meta},
                      {"ed25519_public_key", base64url_encode(k->pub.ed25519_pk)},
                      {"mldsa65_public_key", base64url_encode(k->pub.mldsa65_pk)},
                      {"proof", proof->to_json()}};
    if (keys != nullptr) *keys = std::move(*k);
    return send("POST", "/api/v1/robots", json::dump(json::Value(std::move(body))), key);
  }
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
