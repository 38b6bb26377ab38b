// Request bodies of the registry API (docs/REGISTRY.md): parsing and validation, apart from
// the routes so that a fuzz target can run arbitrary bytes through them. Nothing here touches
// the store, the network or the clock.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/crypto/registry_proof.h"
#include "rcan/json.h"
#include "rcan/registry.h"
#include "rcan/result.h"

namespace rcan::registry::api {

inline constexpr size_t kMaxTextField = 1024;       // description, source, label
inline constexpr size_t kMaxSlugInput = 256;        // manufacturer/model/version/device_id
inline constexpr size_t kMaxMetadataBytes = 16384;  // metadata object, as JSON
inline constexpr size_t kMaxEndpoints = 16;
inline constexpr size_t kMaxUrl = 2048;

// Slugs are rcan/registry.h's slugify (the reference's slugging). True when a slug carries at least
// one [a-z0-9] (the reference refuses empty slugs; a slug of dashes only cannot name anything
// either).
bool usable_slug(std::string_view slug);

// The RRN forms of the reference: RRN-<8..16 digits> or RRN-<[A-Z0-9]{2,8}>-<8..16 digits>,
// case-insensitive. Returns the canonical RRN (upper case, the number padded to 12 digits:
// rcan/ruri.h parse_rrn) and its prefix ("" for the root namespace).
struct ParsedRrn {
  std::string rrn, prefix;
};
std::optional<ParsedRrn> parse_rrn(std::string_view s);
bool valid_prefix(std::string_view p);  // [A-Z0-9]{2,8}

// A registration's proof of possession is rcan/crypto/registry_proof.h's Proof.

struct Registration {
  std::string manufacturer, model, version, device_id;  // slugged
  std::string description, contact_email, source, rcan_version;
  std::string metadata_json = "{}";
  std::string ed25519_pub, mldsa65_pub;  // base64url, as sent (decoded and checked later)
  std::optional<Proof> proof;
  std::string endpoints_json = "[]";
};

// Field errors come back as kSchemaValidationFailed (kMalformedJson for non-JSON) with a
// message fit for the client.
Result<Registration> parse_registration(std::string_view body, std::string_view now);

// The signed string of a proof of possession is rcan/registry.h's proof_message.

struct Update {
  std::optional<std::string> description, contact_email, metadata_json, endpoints_json;
  bool empty() const { return !description && !contact_email && !metadata_json && !endpoints_json; }
};
Result<Update> parse_update(std::string_view body, std::string_view now);

struct KeyRequest {
  std::string role, label;
};
Result<KeyRequest> parse_key_request(std::string_view body);

struct NodeRequest {
  std::string prefix, operator_name, node_url, node_pubkey, contact, expires_at;
};
// node_url must be https://; `allow_http` also takes http:// (local federation tests only).
Result<NodeRequest> parse_node_request(std::string_view body, bool allow_http = false);

// A webhook subscription (POST /api/v1/webhooks): {"node_prefix", "webhook_url", "secret"}.
// node_prefix is a delegated prefix or "RRN" (the root namespace), upper-cased; webhook_url
// must be https:// (`allow_http` also takes http://, local tests only), without whitespace or
// control characters; secret is required, kMinWebhookSecret..kMaxWebhookSecret bytes of
// printable ASCII.
inline constexpr size_t kMinWebhookSecret = 16;
inline constexpr size_t kMaxWebhookSecret = 256;
struct WebhookRequest {
  std::string prefix, url, secret;
};
Result<WebhookRequest> parse_webhook_request(std::string_view body, bool allow_http = false);

// `endpoints`: an array of URL strings or of {"url": …} objects → the stored form
// [{"url": …, "last_seen": now}].
Result<std::string> normalize_endpoints(const json::Value& endpoints, std::string_view now);

}  // namespace rcan::registry::api
