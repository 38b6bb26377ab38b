// NodeServices — everything the pipeline stages and routes share: settings, clock,
// authenticator, replay guard, rate limiter, injection screen, the safety core (through
// Actuation), the audit log and its trail, the event bus, metrics and control (ControlService).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "base/clock.h"
#include "base/metrics.h"
#include "base/thread_annotations.h"
#include "config/safety_types.h"
#include "node/admission/authenticator.h"
#include "node/admission/injection.h"
#include "node/admission/rate_limit.h"
#include "node/admission/replay.h"
#include "node/admission/revocation.h"
#include "node/control/control_service.h"
#include "node/safety/actuation.h"
#include "node/vocabulary/audit_record.h"
#include "node/vocabulary/audit_trail.h"
#include "node/vocabulary/event_bus.h"
#include "rcan/actions.h"
#include "rcan/audit/audit_log.h"
#include "rcan/message.h"
#include "rcan/roles.h"

namespace rcan::node {

struct FleetMembership;
class AiServices;  // §16 gates, HiTL queue, thought log, watermark (ai_services.h)

// The port the node serves on: rcand stores the bound port (for `--port 0`) after the listener
// is up, while I/O threads may already read it for /rcan/v1/status — an atomic, still copyable.
class BoundPort {
 public:
  BoundPort(uint16_t p = 0) : v_(p) {}  // NOLINT: converts like the uint16_t it replaces
  BoundPort(const BoundPort& o) : v_(o.load()) {}
  BoundPort& operator=(const BoundPort& o) { return *this = o.load(); }
  BoundPort& operator=(uint16_t p) {
    v_.store(p, std::memory_order_relaxed);
    return *this;
  }
  operator uint16_t() const { return load(); }
  uint16_t load() const { return v_.load(std::memory_order_relaxed); }

 private:
  std::atomic<uint16_t> v_;
};

struct NodeSettings {
  std::string ruri;      // canonical robot RURI (identity, no capability)
  std::string ruri_sdk;  // the same in the SDKs' 5-segment form (sdk_form), "" if none
  std::string rrn;
  std::string name = "rcan-robot";
  std::string manufacturer;
  std::string model;
  std::vector<std::string> capabilities{"status", "chat", "teleop", "nav", "arm"};
  BoundPort port = 8080;
  std::string rcan_version = "1.0.0";
  std::vector<std::string> extensions{"8.5-sender-type", "16-ai-accountability", "16.6-watermark",
                                      "replay-window"};
  RolePolicy role_policy;
  // Per-role rate limits per minute, indexed by role level (0 unused); 0 = unlimited.
  std::array<uint32_t, 6> rate_per_minute{0, 10, 100, 500, 1000, 0};
  // Failed token verifications one source address may cost per minute (a bucket of as many,
  // refilled continuously); past it, tokens not already verified are refused 429 unverified.
  // 0 = no limit. security.failed_auth_per_address_per_minute.
  uint32_t failed_auth_per_address_per_minute = config::kDefaultFailedAuthPerAddressPerMinute;
  ReplayOptions replay;
  std::vector<InjectionRule> injection_patterns = InjectionScreen::default_rules();
  int64_t heartbeat_timeout_ms = config::kDefaultHeartbeatTimeoutMs;
  int64_t default_ttl_ms = 0;  // applied to commands that carry none (0 = none)
  CodecLimits codec;
  int telemetry_hz = 5;
  size_t audit_listing = 50;  // entries in GET /api/audit
  int64_t handoff_window_ms = 30'000;
  GuestLimits guest_limits;  // seed §6.3 (guest_limits.h)
  std::string state_dir;     // leases, ownership, consent, credential cache ("" = not kept)
  // Entries of a registry's revocation feed kept in force (a table of their own, revocation.h).
  size_t feed_revocations = RevocationList::kDefaultCapacity;
  std::string consent_webhook;  // http:// URL the owner notification is POSTed to ("" = none)
};

class NodeServices {
 public:
  NodeServices(NodeSettings settings, Clock& clock, AuthOptions auth, Actuation& actuation,
               audit::AuditLog& audit);

  NodeSettings settings;
  Clock& clock;
  Authenticator auth;
  // Revoked tokens (`<state_dir>/revocations.json`; revocation.h): checked by authenticate()
  // and, for a stream's CONNECT principal, by the pipeline's authentication stage.
  RevocationList revocations;
  ReplayGuard replay;
  RateLimiter rate;
  // Failed token verifications per source address (authenticate()).
  mutable RateLimiter failed_auth{10'000};
  InjectionScreen injection;
  Actuation& act;
  // What every COMMAND action name means (rcan/actions.h): the built-in table today; a driver
  // that offers skills of its own will extend it.
  const ActionTable& actions = ActionTable::builtin();
  audit::AuditLog& audit;
  // The link to the registry whose tokens the node trusts, for the detailed status (set by
  // rcand before the node serves; empty: no such link).
  std::function<json::Value()> registry_status;
  EventBus events;
  Metrics metrics;
  // Every audit record goes through it (audit_trail.h): records, the stop backlog, refusals.
  AuditTrail trail;
  // Who holds the robot: sessions, leases, ownership, consent, partition (control_service.h).
  ControlService control;
  // The robot's fleet membership (fleet.h); null when it is in no fleet.
  std::shared_ptr<const FleetMembership> fleet;
  std::shared_ptr<AiServices> ai;  // set by the daemon before the node starts; may be null

  uint32_t rate_limit(Role r) const {
    return settings.rate_per_minute[static_cast<size_t>(role_level(r))];
  }

  // The one way a token becomes a principal: verified (JWT, audience, expiry, revocation) and
  // then limited by the node's state (a former owner's token no longer carries ownership).
  // `source` (a peer address; empty for none, and for stops) is charged for each token that
  // fails verification; a source past its budget gets RATE_LIMITED `failed_auth_rate` for
  // any token not already verified, without the cost of verifying it.
  // Errors: AUTH_REQUIRED (empty), AUTH_INVALID, RATE_LIMITED.
  Result<Principal> authenticate(std::string_view token, const std::string& source = {}) const;
  // The same from an Authorization header value ("Bearer <token>"; empty → AUTH_REQUIRED).
  Result<Principal> authenticate_header(std::string_view authorization,
                                        const std::string& source = {}) const;
  // AUTH_INVALID `token_revoked` when the revocation list names `p`'s token.
  Status check_revoked(const Principal& p) const;

  json::Value discovery_info() const;
  json::Value status(bool detailed);
  // A fresh message envelope from the node (type, payload), seed shape.
  json::Value envelope(MessageType type, json::Object payload,
                       const std::string& reply_to = {}) const;
  // The profile's error body with the node's clock.
  json::Value error(const Error& err, const std::string& reply_to = {}) const;
};

}  // namespace rcan::node
