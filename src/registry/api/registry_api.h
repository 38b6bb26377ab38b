// The registry's HTTP API (docs/REGISTRY.md): robots, resolve, federation nodes, the node
// manifest, API keys and proof-of-possession challenges, compatible with the rcan.dev
// reference and the official SDK clients. One HttpHandler over a Store (src/registry/store.h);
// every change is appended to the audit log.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "base/metrics.h"
#include "rcan/audit/audit_log.h"
#include "rcan/encoding.h"
#include "rcan/result.h"
#include "registry/api/address.h"
#include "registry/api/rate_limit.h"
#include "registry/api/webhooks.h"
#include "registry/store.h"
#include "transport/http_api.h"

namespace rcan::registry::api {

struct ApiOptions {
  std::string public_url = "http://127.0.0.1:8090";  // what clients use; no trailing '/'
  std::string host = "127.0.0.1";                    // registry host of rcan:// URIs
  std::string prefix;                                // authoritative for RRN-<prefix>-…; "" root
  Bytes node_seed;                                   // the node's Ed25519 seed (32 bytes)
  std::string operator_name = "rcan-registry";
  std::string contact;
  // Rate limits (rate 0 = unlimited): writes per API key; per client address, the writes of
  // callers who proved a credential (a valid API key, a token request's valid client
  // credentials), anonymous writes (challenges and every write without such a credential:
  // their own, smaller bucket, so that an anonymous flood from a shared address never spends
  // what a registrant there needs), and reads.
  BucketConfig write_per_key{10, 20};
  BucketConfig write_per_address{50, 100};
  BucketConfig anonymous_per_address{20, 40};
  BucketConfig read_per_address{2000, 4000};
  // Anonymous registration (POST /api/v1/robots without credentials, as rcan.dev takes it): off
  // unless set; then a robot is registered at the community tier, its public keys proven as with
  // a key, and an address registers five, then one a minute (over the anonymous write bucket).
  bool open_registration = false;
  BucketConfig open_registration_per_address{1.0 / 60, 5};
  // Peers whose X-Forwarded-For names the client (the TLS proxy in front of the registry);
  // from any other peer the header is ignored.
  std::vector<Cidr> trusted_proxies;
  int challenge_ttl_s = 300;
  // Accept http:// node URLs in delegations (local federation tests; never in production).
  bool allow_http_node_urls = false;
  std::function<int64_t()> wall_ms;  // unset: the system clock
  // The token authority (docs/REGISTRY.md "Token authority").
  int64_t key_overlap_s = 600;       // a new key is published this long before it signs
  int64_t key_lifetime_s = 2592000;  // a key signs this long before one replaces it (30 days)
  int64_t max_token_ttl_s = 3600;    // cap on every token's lifetime
  int64_t jwks_max_age_s = 300;      // Cache-Control of the JWKS
  int64_t device_ttl_s = 600, device_interval_s = 5;
  // Webhook deliveries (docs/REGISTRY.md "Webhooks"); webhook URLs may be http:// only with
  // allow_http_node_urls.
  WebhookOptions webhooks;
  // Federation sync: authoritative nodes (their public URLs) pulled every sync_interval_ms.
  std::vector<std::string> sync_from;
  bool sync_delegations = false;  // also every delegation's node_url
  int sync_interval_ms = 60000;
};

// "2026-11-27T05:20:00.000Z"
std::string iso_utc(int64_t ms);
// The inverse of iso_utc; -1 when `s` is not in that form.
int64_t iso_utc_ms(std::string_view s);

class RegistryApi : public transport::HttpHandler {
 public:
  // `store` and `audit` must outlive the API. `audit` may be null (tests of the routes only).
  RegistryApi(Store& store, audit::AuditLog* audit, ApiOptions options);
  ~RegistryApi() override;

  void handle(transport::HttpRequest req, Respond respond) override;
  // The same, synchronously.
  transport::HttpResponse serve(const transport::HttpRequest& req);

  // Creates and stores an API key; returns the presented form "rcan_<id>_<secret>", which is
  // never stored. `by` names who asked, for the audit record.
  Result<std::string> create_key(const std::string& role, const std::string& rrn,
                                 const std::string& label, const std::string& by);

  // The database's first admin key (by system:first-start), presented form; nullopt, and no key
  // made, when the database holds a live admin key already (a restart without admin.key, or
  // another instance on the same database).
  Result<std::optional<std::string>> create_first_admin_key();

  // The signed node manifest (GET /.well-known/rcan-node.json).
  const std::string& manifest() const;

  class Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace rcan::registry::api
