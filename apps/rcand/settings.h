// The configuration turned into the settings of each part rcand starts: the audit log, the
// safety core, the node, its authenticator, control sessions and partition watch, and the
// HTTP server. Pure functions of the loaded config (docs/CONFIG.md says what each key means).
#pragma once

#include <functional>
#include <string>

#include "config/config.h"
#include "node/admission/authenticator.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"
#include "node/services/node_services.h"
#include "rcan/audit/audit_log.h"
#include "rcan/crypto/keys.h"
#include "transport/http_server.h"

namespace rcan::rcand {

audit::AuditOptions audit_options(const config::NodeConfig& cfg, const std::string& secret);

node::SafetyConfig safety_config(const config::NodeConfig& cfg, const node::SimRobotConfig& sim);

// The robot's identity, limits and policies. Without a configured RRN the robot gets a stable
// local one from its key id (RRN- and 12 digits).
node::NodeSettings node_settings(const config::NodeConfig& cfg, const keys::RobotKeys& robot);

// Token verification for this robot (audience, fleet ids, leeway) with `trust` as its issuers,
// and the trusted robot and signer keys the config names. Errors name the key entry.
Result<node::AuthOptions> auth_options(const config::NodeConfig& cfg, jwt::TrustStore trust,
                                       const std::string& rrn);

// Control sessions, ownership transfer, consent and the partition watch (docs/SESSIONS.md).
// `registry_keys_fetched_ms` (set when registry.trust_tokens is on,
// node/admission/registry_trust.h): the partition monitor probes the registry and calls its keys
// fresh from their last fetch, unless offline.issuer_url names something else to probe.
void configure_control(node::NodeServices& services, const config::NodeConfig& cfg,
                       std::function<int64_t()> registry_keys_fetched_ms = {});

transport::ServerOptions server_options(const config::NodeConfig& cfg);

}  // namespace rcan::rcand
