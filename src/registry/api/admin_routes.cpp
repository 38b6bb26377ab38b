// API keys, federation nodes, proof-of-possession challenges and the node manifest.
#include "rcan/crypto/ed25519.h"
#include "rcan/hash.h"
#include "registry/api/impl.h"

namespace rcan::registry::api {
namespace {

json::Object key_json(const ApiKey& k) {
  return json::Object{
      {"id", k.id},
      {"role", k.role},
      {"rrn", k.rrn.empty() ? json::Value() : json::Value(k.rrn)},
      {"label", k.label},
      {"created_at", k.created_at},
      {"revoked_at", k.revoked_at.empty() ? json::Value() : json::Value(k.revoked_at)}};
}

json::Object delegation_json(const Delegation& d) {
  json::Object o{
      {"prefix", d.prefix},
      {"namespace_prefix", d.prefix},
      {"operator", d.operator_name},
      {"node_url", d.node_url},
      {"node_type", "delegated"},
      {"api_base", d.node_url + "/api/v1"},
      {"manifest_url", d.node_url + "/.well-known/rcan-node.json"},
      {"node_pubkey", d.node_pubkey.empty() ? json::Value() : json::Value(d.node_pubkey)},
      {"delegated_at", d.delegated_at},
      {"expires_at", d.expires_at.empty() ? json::Value() : json::Value(d.expires_at)}};
  return o;
}

}  // namespace

HttpResponse RegistryApi::Impl::challenge(bool post) {
  Challenge c;
  Bytes id(16), nonce(32);
  if (!random_bytes(id.data(), id.size()) || !random_bytes(nonce.data(), nonce.size()))
    return store_error(Error(ErrorCode::kInternal, "no randomness"));
  c.id = to_hex(id);
  c.nonce = base64url_encode(nonce);
  c.purpose = "register";
  int64_t t = now_ms();
  c.expires_at = iso_utc(t + int64_t{o.challenge_ttl_s} * 1000);
  (void)store.expire_challenges(iso_utc(t));
  if (Status s = store.put_challenge(c); !s.ok()) return store_error(s.error());
  return json_response(post ? 201 : 200,
                       json::Object{{"challenge_id", c.id},
                                    {"nonce", c.nonce},
                                    {"expires_at", c.expires_at},
                                    {"format",
                                     "rcan-registry-pop:<challenge_id>:<nonce>:<manufacturer>/"
                                     "<model>/<version>/<device_id>"}});
}

HttpResponse RegistryApi::Impl::create_key_route(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (auto l = limit_key(caller->key.id)) return *l;
  if (!caller->is("admin"))
    return project_error(ErrorCode::kInsufficientPrivileges, "creating keys needs an admin key",
                         "authorization", "role");
  auto k = parse_key_request(req.body);
  if (!k.ok()) return from_error(k.error());
  if (auto a = audit_unavailable()) return *a;
  auto token = create_key(k->role, "", k->label, "apikey:" + caller->key.id);
  if (!token.ok()) return store_error(token.error());
  std::string id = token->substr(5, 16);
  return json_response(201, json::Object{{"id", id},
                                         {"key", *token},
                                         {"role", k->role},
                                         {"label", k->label},
                                         {"message", "Store this key now: it is not shown again"}});
}

HttpResponse RegistryApi::Impl::list_keys(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (!caller->is("admin"))
    return project_error(ErrorCode::kInsufficientPrivileges, "listing keys needs an admin key",
                         "authorization", "role");
  auto keys = store.list_api_keys();
  if (!keys.ok()) return store_error(keys.error());
  json::Array out;
  for (const auto& k : *keys) out.emplace_back(key_json(k));
  int64_t total = static_cast<int64_t>(out.size());
  return json_response(200, json::Object{{"keys", std::move(out)}, {"total", total}});
}

HttpResponse RegistryApi::Impl::revoke_key(const HttpRequest& req, const std::string& id) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) return err;
  if (auto l = limit_key(caller->key.id)) return *l;
  if (!caller->is("admin"))
    return project_error(ErrorCode::kInsufficientPrivileges, "revoking keys needs an admin key",
                         "authorization", "role");
  if (auto a = audit_unavailable()) return *a;
  std::string t = now();
  auto done = store.revoke_api_key(id, t);
  if (!done.ok()) return store_error(done.error());
  if (!*done)
    return project_error(ErrorCode::kNotFound, "no active key with that id", "id", "not_found");
  audit("REGISTRY_KEY_REVOKED", "apikey:" + caller->key.id, registry_ruri(),
        json::Object{{"key_id", id}});
  return json_response(200, json::Object{{"id", id}, {"revoked_at", t}});
}

json::Object RegistryApi::Impl::self_node() const {
  std::string prefix = o.prefix.empty() ? "RRN" : o.prefix;
  return json::Object{{"prefix", prefix},
                      {"namespace_prefix", prefix},
                      {"operator", o.operator_name},
                      {"node_url", o.public_url},
                      {"node_type", o.prefix.empty() ? "root" : "authoritative"},
                      {"api_base", o.public_url + "/api/v1"},
                      {"manifest_url", o.public_url + "/.well-known/rcan-node.json"},
                      {"node_pubkey", "ed25519:" + base64url_encode(node_pub)}};
}

HttpResponse RegistryApi::Impl::list_nodes(const HttpRequest& req) {
  std::string filter;
  for (char c : req.query_value("prefix"))
    if (c != ' ') filter.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  // With ?prefix= the matching node comes first (rcan-ts's discover takes nodes[0]; rcan-py's
  // matches namespace_prefix); no match: the root (self) alone, as the reference answers.
  json::Array nodes;
  std::string own = o.prefix.empty() ? "RRN" : o.prefix;
  if (!filter.empty()) {
    if (filter == own) {
      nodes.emplace_back(self_node());
    } else if (valid_prefix(filter)) {
      auto d = store.get_delegation(filter);
      if (!d.ok()) return store_error(d.error());
      if (*d) nodes.emplace_back(delegation_json(**d));
    }
    if (nodes.empty()) nodes.emplace_back(self_node());
  } else {
    nodes.emplace_back(self_node());
    auto all = store.list_delegations();
    if (!all.ok()) return store_error(all.error());
    for (const auto& d : *all) nodes.emplace_back(delegation_json(d));
  }
  int64_t total = static_cast<int64_t>(nodes.size());
  return json_response(200, json::Object{{"nodes", std::move(nodes)}, {"total", total}});
}

HttpResponse RegistryApi::Impl::get_node(const std::string& raw) {
  std::string prefix;
  for (char c : raw)
    prefix.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  if (prefix.empty())
    return json_response(
        400, json::Object{{"error", "INVALID_REQUEST"}, {"message", "prefix is required"}});
  if (prefix == "RRN" || prefix == "ROOT" || (!o.prefix.empty() && prefix == o.prefix))
    return json_response(200, json::Object{{"success", true}, {"node", self_node()}});
  std::optional<Delegation> d;
  if (valid_prefix(prefix)) {
    auto got = store.get_delegation(prefix);
    if (!got.ok()) return store_error(got.error());
    d = std::move(*got);
  }
  if (!d)
    return json_response(
        404, json::Object{{"success", false},
                          {"error", "DELEGATION_NOT_FOUND"},
                          {"message", "No delegation found for prefix '" + prefix + "'"},
                          {"prefix", prefix}});
  return json_response(200, json::Object{{"success", true}, {"node", delegation_json(*d)}});
}

HttpResponse RegistryApi::Impl::add_node(const HttpRequest& req) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller)
    return json_response(
        err.status,
        json::Object{
            {"error", err.status == 401 && req.bearer().empty() ? "AUTH_REQUIRED" : "AUTH_INVALID"},
            {"message", "Bearer token invalid or missing"}});
  if (auto l = limit_key(caller->key.id)) return *l;
  if (!caller->is("admin"))
    return json_response(403, json::Object{{"error", "AUTH_INVALID"},
                                           {"message", "delegating a prefix needs an admin key"}});
  auto n = parse_node_request(req.body, o.allow_http_node_urls);
  if (!n.ok()) {
    std::string code =
        n.error().code == ErrorCode::kMalformedJson ? "INVALID_REQUEST"
        : n.error().reason == "INVALID_PREFIX" || n.error().reason == "INVALID_NODE_URL"
            ? n.error().reason
            : "INVALID_REQUEST";
    return json_response(400, json::Object{{"error", code}, {"message", n.error().message}});
  }
  if (auto a = audit_unavailable()) return *a;
  Delegation d;
  d.prefix = n->prefix;
  d.operator_name = n->operator_name;
  d.node_url = n->node_url;
  d.node_pubkey = n->node_pubkey;
  d.contact = n->contact;
  d.delegated_at = now();
  d.expires_at = n->expires_at;
  auto added = store.add_delegation(d);
  if (!added.ok()) return store_error(added.error());
  if (!*added)
    return json_response(
        409, json::Object{{"error", "DELEGATION_EXISTS"},
                          {"message", "Prefix '" + d.prefix + "' is already registered"},
                          {"prefix", d.prefix}});
  audit(
      "REGISTRY_PREFIX_DELEGATED", "apikey:" + caller->key.id, registry_ruri(),
      json::Object{{"prefix", d.prefix}, {"node_url", d.node_url}, {"operator", d.operator_name}});
  json::Object out{{"success", true},
                   {"prefix", d.prefix},
                   {"operator", d.operator_name},
                   {"node_url", d.node_url},
                   {"delegation_id", "del-" + slugify(d.prefix) + "-" + std::to_string(now_ms())},
                   {"delegated_at", d.delegated_at}};
  if (!d.contact.empty()) out.set("contact", d.contact);
  return json_response(201, out);
}

void RegistryApi::Impl::build_manifest() {
  std::string pub = base64url_encode(node_pub);
  json::Object m{{"rcan_node_version", "1.0"},
                 {"node_type", o.prefix.empty() ? "root" : "authoritative"},
                 {"operator", o.operator_name},
                 {"namespace_prefix", o.prefix.empty() ? "RRN" : o.prefix},
                 {"public_key", "ed25519:" + pub},
                 {"ed25519_public_key", pub},
                 {"crypto_profile", "ed25519"},
                 {"pqc_public_key", nullptr},
                 {"api_base", o.public_url + "/api/v1"},
                 {"spec_version", "2.3"},
                 {"capabilities", json::Array{"register", "resolve", "delegate"}},
                 {"ttl_seconds", 3600},
                 {"contact", o.contact.empty() ? json::Value() : json::Value(o.contact)},
                 {"signature_alg", "ed25519"}};
  std::string signed_bytes = json::canonical(m);
  auto sig = ed25519::sign(o.node_seed, to_bytes(signed_bytes));
  m.set("signature", sig.ok() ? json::Value(base64url_encode(*sig)) : json::Value());
  manifest = json::dump(json::Value(std::move(m)));
}

}  // namespace rcan::registry::api
