// rcand's start and stop paths (daemon.h).
#include "daemon.h"

#include <chrono>
#include <filesystem>

#include "base/clock.h"
#include "driver_factory.h"
#include "node/admission/registry_trust.h"
#include "node/ai/ai_services.h"
#include "node/api/node.h"
#include "node/bindings/mqtt_node.h"
#include "node/discovery/mdns.h"
#include "node/discovery/robot_directory.h"
#include "node/fleet/fleet.h"
#include "node/safety/actuation_safety.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "registry_join.h"
#include "runtime/log.h"
#include "settings.h"
#include "transport/http_server.h"
#include "transports.h"

namespace fs = std::filesystem;

namespace rcan::rcand {
namespace {

// An error whose message is `context` followed by the cause's message.
Error failed(const std::string& context, const Error& cause) {
  return Error(ErrorCode::kInternal, context + cause.message);
}

// The link to the registry whose tokens the node trusts (registry.trust_tokens), primed before
// the node serves: its keys (fetched, else cached), its revocation cursor, its records in the
// node's audit log, its metrics and its part of the detailed status.
std::unique_ptr<node::RegistryTrust> start_registry_trust(const config::NodeConfig& cfg,
                                                          node::NodeServices& svc) {
  node::RegistryTrustOptions o;
  o.registry_url = cfg.registry_url;
  o.issuer = cfg.registry.issuer.empty() ? cfg.registry_url : cfg.registry.issuer;
  o.data_dir = cfg.data_dir;
  o.ca_file = cfg.registry.ca_file;
  o.rrn = svc.settings.rrn;
  o.jwks_refresh_s = cfg.registry.jwks_refresh_s;
  o.revocations_refresh_s = cfg.registry.revocations_refresh_s;
  o.max_key_age_s = cfg.registry.max_key_age_s;
  auto record = [&svc](node::TrustRecord r) {
    auto rec = svc.trail.record(r.event, r.outcome);
    rec.by_system();
    if (!r.reason.empty()) rec.reason(r.reason);
    for (const auto& [key, value] : r.detail) rec.detail(key, value);
    rec.write();
  };
  auto trust = std::make_unique<node::RegistryTrust>(std::move(o), svc.clock, svc.auth,
                                                     svc.revocations, svc.metrics, record);
  trust->prime(3000);
  svc.registry_status = [t = trust.get()] { return t->status_json(); };
  return trust;
}

}  // namespace

Daemon::Daemon() = default;

Daemon::~Daemon() { stop(0); }

void Daemon::stop(int drain_ms) {
  while (!stops_.empty()) {
    auto fn = std::move(stops_.back());
    stops_.pop_back();
    fn(drain_ms);
  }
}

uint64_t Daemon::audit_last_seq() const { return audit_ ? audit_->stats().last_seq : 0; }

uint64_t Daemon::safety_loop_count() const { return core_ ? core_->loop_count() : 0; }

void Daemon::safety_estop(const std::string& reason) {
  if (core_) (void)core_->estop("node", reason);
}

Status Daemon::start(const DaemonOptions& options) {
  const auto started = steady_now();
  Status s = load_configuration(options);
  for (auto step : {&Daemon::open_identity, &Daemon::open_audit_log, &Daemon::join_registry,
                    &Daemon::start_safety_core, &Daemon::start_node, &Daemon::start_transports}) {
    if (!s.ok()) break;
    s = (this->*step)();
  }
  if (!s.ok()) {
    stop(0);
    return s;
  }
  const double startup_ms =
      std::chrono::duration<double, std::milli>(steady_now() - started).count();
  log(LogLevel::kInfo, "listening",
      json::Object{{"url", info_.url},
                   {"ruri", cfg_.ruri},
                   {"rrn", services_->settings.rrn},
                   {"data_dir", cfg_.data_dir},
                   {"estop_active", core_->estop_active()},
                   {"startup_ms", startup_ms}});
  return Status::Ok();
}

// 1. The configuration: the embedded default (with its local identity) or the --config file,
// then the command line's overrides.
Status Daemon::load_configuration(const DaemonOptions& options) {
  embedded_ = !options.config;
  std::string data_dir;
  if (options.data_dir) {
    data_dir = fs::absolute(*options.data_dir).string();
  } else {
    auto d = config::default_data_dir();
    if (!d.ok()) return d.error();
    data_dir = *d;
  }
  Result<config::NodeConfig> loaded = Error(ErrorCode::kInternal, "no configuration");
  if (embedded_) {
    auto id = ensure_local_identity(data_dir);
    if (!id.ok()) return id.error();
    local_ = *id;
    loaded = config::default_config(data_dir, local_->device_id);
  } else {
    loaded = config::load_config(*options.config);
  }
  if (!loaded.ok()) {
    const Error& e = loaded.error();
    return Error(ErrorCode::kInternal,
                 "configuration: " + (e.field.empty() ? "" : e.field + ": ") + e.message);
  }
  cfg_ = std::move(loaded).value();
  std::optional<std::string> dir_override;
  if (options.data_dir) dir_override = data_dir;
  if (Status s = config::apply_overrides(cfg_, options.port, dir_override); !s.ok()) return s;
  if (options.bind) cfg_.server.bind_address = *options.bind;
  if (!options.log_level_given) {
    if (auto lvl = parse_log_level(cfg_.log_level)) set_log_level(*lvl);
  }
  for (const auto& w : cfg_.warnings)
    log(LogLevel::kWarn, "config_warning", json::Object{{"warning", w}});
  return make_private_dir(cfg_.data_dir);
}

// 2. Identity: robot keys, the audit chain secret (kept until the log has it) and the token
// issuers (the embedded default's own issuer and OWNER token included).
Status Daemon::open_identity() {
  auto k = robot_keys(cfg_, embedded_);
  if (!k.ok()) return k.error();
  robot_keys_ = std::move(k).value();
  auto secret = chain_secret(cfg_, embedded_);
  if (!secret.ok()) return secret.error();
  chain_secret_ = std::move(secret).value();
  auto trust = jwt::TrustStore::from_config(cfg_.security.jwt.issuers);
  if (!trust.ok()) return failed("security.jwt.issuers: ", trust.error());
  if (local_) {
    if (Status s = ensure_issuer_and_token(*local_, cfg_.ruri, *trust, info_.token_created);
        !s.ok())
      return s;
  }
  if (trust->empty() && !cfg_.registry.trust_tokens)  // the registry's keys come in start_node
    return Error(
        ErrorCode::kInternal,
        "no token issuer is configured (security.jwt.issuers); every request would be refused");
  trust_ = std::move(trust).value();
  return Status::Ok();
}

// 3. The audit log (its secret is wiped from memory once the log holds it).
Status Daemon::open_audit_log() {
  auto opened = audit::AuditLog::open(cfg_.security.audit.dir, audit_options(cfg_, chain_secret_));
  secure_wipe(chain_secret_.data(), chain_secret_.size());
  chain_secret_.clear();
  if (!opened.ok()) return failed("audit log in " + cfg_.security.audit.dir + ": ", opened.error());
  audit_ = std::move(opened).value();
  return Status::Ok();
}

// 3b. The registry (config `registry`): a robot that has no RRN from it yet registers now, so
// that it serves under the registry's RRN from the start; an unreachable registry does not
// stop it (it serves under its local RRN and the link keeps trying, registry_join.h).
Status Daemon::join_registry() {
  if (cfg_.registry.key_file.empty()) return Status::Ok();
  if (stored_registry_rrn(cfg_.data_dir).empty() && cfg_.registry.register_at_start) {
    auto r = register_with_registry(cfg_, *robot_keys_, 3000);
    audit::AuditEntry e;
    e.principal = "node";
    e.message_id = new_uuid_v4();
    e.ruri = cfg_.ruri;
    e.event = r.ok() ? "REGISTRY_REGISTERED" : "REGISTRY_UNREACHABLE";
    e.outcome = r.ok() ? "ok" : "error";
    e.sender_type = "system";
    e.detail.set("registry", cfg_.registry_url);
    e.detail.set("result", r.ok() ? *r : r.error().message);
    if (auto a = audit_->append(std::move(e)); !a.ok()) return failed("audit log: ", a.error());
    if (!r.ok())
      log(LogLevel::kWarn, "registry_registration_failed",
          json::Object{{"error", r.error().message}, {"next", "retrying in the background"}});
  }
  return Status::Ok();
}

// 4. The safety core over the configured driver, with its persisted ESTOP latch.
Status Daemon::start_safety_core() {
  node::SimRobotConfig sim;
  auto driver = make_driver(cfg_, sim);
  if (!driver.ok()) return failed("driver: ", driver.error());
  core_ = std::make_unique<node::SafetyCore>(std::move(driver).value(), safety_config(cfg_, sim));
  if (Status s = core_->open(cfg_.data_dir + "/safety"); !s.ok())
    return failed("safety state: ", s.error());
  actuation_ = std::make_unique<node::SafetyActuation>(
      *core_, cfg_.robot.name.empty() ? "rcan robot" : cfg_.robot.name);
  return Status::Ok();
}

// 5. The node: its services, the §16 services, the Node itself; then the safety core's ticker,
// the node (SYSTEM_START) and the §16 services (held HiTL commands come back) start, in that
// order, and stop in the reverse one (§16 first, SYSTEM_STOP, the ticker last).
Status Daemon::start_node() {
  node::NodeSettings ns = node_settings(cfg_, *robot_keys_);
  auto auth = auth_options(cfg_, std::move(*trust_), ns.rrn);
  trust_.reset();
  if (!auth.ok()) return auth.error();
  services_ = std::make_unique<node::NodeServices>(ns, Clock::system(), std::move(auth).value(),
                                                   *actuation_, *audit_);
  // Revoked tokens stay revoked across restarts; a list that cannot be read stops start-up
  // rather than accept what it revoked.
  if (Status s = services_->revocations.load(services_->clock.wall_ms() / 1000); !s.ok()) return s;
  if (!cfg_.fleet.fleet_id.empty())
    services_->fleet =
        std::make_shared<node::FleetMembership>(node::FleetMembership{cfg_.fleet, {}});
  // Tokens from the registry (node/admission/registry_trust.h): its keys before the node serves.
  std::function<int64_t()> keys_fetched;
  if (cfg_.registry.trust_tokens) {
    registry_trust_ = start_registry_trust(cfg_, *services_);
    keys_fetched = [t = registry_trust_.get()] { return t->keys_fetched_ms(); };
  }
  configure_control(*services_, cfg_, std::move(keys_fetched));
  node::AiOptions ai_opts = node::ai_options(cfg_);  // §16 gates, layers, HiTL, watermark
  ai_opts.watermark_key = robot_keys_->mldsa65_sk.clone();
  services_->ai = std::make_shared<node::AiServices>(*services_, std::move(ai_opts));
  // An ownership transfer clears personal data, the thought log included (docs/SESSIONS.md).
  services_->control.ownership().on_clear([ai = services_->ai] { ai->clear_thoughts(); });
  node_ = std::make_unique<node::Node>(*services_);
  // The other robots of the dashboard's Robots view (dashboard.robots), read every poll_ms.
  robots_ = std::make_unique<node::RobotDirectory>(cfg_.dashboard, services_->clock);
  node_->set_robot_directory(robots_.get());
  robots_->start();
  on_stop([this](int) { robots_->stop(); });
  core_->set_event_callback([node = node_.get()](const node::SafetyEvent& ev) {
    node->on_safety_event(ev.type, ev.session_id, ev.elapsed_ms, ev.detail);
  });
  core_->start();
  on_stop([this](int) { core_->stop(); });
  node_->start();
  on_stop([this](int) { node_->shutdown(); });
  on_stop([this](int) { services_->ai->shutdown(); });
  if (Status s = services_->ai->start(node_->pipeline()); !s.ok())
    return failed("HiTL pending file: ", s.error());
  if (registry_trust_) {
    registry_trust_->start();
    on_stop([this](int) { registry_trust_->stop(); });
  }
  return Status::Ok();
}

// 6. The transports: UDP first (its claim hook puts the heartbeat key into GRANTED answers, so it
// is in place before HTTP serves, docs/TRANSPORT.md), HTTP/WebSocket, gRPC, MQTT (docs/FLEET.md),
// then the mDNS advertisement. They stop in the reverse order: gRPC drains its calls before
// HTTP and UDP stop.
// The HTTP server's connection counters on /metrics: what the connection limits refused and
// how often the reserve (over max_connections, for a stop) was used (docs/TRANSPORT.md).
void Daemon::add_http_metrics() {
  using Stats = transport::ServerStats;
  struct Row {
    const char* name;
    const char* help;
    uint64_t Stats::*field;
    bool gauge;
  };
  static constexpr Row kRows[] = {
      {"rcan_http_connections_open", "HTTP and WebSocket connections open.",
       &Stats::connections_open, true},
      {"rcan_http_connections_refused_total",
       "Connections refused 503: max_connections and the reserve were full.",
       &Stats::rejected_connections, false},
      {"rcan_http_connections_refused_per_address_total",
       "Connections refused 503 for server.limits.max_connections_per_address.",
       &Stats::rejected_per_address, false},
      {"rcan_http_reserve_connections_total",
       "Connections accepted from the reserve over max_connections or "
       "max_connections_per_address (for a stop).",
       &Stats::reserve_connections, false},
      {"rcan_http_connections_evicted_total",
       "Never-authenticated idle connections closed to make room for a new connection.",
       &Stats::evicted_idle, false},
      {"rcan_http_reserve_refused_total",
       "Requests other than a stop on a reserve connection, answered 503.", &Stats::reserve_refused,
       false},
  };
  for (const Row& r : kRows) {
    auto fn = [this, field = r.field] { return static_cast<double>(http_->stats().*field); };
    if (r.gauge) {
      services_->metrics.add_gauge(r.name, r.help, fn);
    } else {
      services_->metrics.add_counter_fn(r.name, r.help, fn);
    }
  }
}

Status Daemon::start_transports() {
  auto udp = start_udp(cfg_, *node_);
  if (!udp.ok()) return udp.error();
  udp_ = std::move(udp).value();
  if (udp_) on_stop([this](int) { udp_->stop(); });

  transport::ServerOptions so = server_options(cfg_);
  http_ = std::make_unique<transport::HttpServer>(so, *node_, *node_);
  auto port = http_->start();
  if (!port.ok())
    return failed("cannot listen on " + so.bind_address + ":" + std::to_string(so.port) + ": ",
                  port.error());
  on_stop([this](int drain_ms) { http_->stop(drain_ms); });
  add_http_metrics();
  services_->settings.port =
      *port;  // the bound port (differs from the configured one for --port 0)

  auto grpc = start_grpc(cfg_, *node_);
  if (!grpc.ok()) return grpc.error();
  grpc_ = std::move(grpc).value();
  if (grpc_) on_stop([this](int drain_ms) { grpc_->stop(drain_ms); });

  if (cfg_.mqtt.enabled) {
    auto mo = node::mqtt_node_options(cfg_);
    if (!mo.ok()) return failed("mqtt: ", mo.error());
    // Its replies and status are signed with its identity key (docs/FLEET.md, "Signed replies").
    mo->reply_key = std::make_shared<const keys::SecretBytes>(robot_keys_->ed25519_seed.clone());
    mqtt_ = std::make_unique<node::MqttNode>(*node_, *services_, std::move(mo).value());
    on_stop([this](int) { mqtt_->stop(); });
    if (Status s = mqtt_->start(); !s.ok()) return failed("mqtt: ", s.error());
  }
  if (cfg_.server.enable_mdns) {  // _rcan._tcp via Avahi (docs/NODE.md §Discovery)
    mdns_ = node::start_mdns(*services_, so.tls);
    on_stop([this](int) { mdns_.reset(); });
  }

  if (!cfg_.registry.key_file.empty()) {  // registry_join.h
    registry_ = std::make_unique<RegistryLink>(cfg_, *robot_keys_, *audit_, cfg_.ruri);
    registry_->start();
    on_stop([this](int) { registry_->stop(); });
  }

  const std::string host =
      so.bind_address == "0.0.0.0" ? std::string("127.0.0.1") : so.bind_address;
  info_.url = std::string(so.tls ? "https" : "http") + "://" + host + ":" + std::to_string(*port);
  info_.ruri = cfg_.ruri;
  info_.local = local_.has_value();
  if (local_) info_.identity = *local_;
  return Status::Ok();
}

}  // namespace rcan::rcand
