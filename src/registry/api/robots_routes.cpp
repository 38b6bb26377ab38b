// Robots: register, list, search, get, update, delete, and resolve.
#include <charconv>

#include "base/strings.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/ruri.h"
#include "registry/api/authority_internal.h"
#include "registry/api/impl.h"

namespace rcan::registry::api {
namespace {

// parseInt of the reference: the leading digits (with a sign), else `def`.
int64_t int_param(const HttpRequest& req, std::string_view name, int64_t def) {
  std::string_view v = req.query_value(name);
  while (!v.empty() && v.front() == ' ') v.remove_prefix(1);
  int64_t out = 0;
  auto [ptr, ec] = std::from_chars(v.data(), v.data() + v.size(), out);
  if (ec != std::errc() || ptr == v.data()) return def;
  return out;
}

std::string trimmed(std::string_view v) { return std::string(trim(v, " ")); }

json::Value parsed_or(const std::string& text, json::Value def) {
  auto v = json::parse(text);
  return v.ok() ? std::move(v).value() : std::move(def);
}

// metadata.ruri as JSON text ("" when absent): what an update may not change.
std::string ruri_of(const std::string& metadata_json) {
  auto v = json::parse(metadata_json);
  const json::Value* r = v.ok() && v->is_object() ? v->get("ruri") : nullptr;
  return r == nullptr ? std::string() : json::dump(*r);
}

bool owns(const Caller& c, const Robot& r) {
  return c.is("admin") || (c.is("robot") && c.key.rrn == r.rrn) ||
         (!r.owner_key_id.empty() && c.key.id == r.owner_key_id);
}

}  // namespace

json::Object RegistryApi::Impl::robot_json(const Robot& r) const {
  json::Object j{{"rrn", r.rrn},
                 {"manufacturer", r.manufacturer},
                 {"model", r.model},
                 {"version", r.version},
                 {"device_id", r.device_id},
                 {"rcan_uri", r.rcan_uri},
                 {"uri", r.rcan_uri},
                 {"verification_tier", r.verification_tier},
                 {"description", r.description},
                 {"source", r.source},
                 {"metadata", parsed_or(r.metadata_json, json::Object{})},
                 {"endpoints", parsed_or(r.endpoints_json, json::Array{})},
                 {"status", r.deleted ? "deleted" : "active"},
                 {"registered_at", r.registered_at},
                 {"updated_at", r.updated_at}};
  j.set("ed25519_public_key", r.ed25519_pub.empty() ? json::Value() : json::Value(r.ed25519_pub));
  j.set("mldsa65_public_key", r.mldsa65_pub.empty() ? json::Value() : json::Value(r.mldsa65_pub));
  return j;
}

json::Object RegistryApi::Impl::tombstone_json(const Robot& r) {
  return json::Object{
      {"rrn", r.rrn}, {"status", "deleted"}, {"deleted", true}, {"updated_at", r.updated_at}};
}

std::optional<HttpResponse> RegistryApi::Impl::check_proof(const Registration& r) {
  bool keys = !r.ed25519_pub.empty() || !r.mldsa65_pub.empty();
  if (!keys && !r.proof) return std::nullopt;
  auto refused = [](const Error& e) { return project_error(e.code, e.message, "proof", e.reason); };
  if (keys && !r.proof)
    return project_error(ErrorCode::kSchemaValidationFailed,
                         "public keys need a proof of possession: get a challenge (GET "
                         "/api/v1/challenge) and sign it with each key",
                         "proof", "proof_required");
  // Malformed keys or missing signatures are refused before the challenge is spent.
  if (Status s = check_proof_shape(r.ed25519_pub, r.mldsa65_pub, *r.proof); !s.ok())
    return refused(s.error());
  // The challenge is used up whatever follows: a failed proof cannot be retried with it.
  auto c = store.take_challenge(r.proof->challenge_id);
  if (!c.ok()) return store_error(c.error());
  if (!*c || (*c)->purpose != "register")
    return project_error(ErrorCode::kSignatureInvalid, "unknown or already used challenge", "proof",
                         "challenge_unknown");
  if ((*c)->expires_at < now())
    return project_error(ErrorCode::kSignatureInvalid, "the challenge has expired", "proof",
                         "challenge_expired");
  const std::string msg =
      proof_message((*c)->id, (*c)->nonce, r.manufacturer, r.model, r.version, r.device_id);
  if (Status s = verify_proof(r.ed25519_pub, r.mldsa65_pub, msg, *r.proof); !s.ok())
    return refused(s.error());
  return std::nullopt;
}

HttpResponse RegistryApi::Impl::register_robot(const HttpRequest& req) {
  HttpResponse err;
  auto who = registrant_of(req, err);
  if (!who) return err;
  std::string t = now();
  auto reg = parse_registration(req.body, t);
  if (!reg.ok()) return ref_error(400, reg.error().message);
  if (auto bad = check_proof(*reg)) return *bad;
  if (auto a = audit_unavailable()) return *a;
  NewRobot n;
  n.manufacturer = reg->manufacturer;
  n.model = reg->model;
  n.version = reg->version;
  n.device_id = reg->device_id;
  n.rcan_uri_base = uri_base();
  n.description = reg->description;
  n.contact_email = reg->contact_email;
  n.source = reg->source;
  n.metadata_json = reg->metadata_json;
  n.ed25519_pub = reg->ed25519_pub;
  n.mldsa65_pub = reg->mldsa65_pub;
  n.endpoints_json = reg->endpoints_json;
  n.owner_key_id = who->owner_key_id;
  n.now = t;
  if (reg->proof && !ruri_of(reg->metadata_json).empty()) {
    // The RURI its tokens will name (docs/THREATS.md T1): the robot the proof named, and no
    // other live record's. (Without one, the tokens name rcan://<host>/<names>, checked when a
    // token is asked for.)
    Robot claimed = robot_of(n);
    claimed.registered_at.clear();  // not stored yet: every live record comes before it
    auto aud = robot_audience(claimed, o.host);
    if (!aud.ok())
      return project_error(ErrorCode::kSchemaValidationFailed, aud.error().message, "metadata.ruri",
                           "ruri_not_proven");
    if (Status s = unique_audience(claimed, *aud); !s.ok())
      return ref_error(409, s.error().message);
  }
  auto done = store.register_robot(n);
  if (!done.ok()) return store_error(done.error());
  const Robot& r = done->robot;
  // Names registered by another registrant are not this caller's to adopt (docs/THREATS.md T3).
  if (!done->created && (!who->caller || !owns(*who->caller, r)))
    return ref_error(409, "these names are registered as " + r.rrn +
                              " by another registrant: an admin must remove that record first");
  if (!done->created)
    return json_response(200, json::Object{{"rrn", r.rrn},
                                           {"rcan_uri", r.rcan_uri},
                                           {"message", "Robot already registered"},
                                           {"already_existed", true}});
  const std::string& principal = who->principal;
  auto key = create_key("robot", r.rrn, "robot " + r.rrn, principal);
  audit("REGISTRY_ROBOT_REGISTERED", principal, r.rcan_uri,
        json::Object{{"rrn", r.rrn}, {"proof_of_possession", reg->proof.has_value()}});
  notify("record.created", r);
  json::Object out{{"rrn", r.rrn},
                   {"rcan_uri", r.rcan_uri},
                   {"uri", r.rcan_uri},
                   {"manufacturer", r.manufacturer},
                   {"model", r.model},
                   {"version", r.version},
                   {"device_id", r.device_id},
                   {"verification_tier", r.verification_tier},
                   {"registered_at", r.registered_at},
                   {"api_key", key.ok() ? json::Value(*key) : json::Value()},
                   {"message", "Robot registered successfully"}};
  if (!r.ed25519_pub.empty() || !r.mldsa65_pub.empty()) out.set("identity_proven", true);
  return json_response(201, out);
}

HttpResponse RegistryApi::Impl::list_robots(const HttpRequest& req) {
  int64_t raw_limit =
      req.has_query("limit") ? int_param(req, "limit", 20) : int_param(req, "per_page", 20);
  int64_t limit = std::min<int64_t>(100, std::max<int64_t>(1, raw_limit));
  int64_t offset = 0;
  if (req.has_query("offset")) {
    offset = std::max<int64_t>(0, int_param(req, "offset", 0));
  } else {
    int64_t page = std::max<int64_t>(1, int_param(req, "page", 1));
    offset = (std::min<int64_t>(page, int64_t{1} << 40) - 1) * limit;
  }
  RobotQuery q;
  q.q = trimmed(req.query_value("q"));
  q.tier = trimmed(req.query_value("tier"));
  if (std::string m = trimmed(req.query_value("manufacturer")); !m.empty())
    q.manufacturer = slugify(m);
  if (std::string m = trimmed(req.query_value("model")); !m.empty()) q.model = slugify(m);
  q.limit = static_cast<int>(limit);
  q.offset = offset;
  auto page = store.list_robots(q);
  if (!page.ok()) return store_error(page.error());
  json::Array robots;
  for (const auto& r : page->robots) robots.emplace_back(robot_json(r));
  int64_t total = page->total;
  bool has_next = offset + limit < total;
  int64_t page_no = offset / limit + 1;
  int64_t pages = (total + limit - 1) / limit;
  json::Object out{{"robots", std::move(robots)},
                   {"total", total},
                   {"limit", limit},
                   {"offset", offset},
                   {"next_offset", has_next ? json::Value(offset + limit) : json::Value()}};
  out.set("pagination", json::Object{{"page", page_no},
                                     {"limit", limit},
                                     {"total", total},
                                     {"total_pages", pages},
                                     {"has_next", has_next},
                                     {"has_prev", offset > 0}});
  out.set("meta", json::Object{{"total", total}, {"page", page_no}, {"per_page", limit}});
  return json_response(200, out);
}

HttpResponse RegistryApi::Impl::search_robots(const HttpRequest& req) {
  RobotQuery q;
  q.q = trimmed(req.query_value("q"));
  q.tier = trimmed(req.query_value("tier"));
  if (std::string m = trimmed(req.query_value("manufacturer")); !m.empty())
    q.manufacturer = slugify(m);
  if (std::string m = trimmed(req.query_value("model")); !m.empty()) q.model = slugify(m);
  bool filtered = !q.tier.empty() || !q.manufacturer.empty() || !q.model.empty();
  if ((q.q.size() < 2 && !filtered) || (!q.q.empty() && q.q.size() < 2))
    return json_response(400, json::Object{{"error", "Query must be at least 2 characters"},
                                           {"results", json::Array{}}});
  q.limit =
      static_cast<int>(std::min<int64_t>(50, std::max<int64_t>(1, int_param(req, "limit", 10))));
  auto page = store.list_robots(q);
  if (!page.ok()) return store_error(page.error());
  json::Array results;
  for (const auto& r : page->robots) results.emplace_back(robot_json(r));
  int64_t count = static_cast<int64_t>(results.size());
  return json_response(200,
                       json::Object{{"q", q.q}, {"results", std::move(results)}, {"count", count}});
}

HttpResponse RegistryApi::Impl::get_robot(const std::string& rrn) {
  auto r = store.get_robot(rrn);
  if (!r.ok()) return store_error(r.error());
  if (!*r) return ref_error(404, "Robot not found: " + rrn);
  HttpResponse out = json_response(200, robot_json(**r));
  out.headers.emplace_back("Cache-Control", "public, max-age=60, stale-while-revalidate=300");
  return out;
}

// A robot that proved its keys changes its record only by requests it signs: the key alone
// (a bearer secret) is not enough. The timestamp must be within 5 minutes of the registry's
// clock and later than the record's last change, so a captured request cannot be replayed.
std::optional<HttpResponse> RegistryApi::Impl::check_signed_update(const HttpRequest& req,
                                                                   const Robot& robot) {
  auto refuse = [](std::string msg, std::string reason) {
    return project_error(ErrorCode::kSignatureInvalid, std::move(msg), "X-RCAN-Signature",
                         std::move(reason));
  };
  const std::string ts_text(req.header("x-rcan-timestamp"));
  const std::string_view sig = req.header("x-rcan-signature");
  int64_t ts = -1;
  if (!ts_text.empty() && ts_text.size() <= 16 &&
      ts_text.find_first_not_of("0123456789") == std::string::npos)
    ts = std::stoll(ts_text);
  if (ts < 0 || sig.empty())
    return refuse(
        "this robot proved its keys: its updates must be signed (X-RCAN-Timestamp, "
        "X-RCAN-Signature: ed25519=<signature of rcan-registry-update:<RRN>:<timestamp>:<body>>)",
        "signature_required");
  const int64_t t = now_ms();
  if (ts > t + 300'000 || ts < t - 300'000)
    return refuse("X-RCAN-Timestamp is more than 5 minutes from the registry's clock",
                  "timestamp_skew");
  // The signature first: a request the robot did not sign learns nothing about the record.
  if (Status s = verify_update(robot.ed25519_pub, update_message(robot.rrn, ts, req.body), sig);
      !s.ok())
    return refuse(s.error().message, s.error().reason);
  if (ts <= iso_utc_ms(robot.updated_at))
    return refuse("X-RCAN-Timestamp is not later than the record's last change (a replay?)",
                  "replayed");
  return std::nullopt;
}

std::optional<RegistryApi::Impl::RobotWrite> RegistryApi::Impl::robot_write(const HttpRequest& req,
                                                                            const std::string& rrn,
                                                                            HttpResponse& refusal) {
  HttpResponse err;
  auto caller = authenticate(req, err);
  if (!caller) {
    refusal = err.status >= 500 ? err
                                : ref_error(err.status, err.status == 401 && req.bearer().empty()
                                                            ? "Authorization required"
                                                            : "Invalid API key");
    return std::nullopt;
  }
  if (auto l = limit_key(caller->key.id)) {
    refusal = *l;
    return std::nullopt;
  }
  auto r = store.get_robot(rrn);
  if (!r.ok() || !*r) {
    refusal = !r.ok() ? store_error(r.error()) : ref_error(404, "Robot not found: " + rrn);
    return std::nullopt;
  }
  return RobotWrite{std::move(*caller), std::move(**r)};
}

HttpResponse RegistryApi::Impl::patch_robot(const HttpRequest& req, const std::string& rrn) {
  HttpResponse refusal;
  auto w = robot_write(req, rrn, refusal);
  if (!w) return refusal;
  const Caller* caller = &w->caller;
  const Robot* robot = &w->robot;
  if (!caller->is("admin") && !(caller->is("robot") && caller->key.rrn == robot->rrn))
    return ref_error(403, "Invalid API key");
  if (caller->is("robot") && !robot->ed25519_pub.empty())
    if (auto refused = check_signed_update(req, *robot)) return *refused;
  std::string t = now();
  auto u = parse_update(req.body, t);
  if (!u.ok()) return ref_error(400, u.error().message);
  if (u->empty()) return ref_error(400, "No updatable fields provided");
  // The RURI a proven robot's tokens name is set by its registration, never by an update.
  if (u->metadata_json && (!robot->ed25519_pub.empty() || !robot->mldsa65_pub.empty()) &&
      ruri_of(*u->metadata_json) != ruri_of(robot->metadata_json))
    return project_error(ErrorCode::kSchemaValidationFailed,
                         "metadata.ruri of a robot that proved its keys is set at its "
                         "registration and does not change",
                         "metadata.ruri", "ruri_fixed");
  if (auto a = audit_unavailable()) return *a;
  RobotUpdate ru;
  ru.description = u->description;
  ru.contact_email = u->contact_email;
  ru.metadata_json = u->metadata_json;
  ru.endpoints_json = u->endpoints_json;
  ru.now = t;
  auto done = store.update_robot(robot->rrn, ru);
  if (!done.ok()) return store_error(done.error());
  if (!*done) return ref_error(404, "Robot not found: " + rrn);
  json::Array fields;
  for (auto [name, set] : {std::pair{"description", u->description.has_value()},
                           {"contact_email", u->contact_email.has_value()},
                           {"metadata", u->metadata_json.has_value()},
                           {"endpoints", u->endpoints_json.has_value()}})
    if (set) fields.emplace_back(name);
  audit("REGISTRY_ROBOT_UPDATED", "apikey:" + caller->key.id, (*done)->rcan_uri,
        json::Object{{"rrn", (*done)->rrn}, {"fields", std::move(fields)}});
  notify("record.updated", **done);
  return json_response(200, robot_json(**done));
}

HttpResponse RegistryApi::Impl::delete_robot(const HttpRequest& req, const std::string& rrn) {
  HttpResponse refusal;
  auto w = robot_write(req, rrn, refusal);
  if (!w) return refusal;
  const Robot& robot = w->robot;
  if (!owns(w->caller, robot)) return ref_error(403, "Invalid API key");
  if (auto a = audit_unavailable()) return *a;
  Robot gone = robot;
  gone.deleted = true;
  gone.updated_at = now();
  auto done = store.delete_robot(robot.rrn, gone.updated_at);
  if (!done.ok()) return store_error(done.error());
  if (!*done) return ref_error(404, "Robot not found: " + rrn);
  audit("REGISTRY_ROBOT_DELETED", "apikey:" + w->caller.key.id, robot.rcan_uri,
        json::Object{{"rrn", robot.rrn}});
  notify("record.deleted", gone);
  return json_response(200,
                       json::Object{{"message", "Robot registration removed"}, {"rrn", robot.rrn}});
}

HttpResponse RegistryApi::Impl::resolved(const Robot& r, const std::string& ns,
                                         const std::string& by, const char* cache) {
  json::Object rec = robot_json(r);
  json::Object keys{
      {"ed25519", rec.find("ed25519_public_key") ? *rec.find("ed25519_public_key") : json::Value()},
      {"mldsa65",
       rec.find("mldsa65_public_key") ? *rec.find("mldsa65_public_key") : json::Value()}};
  json::Value endpoints = *rec.find("endpoints");
  json::Object out{{"rrn", r.rrn},
                   {"resolved_by", by},
                   {"namespace", ns},
                   {"record", std::move(rec)},
                   {"keys", std::move(keys)},
                   {"endpoints", std::move(endpoints)},
                   {"cache_status", cache},
                   {"resolved_at", now()}};
  return json_response(200, out);
}

HttpResponse RegistryApi::Impl::resolve(const HttpRequest& req, const std::string& raw) {
  (void)req;
  auto parsed = parse_rrn(raw);
  auto with = [this](HttpResponse r, const std::string& by, const std::string& ns) {
    r.headers.emplace_back("X-Resolved-By", by);
    r.headers.emplace_back("X-Cache", "MISS");
    r.headers.emplace_back("X-RRN-Namespace", ns);
    return r;
  };
  if (!parsed) {
    return with(json_response(
                    400, json::Object{{"error", "INVALID_RRN_FORMAT"}, {"rrn", ascii_upper(raw)}}),
                o.public_url, "");
  }
  const std::string& rrn = parsed->rrn;
  std::string ns = parsed->prefix.empty() ? "root" : parsed->prefix;
  bool local = parsed->prefix.empty() ? o.prefix.empty() : parsed->prefix == o.prefix;
  if (!local && !parsed->prefix.empty()) {
    auto d = store.get_delegation(parsed->prefix);
    if (!d.ok()) return store_error(d.error());
    if (!*d)
      return with(json_response(404, json::Object{{"error", "NODE_DELEGATION_NOT_FOUND"},
                                                  {"prefix", parsed->prefix},
                                                  {"rrn", rrn}}),
                  o.public_url, ns);
    if (!(*d)->expires_at.empty() && (*d)->expires_at < now())
      return with(json_response(404, json::Object{{"error", "NODE_DELEGATION_EXPIRED"},
                                                  {"prefix", parsed->prefix},
                                                  {"rrn", rrn},
                                                  {"expired_at", (*d)->expires_at}}),
                  o.public_url, ns);
    // A copy synced from the authoritative node (--sync-from) is answered here.
    auto copy = store.get_robot(rrn);
    if (!copy.ok()) return store_error(copy.error());
    if (*copy) return with(resolved(**copy, ns, (*d)->node_url, "SYNCED"), (*d)->node_url, ns);
    // No fan-out from here: the client is sent to the authoritative node.
    std::string loc = (*d)->node_url + "/api/v1/resolve/" + rrn;
    HttpResponse r = json_response(307, json::Object{{"rrn", rrn},
                                                     {"namespace", ns},
                                                     {"authoritative_node", (*d)->node_url},
                                                     {"api_base", (*d)->node_url + "/api/v1"},
                                                     {"location", loc}});
    r.headers.emplace_back("Location", loc);
    return with(std::move(r), (*d)->node_url, ns);
  }
  // A root RRN on a prefix node, or another prefix's RRN on the root without delegation,
  // falls through to the local lookup (a synced copy may be here).
  auto r = store.get_robot(rrn);
  if (!r.ok()) return store_error(r.error());
  if (!*r)
    return with(json_response(404, json::Object{{"error", "NOT_FOUND"}, {"rrn", rrn}}),
                o.public_url, ns);
  return with(resolved(**r, ns, o.public_url, "MISS"), o.public_url, ns);
}

HttpResponse RegistryApi::Impl::resolve_uri(const HttpRequest& req) {
  const std::string text(req.query_value("uri"));
  auto ruri = parse_ruri(text);
  if (text.empty() || !ruri.ok() || ruri->form == Ruri::Form::kDiscovered)
    return json_response(400,
                         json::Object{{"error", "INVALID_RURI"},
                                      {"message", text.empty() ? std::string("uri is required")
                                                  : ruri.ok()  ? std::string("a discovered RURI "
                                                                              "names no robot")
                                                               : ruri.error().message}});
  const std::string version = ruri->version.empty() ? "v1" : ruri->version;
  const std::string uri = uri_base() + "/" + slugify(ruri->manufacturer) + "/" +
                          slugify(ruri->model) + "/" + slugify(version) + "/" +
                          slugify(ruri->device_id);
  auto r = store.find_robot_by_uri(uri);
  if (!r.ok()) return store_error(r.error());
  if (!*r) return json_response(404, json::Object{{"error", "NOT_FOUND"}, {"rcan_uri", uri}});
  return resolve(req, (*r)->rrn);
}

}  // namespace rcan::registry::api
