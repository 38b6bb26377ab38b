// One real robot node per fuzzing process, built as rcand builds it (src/node: NodeServices,
// the safety core over the simulated robot, the audit log, the §16 services, Node) in a
// temporary data directory, without sockets: the fuzz targets call Node::handle() and
// Node::open() exactly as the Beast transport does.
//
// Inputs may carry placeholders that the harness expands before use, so that seeds reach
// past authentication and the replay guard:
//   @GUEST@ @USER@ @LEASEE@ @OWNER@ @CREATOR@   a valid token of that role (all scopes)
//   @UUID@                                      a fresh message id (one per occurrence)
//   @UUID1@ … @UUID9@                           a fresh id, the same for the whole input
//   @NOW@ / @NOW_S@                             the node's wall clock in ms / in seconds (rcan-py)
// The node carries its state from one input to the next (sessions, audit, replay cache) like a
// long-running rcand; a latched ESTOP is cleared before each input so that later inputs still
// reach the dispatch path.
#pragma once

#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "base/clock.h"
#include "config/config.h"
#include "node/ai/ai_services.h"
#include "node/api/node.h"
#include "node/safety/actuation_safety.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/errors.h"
#include "rcan/json.h"

namespace rcan::fuzz {

class NodeHarness {
 public:
  static constexpr std::string_view kIssuer = "fuzz-issuer";

  // The process's node, created on first use and stopped at exit.
  static NodeHarness& get() {
    static NodeHarness* h = [] {
      instance() = new NodeHarness();
      std::atexit([] { instance()->stop(); });
      return instance();
    }();
    return *h;
  }

  node::Node& node() { return *node_; }
  node::NodeServices& services() { return *services_; }
  const std::string& ruri() const { return ruri_; }

  // Called before each input.
  void reset() {
    for (auto& u : numbered_) u.clear();
    if (core_->estop_active()) (void)core_->resume(5, "fuzz harness");
  }

  std::string expand(std::string_view in) {
    std::string out;
    out.reserve(in.size());
    size_t i = 0;
    while (i < in.size()) {
      size_t at = in.find('@', i);
      if (at == std::string_view::npos) break;
      out.append(in.substr(i, at - i));
      size_t end = in.find('@', at + 1);
      std::string_view name =
          end == std::string_view::npos ? std::string_view() : in.substr(at + 1, end - at - 1);
      std::string rep;
      bool known = true;
      if (name == "UUID") {
        rep = new_uuid_v4();
      } else if (name.size() == 5 && name.substr(0, 4) == "UUID" && name[4] >= '1' &&
                 name[4] <= '9') {
        std::string& u = numbered_[static_cast<size_t>(name[4] - '1')];
        if (u.empty()) u = new_uuid_v4();
        rep = u;
      } else if (name == "NOW") {
        rep = std::to_string(services_->clock.wall_ms());
      } else if (name == "NOW_S") {
        const int64_t ms = services_->clock.wall_ms();
        rep = std::to_string(ms / 1000) + "." + std::to_string(ms % 1000 / 100);
      } else if (int r = role_index(name); r >= 0) {
        rep = tokens_[static_cast<size_t>(r)];
      } else {
        known = false;
      }
      if (known) {
        out += rep;
        i = end + 1;
      } else {
        out += '@';
        i = at + 1;
      }
    }
    if (i < in.size()) out.append(in.substr(i));
    return out;
  }

 private:
  static NodeHarness*& instance() {
    static NodeHarness* p = nullptr;
    return p;
  }

  static int role_index(std::string_view name) {
    static constexpr std::array<std::string_view, 5> kNames{"GUEST", "USER", "LEASEE", "OWNER",
                                                            "CREATOR"};
    for (size_t i = 0; i < kNames.size(); ++i)
      if (name == kNames[i]) return static_cast<int>(i);
    return -1;
  }

  [[noreturn]] static void die(const std::string& what) {
    std::fprintf(stderr, "node harness: %s\n", what.c_str());
    std::abort();
  }

  NodeHarness() {
    // tmpfs when there is one: the audit log syncs every group.
    std::string base = ::access("/dev/shm", W_OK) == 0
                           ? "/dev/shm"
                           : std::filesystem::temp_directory_path().string();
    std::string tmpl = base + "/rcan-fuzz-node-XXXXXX";
    if (!::mkdtemp(tmpl.data())) die("mkdtemp failed");
    dir_ = tmpl;
    const std::string device = "0f0f0f0f";

    // The daemon's own default configuration, with two confidence gates and one HiTL gate
    // (short timeout) so that the §16 paths are reachable.
    std::string yaml(config::default_config_yaml());
    auto put = [&](std::string_view from, std::string_view to) {
      size_t at = yaml.find(from);
      if (at == std::string::npos) die("default config changed: no '" + std::string(from) + "'");
      yaml.replace(at, from.size(), to);
    };
    put("confidence_gates: []",
        "confidence_gates:\n    - {scope: control, min_confidence: 0.7, on_fail: log}\n"
        "    - {scope: admin, min_confidence: 0.9, on_fail: block}");
    put("hitl_gates: []",
        "hitl_gates:\n    - action_types: [arm_deploy]\n      require_auth: true\n      "
        "auth_timeout_ms: 200\n"
        "      on_timeout: block");
    config::ConfigOptions co;
    co.device_id = device;
    co.default_data_dir = dir_;
    auto cfg = config::parse_config_text(yaml, co);
    if (!cfg.ok()) die("config: " + cfg.error().message);
    cfg->data_dir = dir_;
    ruri_ = cfg->ruri;

    audit::AuditOptions ao;
    ao.secret = "fuzz-chain-secret-0123456789abcdef";
    ao.robot_ruri = ruri_;
    ao.max_segment_bytes = 1u << 20;
    ao.preallocate = false;
    ao.retention_max_bytes = 8u << 20;  // long runs keep a bounded log
    auto log = audit::AuditLog::open(dir_ + "/audit", std::move(ao));
    if (!log.ok()) die("audit: " + log.error().message);
    audit_ = std::move(log).value();

    node::SimRobotConfig sim;
    node::SafetyConfig sc;
    core_ = std::make_unique<node::SafetyCore>(std::make_unique<node::SimRobot>(sim), sc);
    if (Status s = core_->open(dir_ + "/safety"); !s.ok()) die("safety: " + s.error().message);
    act_ = std::make_unique<node::SafetyActuation>(*core_, "fuzz robot");

    // A fixed issuer whose tokens the node trusts; one token per role.
    Bytes seed(32, 0x42);
    auto signing = jwt::SigningKey::ed25519_seed(seed);
    if (!signing.ok()) die("issuer key");
    auto verify = signing->verification_key();
    if (!verify.ok()) die("issuer public key");
    node::AuthOptions auth;
    auth.trust.add(std::string(kIssuer), *verify);
    auth.verify.audience = ruri_;
    auth.verify.fleet_ids = {device, ruri_};
    const int64_t now_s = rcan::Clock::system().wall_ms() / 1000;
    static constexpr std::array<const char*, 5> kClaims{"guest", "user", "leasee", "owner",
                                                        "creator"};
    for (size_t i = 0; i < kClaims.size(); ++i) {
      json::Object claims{
          {"iss", std::string(kIssuer)},
          {"sub", std::string("fuzz-") + kClaims[i]},
          {"aud", ruri_},
          {"role", kClaims[i]},
          {"scope", json::Array{"status", "chat", "control", "config", "training", "admin"}},
          {"iat", now_s},
          {"exp", now_s + 7 * 24 * 3600}};
      auto t = jwt::issue(claims, *signing);
      if (!t.ok()) die("token: " + t.error().message);
      tokens_[i] = *t;
    }

    node::NodeSettings ns;
    ns.ruri = ruri_;
    ns.rrn = "RRN-000000000042";
    ns.name = "fuzz-robot";
    ns.rate_per_minute = {0, 0, 0,
                          0, 0, 0};  // no rate limit: the fuzzer sends thousands per second
    ns.state_dir = dir_;
    services_ = std::make_unique<node::NodeServices>(ns, rcan::Clock::system(), std::move(auth),
                                                     *act_, *audit_);

    auto robot_keys = keys::generate();
    if (!robot_keys.ok()) die("robot keys: " + robot_keys.error().message);
    node::AiOptions ai = node::ai_options(*cfg);
    ai.watermark_key = robot_keys->mldsa65_sk.clone();
    ai.pending_file = dir_ + "/hitl_pending.json";
    services_->ai = std::make_shared<node::AiServices>(*services_, std::move(ai));
    node_ = std::make_unique<node::Node>(*services_);
    if (Status s = services_->ai->start(node_->pipeline()); !s.ok())
      die("ai: " + s.error().message);
    core_->start();
    node_->start();
  }

  void stop() {
    if (!node_) return;
    services_->ai->shutdown();
    node_->shutdown();
    core_->stop();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string dir_;
  std::string ruri_;
  std::array<std::string, 5> tokens_;
  std::array<std::string, 9> numbered_;
  std::unique_ptr<audit::AuditLog> audit_;
  std::unique_ptr<node::SafetyCore> core_;
  std::unique_ptr<node::SafetyActuation> act_;
  std::unique_ptr<node::NodeServices> services_;
  std::unique_ptr<node::Node> node_;
};

}  // namespace rcan::fuzz
