#include "registry/api/body.h"

#include <cctype>

#include "base/strings.h"
#include "rcan/ruri.h"

namespace rcan::registry::api {
namespace {

Error invalid(std::string msg, std::string field, std::string reason = "invalid") {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field),
               std::move(reason));
}

Result<json::Object> parse_object(std::string_view body) {
  json::ParseOptions po;
  po.max_depth = 16;
  po.max_bytes = 256 * 1024;
  auto v = json::parse(body, po);
  if (!v.ok()) return Error(ErrorCode::kMalformedJson, "Request body must be valid JSON");
  if (!v->is_object()) return invalid("Request body must be a JSON object", "body", "not_object");
  return std::move(v->as_object());
}

// An optional string member: absent or null → nullopt; another type → error.
Result<std::optional<std::string>> opt_string(const json::Object& o, std::string_view key,
                                              size_t max) {
  const json::Value* v = o.find(key);
  if (v == nullptr || v->is_null()) return std::optional<std::string>();
  if (!v->is_string()) return invalid(std::string(key) + " must be a string", std::string(key));
  if (v->as_string().size() > max)
    return invalid(std::string(key) + " is longer than " + std::to_string(max) + " bytes",
                   std::string(key), "too_long");
  return std::optional<std::string>(v->as_string());
}

bool valid_email(std::string_view e) {
  if (e.empty()) return true;
  size_t at = e.find('@');
  if (at == 0 || at == std::string_view::npos || at + 1 >= e.size()) return false;
  for (char c : e)
    if (static_cast<unsigned char>(c) <= 0x20 || c == '<' || c == '>' || c == '"') return false;
  return e.size() <= 254;
}

Result<std::string> metadata_of(const json::Value& v) {
  if (!v.is_object()) return invalid("metadata must be a JSON object", "metadata", "not_object");
  std::string s = json::dump(v);
  if (s.size() > kMaxMetadataBytes)
    return invalid("metadata is larger than " + std::to_string(kMaxMetadataBytes) + " bytes",
                   "metadata", "too_long");
  return s;
}

bool base64url_chars(std::string_view s) {
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) return false;
  return true;
}

}  // namespace

bool usable_slug(std::string_view slug) {
  for (char c : slug)
    if (c != '-') return true;
  return false;
}

bool valid_prefix(std::string_view p) {
  if (p.size() < 2 || p.size() > 8) return false;
  for (char c : p)
    if (!((c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9'))) return false;
  return true;
}

std::optional<ParsedRrn> parse_rrn(std::string_view s) {
  auto canonical = normalize_rrn(s);  // rcan/registry.h: the core's parse_rrn, any case
  if (!canonical) return std::nullopt;
  return ParsedRrn{*canonical, rcan::parse_rrn(*canonical)->prefix};
}

Result<std::string> normalize_endpoints(const json::Value& endpoints, std::string_view now) {
  if (!endpoints.is_array()) return invalid("endpoints must be an array", "endpoints");
  if (endpoints.as_array().size() > kMaxEndpoints)
    return invalid("at most " + std::to_string(kMaxEndpoints) + " endpoints", "endpoints",
                   "too_many");
  json::Array out;
  for (const auto& e : endpoints.as_array()) {
    const json::Value* url = e.is_string() ? &e : (e.is_object() ? e.get("url") : nullptr);
    if (url == nullptr || !url->is_string())
      return invalid("each endpoint is a URL string or {\"url\": …}", "endpoints");
    const std::string& u = url->as_string();
    bool scheme = u.rfind("https://", 0) == 0 || u.rfind("http://", 0) == 0 ||
                  u.rfind("wss://", 0) == 0 || u.rfind("ws://", 0) == 0 ||
                  u.rfind("mqtt://", 0) == 0 || u.rfind("mqtts://", 0) == 0;
    if (!scheme || u.size() > kMaxUrl)
      return invalid("endpoint URLs are http(s)://, ws(s):// or mqtt(s)://, at most 2048 bytes",
                     "endpoints");
    out.emplace_back(json::Object{{"url", u}, {"last_seen", std::string(now)}});
  }
  return json::dump(json::Value(std::move(out)));
}

Result<Registration> parse_registration(std::string_view body, std::string_view now) {
  auto o = parse_object(body);
  if (!o.ok()) return o.error();
  Registration r;
  std::string* slugs[] = {&r.manufacturer, &r.model, &r.version, &r.device_id};
  const char* names[] = {"manufacturer", "model", "version", "device_id"};
  for (int i = 0; i < 4; ++i) {
    auto s = opt_string(*o, names[i], kMaxSlugInput);
    if (!s.ok()) return s.error();
    if (!*s || (*s)->empty())
      return invalid("Required fields: manufacturer, model, version, device_id", names[i],
                     "missing");
    *slugs[i] = slugify(**s);
    if (!usable_slug(*slugs[i]))
      return invalid("Fields must contain valid characters (a-z, 0-9, hyphens)", names[i]);
  }
  struct Text {
    const char* name;
    std::string* out;
    size_t max;
  } texts[] = {
      {"description", &r.description, kMaxTextField}, {"contact_email", &r.contact_email, 254},
      {"source", &r.source, kMaxTextField},           {"rcan_version", &r.rcan_version, 32},
      {"ed25519_public_key", &r.ed25519_pub, 64},     {"mldsa65_public_key", &r.mldsa65_pub, 2700}};
  for (const auto& t : texts) {
    auto s = opt_string(*o, t.name, t.max);
    if (!s.ok()) return s.error();
    if (*s) *t.out = **s;
  }
  if (!valid_email(r.contact_email))
    return invalid("contact_email is not an e-mail address", "contact_email");
  if (!base64url_chars(r.ed25519_pub) || !base64url_chars(r.mldsa65_pub))
    return invalid("public keys are base64url without padding", "ed25519_public_key");
  if (const json::Value* m = o->find("metadata"); m != nullptr && !m->is_null()) {
    auto s = metadata_of(*m);
    if (!s.ok()) return s.error();
    r.metadata_json = *s;
  }
  if (const json::Value* e = o->find("endpoints"); e != nullptr && !e->is_null()) {
    auto s = normalize_endpoints(*e, now);
    if (!s.ok()) return s.error();
    r.endpoints_json = *s;
  }
  if (const json::Value* p = o->find("proof"); p != nullptr && !p->is_null()) {
    if (!p->is_object()) return invalid("proof must be an object", "proof");
    Proof proof;
    struct F {
      const char* name;
      std::string* out;
      size_t max;
    } fs[] = {{"challenge_id", &proof.challenge_id, 64},
              {"ed25519_sig", &proof.ed25519_sig, 128},
              {"mldsa65_sig", &proof.mldsa65_sig, 4500}};
    for (const auto& f : fs) {
      auto s = opt_string(p->as_object(), f.name, f.max);
      if (!s.ok()) return s.error();
      if (*s) *f.out = **s;
    }
    if (proof.challenge_id.empty()) return invalid("proof.challenge_id is required", "proof");
    r.proof = std::move(proof);
  }
  return r;
}

Result<Update> parse_update(std::string_view body, std::string_view now) {
  auto o = parse_object(body);
  if (!o.ok()) return o.error();
  Update u;
  auto d = opt_string(*o, "description", kMaxTextField);
  if (!d.ok()) return d.error();
  u.description = *d;
  auto c = opt_string(*o, "contact_email", 254);
  if (!c.ok()) return c.error();
  if (*c && !valid_email(**c))
    return invalid("contact_email is not an e-mail address", "contact_email");
  u.contact_email = *c;
  if (const json::Value* m = o->find("metadata"); m != nullptr && !m->is_null()) {
    auto s = metadata_of(*m);
    if (!s.ok()) return s.error();
    u.metadata_json = *s;
  }
  if (const json::Value* e = o->find("endpoints"); e != nullptr && !e->is_null()) {
    auto s = normalize_endpoints(*e, now);
    if (!s.ok()) return s.error();
    u.endpoints_json = *s;
  }
  return u;
}

Result<KeyRequest> parse_key_request(std::string_view body) {
  auto o = parse_object(body);
  if (!o.ok()) return o.error();
  KeyRequest k;
  auto role = opt_string(*o, "role", 16);
  if (!role.ok()) return role.error();
  k.role = role->value_or("registrant");
  if (k.role != "registrant" && k.role != "admin")
    return invalid("role must be \"registrant\" or \"admin\"", "role");
  auto label = opt_string(*o, "label", 128);
  if (!label.ok()) return label.error();
  k.label = label->value_or("");
  return k;
}

Result<NodeRequest> parse_node_request(std::string_view body, bool allow_http) {
  auto o = parse_object(body);
  if (!o.ok()) return o.error();
  NodeRequest n;
  struct F {
    const char* name;
    std::string* out;
    size_t max;
  } fs[] = {{"prefix", &n.prefix, 8},           {"operator", &n.operator_name, 256},
            {"node_url", &n.node_url, kMaxUrl}, {"node_pubkey", &n.node_pubkey, 256},
            {"contact", &n.contact, 256},       {"expires_at", &n.expires_at, 32}};
  for (const auto& f : fs) {
    auto s = opt_string(*o, f.name, f.max);
    if (!s.ok()) return s.error();
    if (*s) *f.out = **s;
  }
  n.prefix = ascii_upper(n.prefix);
  if (!valid_prefix(n.prefix))
    return invalid("prefix must be 2–8 uppercase alphanumeric characters (e.g. BD, ACME)", "prefix",
                   "INVALID_PREFIX");
  if (n.operator_name.empty()) return invalid("operator is required", "operator", "missing");
  bool https = n.node_url.rfind("https://", 0) == 0 && n.node_url.size() > 8;
  bool http = allow_http && n.node_url.rfind("http://", 0) == 0 && n.node_url.size() > 7;
  if (!https && !http)
    return invalid("node_url must start with https://", "node_url", "INVALID_NODE_URL");
  while (!n.node_url.empty() && n.node_url.back() == '/') n.node_url.pop_back();
  return n;
}

Result<WebhookRequest> parse_webhook_request(std::string_view body, bool allow_http) {
  auto o = parse_object(body);
  if (!o.ok()) return o.error();
  WebhookRequest w;
  auto prefix = opt_string(*o, "node_prefix", 8);
  if (!prefix.ok()) return prefix.error();
  auto url = opt_string(*o, "webhook_url", kMaxUrl);
  if (!url.ok()) return url.error();
  auto secret = opt_string(*o, "secret", kMaxWebhookSecret);
  if (!secret.ok()) return secret.error();
  w.prefix = ascii_upper(prefix->value_or(""));
  if (w.prefix != "RRN" && !valid_prefix(w.prefix))
    return invalid("node_prefix must be RRN or 2–8 uppercase alphanumeric characters",
                   "node_prefix", "INVALID_PREFIX");
  w.url = url->value_or("");
  for (char c : w.url)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f)
      return invalid("webhook_url must not contain whitespace or control characters", "webhook_url",
                     "INVALID_URL");
  bool https = w.url.rfind("https://", 0) == 0 && w.url.size() > 8;
  bool http = allow_http && w.url.rfind("http://", 0) == 0 && w.url.size() > 7;
  if (!https && !http)
    return invalid("webhook_url must start with https://", "webhook_url", "INVALID_URL");
  w.secret = secret->value_or("");
  if (w.secret.size() < kMinWebhookSecret)
    return invalid("secret is required: at least 16 bytes", "secret", "missing");
  for (char c : w.secret)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7e)
      return invalid("secret must be printable ASCII", "secret");
  return w;
}

}  // namespace rcan::registry::api
