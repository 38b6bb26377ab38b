// Control sessions and the v1.5 session blocks: `control` (this node's), `offline` (the
// credential cache and partition watch) and `qos` (docs/CONFIG.md §Control sessions, §v1.5
// blocks; docs/SESSIONS.md).
#include "config/blocks/blocks.h"
#include "runtime/http_client.h"

namespace rcan::config::internal {
namespace {

// An optional http:// URL (empty: off).
template <typename T>
Row<T> http_url(std::string key, std::string T::*member) {
  return Rows<T>::read(std::move(key), Str(2048),
                       [member](const At& a, T& out, Ctx&) {
                         if (a) out.*member = a.str();
                         if (!(out.*member).empty() && !rcan::parse_http_url(out.*member).ok())
                           fail(a.path, "must be an http:// URL", "invalid_value");
                       })
      .default_of(member);
}

Table<OfflineConfig> offline_rows() {
  using O = Rows<OfflineConfig>;
  return {
      O::field("grace_period_s", Int(0, 31'536'000), &OfflineConfig::grace_period_s)
          .doc("v1.5 offline grace; read and kept, rcand does not act on it"),
      O::field("cross_owner_grace_s", Int(0, 31'536'000), &OfflineConfig::cross_owner_grace_s)
          .doc("v1.5 offline grace across owners; read and kept, rcand does not act on it"),
      O::field("max_key_ttl_s", Int(0, 31'536'000), &OfflineConfig::max_key_ttl_s)
          .doc("how long the credential cache stays valid after the issuer last answered "
               "(docs/SESSIONS.md)"),
      http_url("issuer_url", &OfflineConfig::issuer_url)
          .doc("an `http://` URL of the token issuer (e.g. its JWKS) probed for reachability; "
               "unreachable: OFFLINE_AUTONOMOUS or LOCKDOWN (seed §6.1); empty: partition "
               "detection off"),
      O::field("issuer_poll_ms", Int(50, 3'600'000), &OfflineConfig::issuer_poll_ms)
          .doc("how often the issuer is probed"),
      O::field("issuer_timeout_ms", Int(50, 60'000), &OfflineConfig::issuer_timeout_ms)
          .doc("how long a probe waits"),
  };
}

Table<ControlConfig> control_rows() {
  using C = Rows<ControlConfig>;
  return {
      C::field("fleet_policy", Enum({"role", "fleet_wins", "individual_wins"}),
               &ControlConfig::fleet_policy)
          .doc("same-role fleet claim (`fleet_id`) vs individual holder: `role` (FIFO queue), "
               "`fleet_wins`, `individual_wins` (seed §5.3)"),
      C::field("handoff_window_s", Int(1, 3600), &ControlConfig::handoff_window_s)
          .doc("AVAILABLE window after release / handoff (seed §2.3)"),
      C::field("queue_max", Int(0, 1024), &ControlConfig::queue_max)
          .doc("same-role claimants that may wait"),
      C::field("queue_wait_s", Int(1, 86400), &ControlConfig::queue_wait_s)
          .doc("a queued claim is dropped after this"),
      C::field("queue_stream_grace_s", Int(0, 86400), &ControlConfig::queue_stream_grace_s)
          .doc("a queued claimant whose last stream closed (a closed tab) and that opens none "
               "again within this is dropped from the queue (`CLAIM_DROPPED`, `stream_closed`)"),
      C::field("max_session_s", Int(0, 31'536'000), &ControlConfig::max_session_s)
          .doc("caps every role's session TTL (0: the role TTLs of PROFILE.md §5)"),
      C::field("transfer_window_s", Int(1, 31'536'000), &ControlConfig::transfer_window_s)
          .doc("TRANSFER_PENDING window (seed §6.2, 24 h)"),
      C::field("consent_ttl_s", Int(1, 31'536'000), &ControlConfig::consent_ttl_s)
          .doc("a pending consent request expires after this"),
      http_url("consent_webhook", &ControlConfig::consent_webhook)
          .doc("`http://` URL the owner notification of a CONSENT_REQUEST is POSTed to (§8.5); "
               "empty: the stream only"),
  };
}

Table<QosConfig> qos_rows() {
  using Q = Rows<QosConfig>;
  return {
      Q::field("ack_timeout_ms", Int(1, 600'000), &QosConfig::ack_timeout_ms)
          .doc("v1.5 QoS; read and kept, rcand does not act on it"),
      Q::field("max_retries", Int(0, 100), &QosConfig::max_retries)
          .doc("v1.5 QoS; read and kept, rcand does not act on it"),
      Q::field("backoff_base_ms", Int(1, 600'000), &QosConfig::backoff_base_ms)
          .doc("v1.5 QoS; read and kept, rcand does not act on it"),
  };
}

}  // namespace

Table<NodeConfig> control_blocks() {
  using R = Rows<NodeConfig>;
  return {
      R::block("offline", offline_rows(), &NodeConfig::offline),
      R::block("control", control_rows(), &NodeConfig::control),
      R::block("qos", qos_rows(), &NodeConfig::qos),
  };
}

}  // namespace rcan::config::internal
