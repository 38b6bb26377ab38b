// rcand — the RCAN robot node.
//
//   rcand                         the simulated robot with a generated identity in the default
//                                 data directory (first run creates keys, the audit chain
//                                 secret, a local token issuer and an OWNER token)
//   rcand --config FILE           a configured robot (.rcan.yaml, docs/CONFIG.md)
//   rcand … --port N --data-dir D overrides
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include "node/actuation_safety.h"
#include "node/ai.h"
#include "node/clock.h"
#include "node/config.h"
#include "node/fleet.h"
#include "node/log.h"
#include "node/mqtt_node.h"
#include "node/mdns.h"
#include "node/node.h"
#include "node/safety.h"
#include "node/sim_robot.h"
#include "rcan/audit/secret.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "extra_transports.h"
#include "transport/http_server.h"

// Read by jemalloc, which rcand links (CMakeLists.txt), when it starts: a background thread
// hands freed pages back to the system once they have been unused for the decay time, also
// while the node is idle. Without it, memory a burst freed stays resident until the next
// allocations (the start-up scan of the audit segment alone reads 4 MiB at a time).
// Ignored where rcand runs on the C library's malloc.
extern "C" {
const char* malloc_conf = "background_thread:true";
}

namespace fs = std::filesystem;
using namespace rcan;
using rcan::node::log;
using rcan::node::LogLevel;

int sim_layer_main(int argc, char** argv);  // sim_layer.cpp: `rcand --sim-layer …`

namespace {

constexpr const char* kUsage =
    "usage: rcand [--config FILE] [--port N] [--bind ADDR] [--data-dir DIR] [--log-level debug|info|warn|error]\n"
    "       rcand --sim-layer [--port N] [--layer reactive|fast|planner] [--confidence C] [--delay-ms D]\n"
    "\n"
    "Without --config, rcand runs the embedded simulated robot. On its first run it creates, in\n"
    "the data directory (default $RCAND_DATA_DIR, else ~/.local/share/rcand): robot keys, the\n"
    "audit chain secret, a local token issuer and an OWNER token (owner.token, mode 0600).\n"
    "SIGTERM or Ctrl-C stops it gracefully (drains requests, flushes the audit log).\n";

struct Args {
  std::optional<std::string> config;
  std::optional<int> port;
  std::optional<std::string> data_dir;
  std::optional<std::string> log_level;
  std::optional<std::string> bind;  // overrides server.bind (e.g. 0.0.0.0 to serve the LAN)
};

int fail(const std::string& what) {
  log(LogLevel::kError, "startup_failed", json::Object{{"error", what}});
  std::fprintf(stderr, "rcand: %s\n", what.c_str());
  return 1;
}

std::optional<Args> parse_args(int argc, char** argv, int& exit_code) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    std::string s = argv[i];
    auto value = [&](const char* name) -> std::optional<std::string> {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "rcand: %s needs a value\n", name);
        return std::nullopt;
      }
      return std::string(argv[++i]);
    };
    if (s == "--help" || s == "-h") {
      std::fputs(kUsage, stdout);
      exit_code = 0;
      return std::nullopt;
    } else if (s == "--version") {
      std::puts("rcand 0.1.0 (RCAN protocol 1.0.0)");
      exit_code = 0;
      return std::nullopt;
    } else if (s == "--config") {
      if (!(a.config = value("--config"))) return std::nullopt;
    } else if (s == "--data-dir") {
      if (!(a.data_dir = value("--data-dir"))) return std::nullopt;
    } else if (s == "--bind") {
      if (!(a.bind = value("--bind"))) return std::nullopt;
    } else if (s == "--log-level") {
      if (!(a.log_level = value("--log-level"))) return std::nullopt;
    } else if (s == "--port") {
      auto v = value("--port");
      if (!v) return std::nullopt;
      char* end = nullptr;
      long p = std::strtol(v->c_str(), &end, 10);
      if (!end || *end || p < 0 || p > 65535) {
        std::fprintf(stderr, "rcand: --port must be 0..65535\n");
        return std::nullopt;
      }
      a.port = static_cast<int>(p);
    } else {
      std::fprintf(stderr, "rcand: unknown argument '%s'\n%s", s.c_str(), kUsage);
      return std::nullopt;
    }
  }
  return a;
}

Status make_private_dir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error(ErrorCode::kInternal, "cannot create " + dir + ": " + ec.message());
  ::chmod(dir.c_str(), 0700);
  return Status::Ok();
}

Result<std::string> read_text(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return Error(ErrorCode::kNotFound, "cannot read " + path);
  std::string s;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0 && s.size() < (1u << 20)) s.append(buf, n);
  std::fclose(f);
  return s;
}

// The embedded default's identity: a device id, robot keys, the chain secret, a local token
// issuer and an OWNER token. Created once; later runs reuse them.
struct LocalIdentity {
  std::string device_id;
  std::string issuer = "rcand-local";
  std::string issuer_seed_file;
  std::string owner_token_file;
  bool created = false;
};

Result<LocalIdentity> ensure_local_identity(const std::string& data_dir) {
  LocalIdentity id;
  if (Status s = make_private_dir(data_dir); !s.ok()) return s.error();
  std::string device_file = data_dir + "/device_id";
  if (auto t = read_text(device_file); t.ok()) {
    id.device_id = *t;
    while (!id.device_id.empty() && (id.device_id.back() == '\n' || id.device_id.back() == '\r')) id.device_id.pop_back();
  } else {
    uint8_t b[4];
    if (!random_bytes(b, sizeof b)) return Error(ErrorCode::kInternal, "no randomness");
    id.device_id = to_hex(b, sizeof b);
    std::string text = id.device_id + "\n";
    if (Status s = keys::write_new_file(device_file, {reinterpret_cast<const uint8_t*>(text.data()), text.size()}, 0644); !s.ok())
      return s.error();
    id.created = true;
  }
  id.issuer_seed_file = data_dir + "/issuer/ed25519.seed";
  id.owner_token_file = data_dir + "/owner.token";
  return id;
}

Status ensure_issuer_and_token(const LocalIdentity& id, const std::string& data_dir, const std::string& ruri,
                               jwt::TrustStore& trust, bool& token_created) {
  if (Status s = make_private_dir(data_dir + "/issuer"); !s.ok()) return s;
  if (!fs::exists(id.issuer_seed_file)) {
    Bytes seed = ed25519::random_seed();
    if (Status s = keys::write_new_file(id.issuer_seed_file, seed, 0600); !s.ok()) return s;
    secure_wipe(seed.data(), seed.size());
  }
  auto signing = jwt::SigningKey::from_file(id.issuer_seed_file);
  if (!signing.ok()) return signing.error();
  auto verify = signing->verification_key();
  if (!verify.ok()) return verify.error();
  trust.add(id.issuer, *verify);
  token_created = false;
  if (!fs::exists(id.owner_token_file)) {
    int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                      std::chrono::system_clock::now().time_since_epoch())
                      .count();
    json::Object claims{{"iss", id.issuer},
                        {"sub", "local-owner"},
                        {"aud", ruri},
                        {"role", "owner"},
                        {"scope", json::Array{"status", "chat", "control", "config", "training"}},
                        {"iat", now},
                        {"exp", static_cast<int64_t>(now + 365 * 24 * 3600)}};
    auto token = jwt::issue(claims, *signing);
    if (!token.ok()) return token.error();
    std::string text = *token + "\n";
    if (Status s = keys::write_new_file(id.owner_token_file, {reinterpret_cast<const uint8_t*>(text.data()), text.size()}, 0600);
        !s.ok())
      return s;
    token_created = true;
  }
  return Status::Ok();
}

sigset_t block_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  signal(SIGPIPE, SIG_IGN);
  return set;
}

node::SafetyConfig safety_config(const config::NodeConfig& cfg, const node::SimRobotConfig& sim) {
  node::SafetyConfig sc;
  sc.limits.max_linear_mps = cfg.safety.max_linear_speed_mps;
  sc.limits.max_angular_radps = cfg.safety.max_angular_speed_radps;
  if (cfg.safety.max_speed_override) {
    sc.limits.max_linear_mps *= *cfg.safety.max_speed_override;
    sc.limits.max_angular_radps *= *cfg.safety.max_speed_override;
  }
  sc.limits.max_joint_speed_radps = sim.max_joint_speed_radps;
  for (size_t i = 0; i < cfg.safety.joint_limits.size() && i < node::kArmJoints; ++i) {
    sc.limits.joint_min_rad[i] = cfg.safety.joint_limits[i].min_rad;
    sc.limits.joint_max_rad[i] = cfg.safety.joint_limits[i].max_rad;
  }
  sc.limits.workspace.min_x = cfg.safety.workspace.x_min;
  sc.limits.workspace.max_x = cfg.safety.workspace.x_max;
  sc.limits.workspace.min_y = cfg.safety.workspace.y_min;
  sc.limits.workspace.max_y = cfg.safety.workspace.y_max;
  sc.policy = cfg.safety.speed_policy == config::LimitPolicy::kReject ? node::LimitPolicy::kReject
                                                                       : node::LimitPolicy::kClamp;
  sc.estop_on_startup = cfg.safety.estop_on_startup;
  sc.default_heartbeat_ms = cfg.safety.heartbeat_timeout_ms;
  sc.tick_period_ms = cfg.driver.sim.tick_hz ? 1000 / cfg.driver.sim.tick_hz : 20;
  return sc;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::strcmp(argv[1], "--sim-layer") == 0) return sim_layer_main(argc, argv);
  int exit_code = 2;
  auto args = parse_args(argc, argv, exit_code);
  if (!args) return exit_code;
  if (args->log_level) {
    auto lvl = node::parse_log_level(*args->log_level);
    if (!lvl) return fail("--log-level must be debug, info, warn or error");
    node::set_log_level(*lvl);
  }
  sigset_t signals = block_signals();
  auto started = std::chrono::steady_clock::now();

  // 1. Configuration.
  bool embedded = !args->config;
  std::string data_dir;
  if (args->data_dir) {
    data_dir = fs::absolute(*args->data_dir).string();
  } else {
    auto d = config::default_data_dir();
    if (!d.ok()) return fail(d.error().message);
    data_dir = *d;
  }
  std::optional<LocalIdentity> local;
  Result<config::NodeConfig> loaded = Error(ErrorCode::kInternal, "no configuration");
  if (embedded) {
    auto id = ensure_local_identity(data_dir);
    if (!id.ok()) return fail(id.error().message);
    local = *id;
    loaded = config::default_config(data_dir, local->device_id);
  } else {
    loaded = config::load_config(*args->config);
  }
  if (!loaded.ok()) {
    const Error& e = loaded.error();
    return fail("configuration: " + (e.field.empty() ? "" : e.field + ": ") + e.message);
  }
  config::NodeConfig cfg = std::move(loaded).value();
  if (Status s = config::apply_overrides(cfg, args->port, args->data_dir ? std::optional<std::string>(data_dir) : std::nullopt);
      !s.ok())
    return fail(s.error().message);
  if (args->bind) cfg.server.bind_address = *args->bind;
  if (!args->log_level) {
    if (auto lvl = node::parse_log_level(cfg.log_level)) node::set_log_level(*lvl);
  }
  for (const auto& w : cfg.warnings) log(LogLevel::kWarn, "config_warning", json::Object{{"warning", w}});
  if (Status s = make_private_dir(cfg.data_dir); !s.ok()) return fail(s.error().message);

  // 2. Identity: robot keys and the audit chain secret.
  if (embedded && !fs::exists(cfg.security.key_dir + "/" + std::string(keys::kMldsaSeedFile))) {
    auto k = keys::generate();
    if (!k.ok()) return fail(k.error().message);
    if (Status s = keys::write_dir(cfg.security.key_dir, *k); !s.ok()) return fail(s.error().message);
  }
  auto robot_keys = keys::load_dir(cfg.security.key_dir);
  if (!robot_keys.ok())
    return fail("robot keys in " + cfg.security.key_dir + ": " + robot_keys.error().message +
                " (create them with: rcan keys generate --dir " + cfg.security.key_dir + ")");
  if (embedded && !fs::exists(cfg.security.audit.chain_secret_file)) {
    if (Status s = audit::create_secret_file(cfg.security.audit.chain_secret_file); !s.ok())
      return fail(s.error().message);
  }
  auto secret = audit::load_chain_secret(cfg.security.audit.chain_secret_file);
  if (!secret.ok()) {
    std::string msg = secret.error().message;
    if (msg.find("new-secret") == std::string::npos)
      msg += " (create one with: rcan audit new-secret --out " + cfg.security.audit.chain_secret_file + ")";
    return fail(msg);
  }

  // 3. Token issuers.
  auto trust = jwt::TrustStore::from_config(cfg.security.jwt.issuers);
  if (!trust.ok()) return fail("security.jwt.issuers: " + trust.error().message);
  bool token_created = false;
  if (local) {
    if (Status s = ensure_issuer_and_token(*local, cfg.data_dir, cfg.ruri, *trust, token_created); !s.ok())
      return fail(s.error().message);
  }
  if (trust->empty())
    return fail("no token issuer is configured (security.jwt.issuers); every request would be refused");

  // 4. The audit log.
  audit::AuditOptions ao;
  ao.secret = *secret;
  secure_wipe(secret->data(), secret->size());
  ao.sync_policy = cfg.security.audit.sync_policy;
  ao.sync_interval_ms = static_cast<int>(cfg.security.audit.sync_interval_ms);
  ao.max_segment_bytes = cfg.security.audit.max_segment_bytes;
  ao.retention_max_bytes = cfg.security.audit.retention_max_bytes;
  ao.retention_max_age_ms = int64_t{cfg.security.audit.retention_max_age_days} * 86'400'000;
  ao.robot_ruri = cfg.ruri;
  auto audit_log = audit::AuditLog::open(cfg.security.audit.dir, std::move(ao));
  if (!audit_log.ok()) return fail("audit log in " + cfg.security.audit.dir + ": " + audit_log.error().message);

  // 5. The safety core and the simulated robot.
  node::SimRobotConfig sim;
  node::SafetyCore core(std::make_unique<node::SimRobot>(sim), safety_config(cfg, sim));
  if (Status s = core.open(cfg.data_dir + "/safety"); !s.ok()) return fail("safety state: " + s.error().message);
  node::SafetyActuation actuation(core, cfg.robot.name.empty() ? "rcan robot" : cfg.robot.name);

  // 6. The node.
  node::NodeSettings ns;
  ns.ruri = cfg.ruri;
  ns.rrn = cfg.rrn;
  if (ns.rrn.empty()) {
    // A stable local registration number from the robot's key id (digits only).
    std::string kid = robot_keys->pub.kid();
    uint64_t v = std::strtoull(kid.c_str(), nullptr, 16) % 1'000'000'000'000ULL;
    char b[32];
    std::snprintf(b, sizeof b, "RRN-%012llu", static_cast<unsigned long long>(v));
    ns.rrn = b;
  }
  ns.name = cfg.robot.name.empty() ? "rcan-robot" : cfg.robot.name;
  ns.manufacturer = cfg.robot.manufacturer.empty() ? cfg.ruri_parts.manufacturer : cfg.robot.manufacturer;
  ns.model = cfg.robot.model.empty() ? cfg.ruri_parts.model : cfg.robot.model;
  if (!cfg.capabilities.empty()) ns.capabilities = cfg.capabilities;
  ns.port = cfg.server.port;
  ns.role_policy = cfg.rbac.policy;
  ns.rate_per_minute = {0, cfg.rbac.rate_limits.guest, cfg.rbac.rate_limits.user, cfg.rbac.rate_limits.leasee,
                        cfg.rbac.rate_limits.owner, cfg.rbac.rate_limits.creator};
  ns.replay.window_ms = int64_t{cfg.security.replay_window_s} * 1000;
  ns.replay.capacity = cfg.security.msg_id_cache_size;
  ns.injection_patterns.clear();
  for (const auto& p : cfg.security.injection_patterns) ns.injection_patterns.push_back(p.text);
  ns.heartbeat_timeout_ms = cfg.safety.heartbeat_timeout_ms;
  ns.default_ttl_ms = cfg.safety.command_ttl_default_ms;
  ns.codec.max_body_bytes = cfg.server.limits.max_body_bytes;
  ns.telemetry_hz = static_cast<int>(cfg.driver.sim.telemetry_hz);
  ns.guest_limits = cfg.rbac.guest_limits.to_guest_limits();
  ns.handoff_window_ms = int64_t{cfg.control.handoff_window_s} * 1000;
  ns.state_dir = cfg.data_dir;
  ns.consent_webhook = cfg.control.consent_webhook;

  node::AuthOptions auth;
  auth.trust = std::move(trust).value();
  auth.verify.audience = cfg.ruri;
  auth.verify.fleet_ids = {cfg.ruri_parts.device_id, cfg.ruri, ns.rrn};
  if (!cfg.fleet.fleet_id.empty()) {
    auth.verify.fleet_ids.push_back(cfg.fleet.member_id);
    auth.verify.fleet_audiences.push_back("rcan://fleet/" + cfg.fleet.fleet_id);  // v1.5 fleet JWT
  }
  auth.verify.leeway_s = cfg.security.jwt.leeway_s;
  // Public keys named in the config: peer robots' (a robot signature changes the §8.5
  // verdict) and operators'/integrators' (human or software signers).
  auto load_keys = [&](const std::vector<config::TrustedRobotKey>& list, const char* what,
                       msgsig::TrustedKeys& into) -> std::optional<std::string> {
    for (const auto& rk : list) {
      if (!rk.mldsa65_pub_file.empty()) {
        auto b = keys::read_public_file(rk.mldsa65_pub_file);
        if (!b.ok()) return std::string("security.") + what + " " + rk.name + ": " + b.error().message;
        into.mldsa65.push_back(*b);
      }
      if (!rk.ed25519_pub_file.empty()) {
        auto b = keys::read_public_file(rk.ed25519_pub_file);
        if (!b.ok()) return std::string("security.") + what + " " + rk.name + ": " + b.error().message;
        into.ed25519.push_back(*b);
      }
    }
    return std::nullopt;
  };
  if (auto e = load_keys(cfg.security.trusted_robot_keys, "trusted_robot_keys", auth.robot_keys)) return fail(*e);
  if (auto e = load_keys(cfg.security.trusted_signer_keys, "trusted_signer_keys", auth.signer_keys)) return fail(*e);

  node::NodeServices services(ns, node::Clock::system(), std::move(auth), actuation, **audit_log);
  if (!cfg.fleet.fleet_id.empty()) services.fleet = std::make_shared<node::FleetMembership>(node::FleetMembership{cfg.fleet, {}});
  {
    node::ControlOptions co;  // docs/SESSIONS.md
    co.handoff_window_ms = ns.handoff_window_ms;
    co.queue_max = cfg.control.queue_max;
    co.queue_wait_ms = int64_t{cfg.control.queue_wait_s} * 1000;
    co.fleet_policy = node::fleet_policy_from_name(cfg.control.fleet_policy).value_or(node::FleetPolicy::kRole);
    co.guest_session_s = ns.guest_limits.session_seconds;
    co.max_session_ms = int64_t{cfg.control.max_session_s} * 1000;
    services.sessions.set_options(co);
    services.ownership.set_window_ms(int64_t{cfg.control.transfer_window_s} * 1000);
    services.consent.set_pending_ttl_ms(int64_t{cfg.control.consent_ttl_s} * 1000);
    node::PartitionOptions po;
    po.issuer_url = cfg.offline.issuer_url;
    po.poll_interval_ms = cfg.offline.issuer_poll_ms;
    po.timeout_ms = static_cast<int>(cfg.offline.issuer_timeout_ms);
    po.key_ttl_ms = int64_t{cfg.offline.max_key_ttl_s} * 1000;
    services.partition.configure(po);
  }
  node::AiOptions ai_opts = node::ai_options(cfg);  // §16 gates, layers, HiTL, watermark
  ai_opts.watermark_key = robot_keys->mldsa65_sk.clone();
  services.ai = std::make_shared<node::AiServices>(services, std::move(ai_opts));
  // An ownership transfer clears personal data, the thought log included (docs/SESSIONS.md).
  services.ownership.on_clear([ai = services.ai] { ai->clear_thoughts(); });
  node::Node rcan_node(services);
  if (Status s = services.ai->start(rcan_node.pipeline()); !s.ok()) return fail("HiTL pending file: " + s.error().message);
  core.set_event_callback([&rcan_node](const node::SafetyEvent& ev) {
    rcan_node.on_safety_event(ev.type, ev.session_id, ev.elapsed_ms, ev.detail);
  });
  core.start();
  rcan_node.start();

  // 7. The transport.
  transport::ServerOptions so;
  so.bind_address = cfg.server.bind_address;
  so.port = cfg.server.port;
  so.io_threads = static_cast<int>(cfg.server.io_threads);
  so.max_body_bytes = cfg.server.limits.max_body_bytes;
  so.max_header_bytes = cfg.server.limits.max_header_bytes;
  so.read_timeout_ms = static_cast<int>(cfg.server.limits.read_timeout_ms);
  so.idle_timeout_ms = static_cast<int>(cfg.server.limits.idle_timeout_ms);
  so.max_connections = cfg.server.limits.max_connections;
  so.ws_max_message_bytes = cfg.server.limits.max_body_bytes;
  so.tls = cfg.server.tls.enabled;
  so.cert_file = cfg.server.tls.cert_file;
  so.key_file = cfg.server.tls.key_file;
  // gRPC and UDP first: their claim hook is in place before HTTP serves (docs/TRANSPORT.md).
  auto extra = rcand::start_extra_transports(cfg, rcan_node);
  if (!extra.ok()) {
    services.ai->shutdown();
    rcan_node.shutdown();
    core.stop();
    return fail(extra.error().message);
  }
  transport::HttpServer server(so, rcan_node, rcan_node);
  auto port = server.start();
  if (!port.ok()) {
    (*extra)->stop(0);
    services.ai->shutdown();
    rcan_node.shutdown();
    core.stop();
    return fail("cannot listen on " + so.bind_address + ":" + std::to_string(so.port) + ": " + port.error().message);
  }
  services.settings.port = *port;  // the bound port (differs from the configured one for --port 0)
  std::unique_ptr<node::MqttNode> mqtt;  // the MQTT transport (docs/FLEET.md)
  if (cfg.mqtt.enabled) {
    auto mo = node::mqtt_node_options(cfg);
    if (mo.ok()) mqtt = std::make_unique<node::MqttNode>(rcan_node, services, std::move(mo).value());
    Status s = mo.ok() ? mqtt->start() : Status(mo.error());
    if (!s.ok()) {
      server.stop(0);
      rcan_node.shutdown();
      core.stop();
      return fail("mqtt: " + s.error().message);
    }
  }
  std::unique_ptr<node::MdnsAdvertiser> mdns;  // _rcan._tcp via Avahi (docs/NODE.md §Discovery)
  if (cfg.server.enable_mdns) mdns = node::start_mdns(services, so.tls);
  double startup_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started).count();
  std::string scheme = so.tls ? "https" : "http";
  std::string url = scheme + "://" + (so.bind_address == "0.0.0.0" ? std::string("127.0.0.1") : so.bind_address) +
                    ":" + std::to_string(*port);
  log(LogLevel::kInfo, "listening",
      json::Object{{"url", url},
                   {"ruri", cfg.ruri},
                   {"rrn", ns.rrn},
                   {"data_dir", cfg.data_dir},
                   {"estop_active", core.estop_active()},
                   {"startup_ms", startup_ms}});
  if (local) {
    std::fprintf(stderr,
                 "\nrcand is serving the simulated robot %s at %s\n"
                 "%s token: %s (mode 0600)\n"
                 "Use it from another terminal:\n"
                 "  export RCAN_URL=%s RCAN_TOKEN_FILE=%s\n"
                 "  rcan status        # then: rcan claim, rcan command move --linear 0.3, rcan estop\n"
                 "Dashboard: %s/ (sign in with the token in that file; docs/DASHBOARD.md)\n\n",
                 cfg.ruri.c_str(), url.c_str(), token_created ? "New OWNER" : "OWNER",
                 local->owner_token_file.c_str(), url.c_str(), local->owner_token_file.c_str(), url.c_str());
  }

  // 8. Run until SIGTERM / SIGINT.
  int sig = 0;
  sigwait(&signals, &sig);
  log(LogLevel::kInfo, "shutting_down", json::Object{{"signal", sig == SIGTERM ? "SIGTERM" : "SIGINT"}});
  (*extra)->stop(2000);
  mdns.reset();
  server.stop(2000);
  if (mqtt) mqtt->stop();
  services.ai->shutdown();
  rcan_node.shutdown();
  core.stop();
  log(LogLevel::kInfo, "stopped", json::Object{{"audit_last_seq", static_cast<int64_t>((*audit_log)->stats().last_seq)}});
  return 0;
}
