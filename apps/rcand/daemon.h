// Daemon — rcand's parts, started in one order and stopped in the reverse one.
//
//   Daemon d;
//   if (Status s = d.start(options); !s.ok()) return fail(s);   // already stopped again
//   wait_for_signal();
//   d.stop(2000);
//
// start() runs each step in the order the members are declared below — configuration,
// identity, audit log, safety core, node services, node, §16 services, UDP, HTTP, gRPC, MQTT,
// mDNS — and records how to stop what each step started. stop() runs those records in reverse,
// whether it is called after a signal or by start() when a step failed, so every start-up
// failure tears down exactly what was started, newest first. The destructor calls stop(0).
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "config/config.h"
#include "identity.h"
#include "rcan/audit/audit_log.h"
#include "rcan/crypto/keys.h"
#include "rcan/result.h"

namespace rcan::node {
class SafetyCore;
class SafetyActuation;
class NodeServices;
class Node;
class MqttNode;
class MdnsAdvertiser;
class RegistryTrust;  // node/admission/registry_trust.h
class RobotDirectory;
class UdpService;
class GrpcTransport;
}  // namespace rcan::node
namespace rcan::transport {
class HttpServer;
}

namespace rcan::rcand {

class RegistryLink;  // registry_join.h

struct DaemonOptions {
  std::optional<std::string> config;    // --config: a configured robot; none: the embedded default
  std::optional<int> port;              // --port
  std::optional<std::string> data_dir;  // --data-dir
  std::optional<std::string> bind;      // --bind
  bool log_level_given = false;         // --log-level was given (the config's level is ignored)
};

// What main prints once the daemon serves.
struct ServingInfo {
  std::string url;
  std::string ruri;
  bool local = false;  // the embedded default (LocalIdentity below is meaningful)
  LocalIdentity identity;
  bool token_created = false;
};

class Daemon {
 public:
  Daemon();
  ~Daemon();  // stop(0)
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Starts every part. On an error the parts already started are stopped (in reverse order)
  // before it returns; the error's message says which step failed and why.
  Status start(const DaemonOptions& options);
  // Stops what start() started, newest first, draining transports for up to `drain_ms`.
  // Idempotent.
  void stop(int drain_ms);

  const ServingInfo& info() const { return info_; }
  uint64_t audit_last_seq() const;
  // The safety core's loop turns (the systemd watchdog's liveness signal), and an ESTOP by the
  // node itself (a hung loop).
  uint64_t safety_loop_count() const;
  void safety_estop(const std::string& reason);

 private:
  // The steps of start(), in order; each records its undo with on_stop().
  Status load_configuration(const DaemonOptions& options);
  Status open_identity();
  Status open_audit_log();
  Status join_registry();
  Status start_safety_core();
  Status start_node();
  Status start_transports();
  void add_http_metrics();
  // Records how to undo the step that just succeeded.
  void on_stop(std::function<void(int drain_ms)> fn) { stops_.push_back(std::move(fn)); }

  // The parts, in start order (destroyed in reverse).
  config::NodeConfig cfg_;
  bool embedded_ = false;
  std::optional<LocalIdentity> local_;
  std::optional<keys::RobotKeys> robot_keys_;
  std::string chain_secret_;  // from open_identity() until the audit log holds it
  std::optional<jwt::TrustStore> trust_;
  std::unique_ptr<audit::AuditLog> audit_;
  std::unique_ptr<node::SafetyCore> core_;
  std::unique_ptr<node::SafetyActuation> actuation_;
  std::unique_ptr<node::NodeServices> services_;
  std::unique_ptr<node::RobotDirectory> robots_;  // dashboard.robots (outlives node_)
  std::unique_ptr<node::Node> node_;
  std::unique_ptr<node::RegistryTrust> registry_trust_;  // the registry's keys and revocations
  std::unique_ptr<node::UdpService> udp_;
  std::unique_ptr<transport::HttpServer> http_;
  std::unique_ptr<node::GrpcTransport> grpc_;
  std::unique_ptr<node::MqttNode> mqtt_;
  std::unique_ptr<node::MdnsAdvertiser> mdns_;
  std::unique_ptr<RegistryLink> registry_;

  std::vector<std::function<void(int drain_ms)>> stops_;  // run newest first
  ServingInfo info_;
};

}  // namespace rcan::rcand
