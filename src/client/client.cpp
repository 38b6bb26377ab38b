// rcan::client — the HTTP calls, typed answers and host probing (include/rcan/client.h).
#include "rcan/client.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <future>

#include "client/net.h"
#include "rcan/errors.h"

namespace rcan::client {
namespace {

int64_t int_of(const json::Value& v, std::string_view key, int64_t def) {
  const json::Value* f = v.get(key);
  if (f && f->is_int()) return f->as_int();
  if (f && f->is_double()) return static_cast<int64_t>(f->as_double());
  return def;
}

std::vector<std::string> strings_of(const json::Value& v, std::string_view key) {
  std::vector<std::string> out;
  const json::Value* f = v.get(key);
  if (f && f->is_array())
    for (const auto& e : f->as_array())
      if (e.is_string()) out.push_back(e.as_string());
  return out;
}

ClientError schema_error(const std::string& what, const json::Value& body = {}) {
  ClientError e;
  e.code = "SCHEMA_VALIDATION_FAILED";
  e.http_status = 200;
  e.message = what;
  e.body = body;
  return e;
}

json::ParseOptions parse_opts() {
  json::ParseOptions po;
  po.max_depth = 64;
  po.max_bytes = 64u << 20;
  return po;
}

Result<Reply> reply_from(int status, const json::Value& v) {
  if (!v.is_object()) return schema_error("the answer is not a JSON object", v);
  Reply r;
  r.http_status = status;
  r.type = json::string_field(v, "type");
  if (r.type.empty()) r.type = json::string_field(v, "message_type");
  r.message_id = json::string_field(v, "message_id");
  r.reply_to = json::string_field(v, "reply_to");
  if (const json::Value* p = v.get("payload")) r.payload = *p;
  r.raw = v;
  return r;
}

std::string url_encode(std::string_view s) {
  static const char* hex = "0123456789ABCDEF";
  std::string o;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~') {
      o.push_back(static_cast<char>(c));
    } else {
      o.push_back('%');
      o.push_back(hex[c >> 4]);
      o.push_back(hex[c & 15]);
    }
  }
  return o;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

Result<Endpoint> parse_endpoint(std::string_view url) {
  auto bad = [&](const std::string& why) {
    ClientError e;
    e.code = "BAD_URL";
    e.message = "bad URL '" + std::string(url.substr(0, 200)) + "': " + why;
    return e;
  };
  Endpoint ep;
  std::string_view rest = url;
  if (rest.rfind("https://", 0) == 0 || rest.rfind("wss://", 0) == 0) {
    ep.tls = true;
    rest.remove_prefix(rest[0] == 'h' ? 8 : 6);
  } else if (rest.rfind("http://", 0) == 0 || rest.rfind("ws://", 0) == 0) {
    rest.remove_prefix(rest[0] == 'h' ? 7 : 5);
  } else if (rest.find("://") != std::string_view::npos) {
    return bad("the scheme must be http or https");
  }
  std::string_view authority = rest.substr(0, rest.find('/'));
  std::string_view path =
      rest.size() > authority.size() ? rest.substr(authority.size()) : std::string_view();
  if (authority.find('@') != std::string_view::npos)
    return bad("user information is not supported");
  std::string_view port_text;
  if (!authority.empty() && authority.front() == '[') {
    size_t close = authority.find(']');
    if (close == std::string_view::npos) return bad("unterminated IPv6 address");
    ep.host = std::string(authority.substr(1, close - 1));
    std::string_view after = authority.substr(close + 1);
    if (!after.empty()) {
      if (after.front() != ':') return bad("junk after the IPv6 address");
      port_text = after.substr(1);
    }
  } else {
    size_t colon = authority.rfind(':');
    if (colon != std::string_view::npos) {
      ep.host = std::string(authority.substr(0, colon));
      port_text = authority.substr(colon + 1);
    } else {
      ep.host = std::string(authority);
    }
  }
  if (ep.host.empty()) return bad("no host");
  for (char c : ep.host)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == ':' ||
          c == '_' || c == '%'))
      return bad("invalid character in the host");
  ep.port = ep.tls ? 443 : 80;
  if (!port_text.empty()) {
    if (port_text.size() > 5) return bad("bad port");
    long p = 0;
    for (char c : port_text) {
      if (c < '0' || c > '9') return bad("bad port");
      p = p * 10 + (c - '0');
    }
    if (p < 1 || p > 65535) return bad("port out of range");
    ep.port = static_cast<uint16_t>(p);
  }
  if (auto q = path.find_first_of("?#"); q != std::string_view::npos) path = path.substr(0, q);
  while (!path.empty() && path.back() == '/') path.remove_suffix(1);
  ep.base_path = std::string(path);
  return ep;
}

std::string RawResponse::header(std::string_view name) const {
  for (const auto& [k, v] : headers)
    if (k == name) return v;
  return {};
}

ClientError error_from_response(int status, std::string_view body, std::string_view retry_after) {
  ClientError e;
  e.http_status = status;
  e.code = "HTTP_" + std::to_string(status);
  e.message = "HTTP " + std::to_string(status);
  if (!retry_after.empty()) e.retry_after_s = std::atoll(std::string(retry_after).c_str());
  auto v = json::parse(body, parse_opts());
  if (!v.ok() || !v->is_object()) {
    if (!body.empty()) e.message += ": " + std::string(body.substr(0, 200));
    return e;
  }
  e.body = *v;
  if (const json::Value* p = v->get("payload"); p && p->is_object()) {
    // The profile's body: payload.error_code / error / reason / detail.reason.
    if (std::string c = json::string_field(*p, "error_code"); !c.empty()) e.code = c;
    if (std::string m = json::string_field(*p, "error"); !m.empty()) e.message = m;
    e.reason = json::string_field(*p, "reason");
    if (e.reason.empty())
      if (const json::Value* d = p->get("detail"); d && d->is_object())
        e.reason = json::string_field(*d, "reason");
  } else {
    // Other shapes: {"error","code"} (§16.6 verify), {"error_code", …}, {"error": …}.
    for (const char* k : {"error_code", "code"})
      if (std::string c = json::string_field(*v, k); !c.empty()) {
        e.code = c;
        break;
      }
    if (std::string m = json::string_field(*v, "error"); !m.empty())
      e.message = m;
    else if (std::string m2 = json::string_field(*v, "message"); !m2.empty())
      e.message = m2;
    e.reason = json::string_field(*v, "reason");
  }
  return e;
}

Result<RobotStatus> parse_status(std::string_view body) {
  auto v = json::parse(body, parse_opts());
  if (!v.ok()) return schema_error("the status answer is not JSON: " + v.error().message);
  if (!v->is_object()) return schema_error("the status answer is not an object", *v);
  const json::Value* ruri = v->get("ruri");
  if (!ruri || !ruri->is_string()) return schema_error("the status answer has no ruri", *v);
  RobotStatus s;
  s.ruri = ruri->as_string();
  s.rrn = json::string_field(*v, "rrn");
  s.name = json::string_field(*v, "name");
  s.rcan_version = json::string_field(*v, "rcan_version");
  if (s.rcan_version.empty()) s.rcan_version = json::string_field(*v, "version");
  s.extensions = strings_of(*v, "extensions");
  s.capabilities = strings_of(*v, "capabilities");
  if (const json::Value* e = v->get("estop_active"); e && e->is_bool())
    s.estop_active = e->as_bool();
  s.mode = json::string_field(*v, "mode");
  if (const json::Value* a = v->get("audit_available"); a && a->is_bool())
    s.audit_available = a->as_bool();
  if (const json::Value* l = v->get("sessions"); l && l->is_array()) {
    for (const auto& e : l->as_array()) {
      if (!e.is_object()) continue;
      SessionInfo si;
      si.session_id = json::string_field(e, "session_id");
      if (si.session_id.empty()) si.session_id = json::string_field(e, "id");
      si.role = json::string_field(e, "role");
      si.principal = json::string_field(e, "principal");
      if (si.principal.empty()) si.principal = json::string_field(e, "user_id");
      si.expires_in_s = int_of(e, "expires_in", -1);
      s.sessions.push_back(std::move(si));
    }
  }
  s.active_sessions = int_of(*v, "active_sessions", static_cast<int64_t>(s.sessions.size()));
  if (const json::Value* r = v->get("robot")) s.robot = *r;
  s.raw = *v;
  return s;
}

json::Value command_message(const Command& c, int64_t now_ms) {
  json::Object payload{{"action", c.action}};
  for (const auto& [k, v] : c.params) payload.set(k, v);
  json::Object m{{"version", "1.0.0"},
                 {"message_id", new_uuid_v4()},
                 {"type", "COMMAND"},
                 {"timestamp_ms", now_ms},
                 {"payload", std::move(payload)}};
  if (!c.priority.empty()) m.set("priority", c.priority);
  if (c.ttl_ms > 0) m.set("ttl_ms", c.ttl_ms);
  if (!c.scope.empty()) m.set("scope", c.scope);
  if (c.confidence) m.set("ai", json::Object{{"confidence", *c.confidence}});
  return json::Value(std::move(m));
}

// ---------------------------------------------------------------------------------------------

Client::Client(ClientOptions options) : opts_(std::move(options)) {}

Result<RawResponse> Client::request(const std::string& method, const std::string& path,
                                    const std::string& body, bool with_token) {
  auto ep = parse_endpoint(opts_.url);
  if (!ep.ok()) return ep.error();
  std::vector<std::pair<std::string, std::string>> h;
  if (with_token && !opts_.token.empty()) h.emplace_back("Authorization", "Bearer " + opts_.token);
  return net::http_exchange(*ep, method, path, body, h, opts_.timeout_ms, opts_.ca_file,
                            opts_.insecure);
}

Result<json::Value> Client::call_json(const std::string& method, const std::string& path,
                                      const std::string& body, bool with_token, int* status) {
  auto r = request(method, path, body, with_token);
  if (!r.ok()) return r.error();
  if (r->status < 200 || r->status > 299)
    return error_from_response(r->status, r->body, r->header("retry-after"));
  if (status) *status = r->status;
  auto v = json::parse(r->body, parse_opts());
  if (!v.ok()) return schema_error("the answer is not JSON: " + v.error().message);
  return std::move(v).value();
}

Result<RobotStatus> Client::status() {
  auto r = request("GET", "/rcan/v1/status", "", true);
  if (!r.ok()) return r.error();
  if (r->status != 200) return error_from_response(r->status, r->body, r->header("retry-after"));
  return parse_status(r->body);
}

Result<Grant> Client::claim(const std::string& role) {
  json::Object body;
  if (!role.empty()) body.set("role", role);
  auto v = call_json("POST", "/rcan/v1/auth/claim", json::dump(json::Value(body)), true);
  if (!v.ok()) return v.error();
  const json::Value* p = v->get("payload");
  if (!p || !p->is_object() || json::string_field(*p, "session_id").empty())
    return schema_error("the claim answer carries no session_id", *v);
  Grant g;
  g.session_id = json::string_field(*p, "session_id");
  g.role = json::string_field(*p, "role");
  g.capabilities = strings_of(*p, "capabilities");
  g.heartbeat_timeout_ms = int_of(*p, "heartbeat_timeout_ms", 0);
  g.expires_in_s = int_of(*p, "expires_in", -1);
  g.raw = *v;
  return g;
}

Result<Reply> Client::release(const std::string& session_id) {
  json::Object body;
  if (!session_id.empty()) body.set("session_id", session_id);
  int status = 200;
  auto v =
      call_json("DELETE", "/rcan/v1/auth/release", json::dump(json::Value(body)), true, &status);
  if (!v.ok()) return v.error();
  return reply_from(status, *v);
}

Result<Reply> Client::handoff(const std::string& session_id, const std::string& target_user_id,
                              const std::string& target_role, const std::string& reason) {
  json::Object body{{"session_id", session_id}, {"target_user_id", target_user_id}};
  if (!target_role.empty()) body.set("target_role", target_role);
  if (!reason.empty()) body.set("reason", reason);
  int status = 200;
  auto v = call_json("POST", "/rcan/v1/handoff", json::dump(json::Value(body)), true, &status);
  if (!v.ok()) return v.error();
  return reply_from(status, *v);
}

Result<Reply> Client::send(const json::Value& message) {
  int status = 200;
  auto v = call_json("POST", "/rcan/v1/command", json::dump(message), true, &status);
  if (!v.ok()) return v.error();
  return reply_from(status, *v);
}

Result<Reply> Client::command(const Command& c) { return send(command_message(c, net::wall_ms())); }

Result<Reply> Client::estop(const std::string& reason) {
  json::Object body;
  if (!reason.empty()) body.set("reason", reason);
  int status = 200;
  auto v = call_json("POST", "/api/stop", json::dump(json::Value(body)), true, &status);
  if (!v.ok()) return v.error();
  return reply_from(status, *v);
}

Result<Reply> Client::resume(const std::string& reason) {
  json::Object payload{{"safety_event", "RESUME"}};
  if (!reason.empty()) payload.set("reason", reason);
  json::Object m{
      {"version", "1.0.0"},   {"message_id", new_uuid_v4()},    {"type", "SAFETY"},
      {"priority", "SAFETY"}, {"timestamp_ms", net::wall_ms()}, {"payload", std::move(payload)}};
  return send(json::Value(std::move(m)));
}

Result<Reply> Client::heartbeat() {
  json::Object m{{"version", "1.0.0"},
                 {"message_id", new_uuid_v4()},
                 {"type", "HEARTBEAT"},
                 {"timestamp_ms", net::wall_ms()},
                 {"payload", json::Object{}}};
  return send(json::Value(std::move(m)));
}

Result<std::vector<PendingAuth>> Client::pending() {
  auto v = call_json("GET", "/rcan/v1/pending", "", true);
  if (!v.ok()) return v.error();
  const json::Value* list = v->is_array() ? &*v : nullptr;
  if (!list)
    for (const char* k : {"pending", "entries", "items"})
      if (const json::Value* l = v->get(k); l && l->is_array()) {
        list = l;
        break;
      }
  if (!list) return schema_error("the pending answer holds no list", *v);
  std::vector<PendingAuth> out;
  for (const auto& e : list->as_array()) {
    if (!e.is_object()) continue;
    // Either the PENDING_AUTH message or its payload.
    const json::Value* p = e.get("payload");
    const json::Value& src = p && p->is_object() ? *p : e;
    PendingAuth pa;
    pa.message_id = json::string_field(src, "message_id");
    if (pa.message_id.empty()) pa.message_id = json::string_field(e, "message_id");
    pa.action_type = json::string_field(src, "action_type");
    pa.description = json::string_field(src, "description");
    pa.principal = json::string_field(src, "principal");
    pa.auth_timeout_ms = int_of(src, "auth_timeout_ms", 0);
    pa.expires_at_ms = int_of(src, "expires_at_ms", 0);
    pa.raw = e;
    out.push_back(std::move(pa));
  }
  return out;
}

Result<Reply> Client::authorize(const std::string& message_id, bool approve,
                                const std::string& reason) {
  json::Object payload{{"message_id", message_id}, {"decision", approve ? "approve" : "deny"}};
  if (!reason.empty()) payload.set("reason", reason);
  json::Object m{{"version", "1.0.0"},
                 {"message_id", new_uuid_v4()},
                 {"type", "AUTHORIZE"},
                 {"timestamp_ms", net::wall_ms()},
                 {"payload", std::move(payload)}};
  int status = 200;
  auto v =
      call_json("POST", "/rcan/v1/authorize", json::dump(json::Value(std::move(m))), true, &status);
  if (!v.ok()) return v.error();
  return reply_from(status, *v);
}

Result<AuditPage> Client::audit_recent(int limit) {
  auto v = call_json("GET", "/api/audit?limit=" + std::to_string(limit), "", true);
  if (!v.ok()) return v.error();
  const json::Value* list = v->is_array() ? &*v : v->get("entries");
  if (!list || !list->is_array()) return schema_error("the audit answer holds no entries", *v);
  AuditPage page;
  page.entries = list->as_array();
  page.last_seq = v->is_object() ? int_of(*v, "last_seq", 0) : 0;
  if (const json::Value* bad = v->is_object() ? v->get("unreadable") : nullptr;
      bad && bad->is_array())
    for (const auto& s : bad->as_array())
      if (s.is_int()) page.unreadable.push_back(s.as_int());
  return page;
}

Result<std::string> Client::audit_export(std::optional<int64_t> from_ms,
                                         std::optional<int64_t> to_ms) {
  std::string q = "/api/v1/audit?format=jsonl";
  if (from_ms) q += "&from=" + std::to_string(*from_ms);
  if (to_ms) q += "&to=" + std::to_string(*to_ms);
  auto r = request("GET", q, "", true);
  if (!r.ok()) return r.error();
  if (r->status != 200) return error_from_response(r->status, r->body, r->header("retry-after"));
  return std::move(r->body);
}

Result<Thought> Client::thought(const std::string& id) {
  auto v = call_json("GET", "/api/thoughts/" + url_encode(id), "", true);
  if (!v.ok()) return v.error();
  if (!v->is_object()) return schema_error("the thought is not an object", *v);
  Thought t;
  t.id = json::string_field(*v, "id");
  if (t.id.empty()) t.id = json::string_field(*v, "thought_id");
  t.timestamp_ms = int_of(*v, "timestamp_ms", 0);
  t.provider = json::string_field(*v, "provider");
  t.model = json::string_field(*v, "model");
  t.layer = json::string_field(*v, "layer");
  t.instruction = json::string_field(*v, "instruction");
  if (const json::Value* c = v->get("confidence"); c && c->is_number())
    t.confidence = c->to_double();
  if (const json::Value* r = v->get("reasoning"); r && r->is_string()) t.reasoning = r->as_string();
  if (const json::Value* a = v->get("action")) t.action = *a;
  t.raw = *v;
  return t;
}

Result<WatermarkVerdict> Client::watermark_verify(const std::string& token,
                                                  const std::string& rrn) {
  std::string q = "/api/v1/watermark/verify?token=" + url_encode(token);
  if (!rrn.empty()) q += "&rrn=" + url_encode(rrn);
  auto v = call_json("GET", q, "", false);
  if (!v.ok()) return v.error();
  WatermarkVerdict w;
  if (const json::Value* b = v->get("valid"); b && b->is_bool()) w.valid = b->as_bool();
  w.rrn = json::string_field(*v, "rrn");
  w.watermark_token = json::string_field(*v, "watermark_token");
  if (const json::Value* a = v->get("audit_entry")) w.audit_entry = *a;
  return w;
}

// ---------------------------------------------------------------------------------------------
// Discovery

Result<DiscoveredRobot> probe(const std::string& host, const DiscoverOptions& options) {
  std::string url = host;
  if (url.find("://") == std::string::npos) {
    // host, host:port, [v6] or [v6]:port; the default RCAN port is 8080.
    bool has_port = false;
    if (!url.empty() && url.front() == '[')
      has_port = url.find("]:") != std::string::npos;
    else
      has_port = std::count(url.begin(), url.end(), ':') == 1;
    if (!has_port)
      url = (url.find(':') != std::string::npos && url.front() != '[' ? "[" + url + "]" : url) +
            ":8080";
    url = "http://" + url;
  }
  auto ep = parse_endpoint(url);
  if (!ep.ok()) return ep.error();
  ClientOptions co;
  co.url = ep->url();
  co.timeout_ms = options.timeout_ms;
  co.ca_file = options.ca_file;
  co.insecure = options.insecure;
  Client c(co);
  auto st = c.status();
  if (!st.ok()) return st.error();
  DiscoveredRobot r;
  r.source = "probe";
  r.name = host;
  r.url = ep->url();
  r.host = ep->host;
  r.port = ep->port;
  r.ruri = st->ruri;
  r.version = st->rcan_version;
  if (const json::Value* d = st->raw.get("discovery"); d && d->is_object())
    r.model = json::string_field(*d, "model");
  r.status_word = st->estop_active ? "estop" : (st->active_sessions > 0 ? "claimed" : "available");
  r.reachable = true;
  r.status = std::move(st).value();
  return r;
}

DiscoverReport discover(const DiscoverOptions& options) {
  DiscoverReport rep;
  std::vector<std::future<Result<DiscoveredRobot>>> probes;
  for (const auto& h : options.hosts)
    probes.push_back(std::async(std::launch::async, [h, &options] { return probe(h, options); }));
  if (options.mdns) {
    auto found = browse_mdns(options.timeout_ms);
    if (!found.ok()) {
      rep.mdns_error = found.error().message;
    } else {
      for (const auto& s : *found) {
        DiscoveredRobot r;
        r.source = "mdns";
        r.name = s.name;
        r.interface = s.interface;
        r.port = s.port;
        r.txt = parse_txt(s.txt);
        auto get = [&](const char* k) {
          auto it = r.txt.find(k);
          return it == r.txt.end() ? std::string() : it->second;
        };
        r.ruri = get("ruri");
        r.model = get("model");
        r.version = get("version");
        r.status_word = get("status");
        bool tls = txt_says_tls(r.txt);
        // A service published by this host may listen on loopback only: try its address,
        // then loopback.
        std::vector<std::string> addrs{s.address};
        if (s.local && s.address != "127.0.0.1") addrs.push_back("127.0.0.1");
        for (const auto& a : addrs) {
          Endpoint ep;
          ep.tls = tls;
          ep.host = a;
          ep.port = s.port;
          r.host = a;
          r.url = ep.url();
          if (!options.probe_mdns_results) break;
          auto p = probe(r.url, options);
          if (p.ok()) {
            r.reachable = true;
            r.status = p->status;
            if (r.status_word.empty()) r.status_word = p->status_word;
            break;
          }
        }
        // The same service seen on several interfaces/protocols: keep one per URL.
        bool dup = std::any_of(rep.robots.begin(), rep.robots.end(), [&](const DiscoveredRobot& o) {
          return o.url == r.url && o.name == r.name;
        });
        if (!dup) rep.robots.push_back(std::move(r));
      }
    }
  }
  for (auto& f : probes) {
    auto r = f.get();
    if (r.ok()) {
      bool dup = std::any_of(rep.robots.begin(), rep.robots.end(), [&](const DiscoveredRobot& o) {
        return o.url == r->url && o.reachable;
      });
      if (!dup) rep.robots.push_back(std::move(r).value());
    }
  }
  return rep;
}

// ---------------------------------------------------------------------------------------------

std::chrono::milliseconds backoff_delay(int attempt, std::mt19937_64& rng) {
  static constexpr int64_t kSteps[] = {1000, 2000, 4000, 8000, 16000, 30000};
  int64_t base =
      kSteps[std::min<size_t>(static_cast<size_t>(std::max(attempt, 0)), std::size(kSteps) - 1)];
  std::uniform_int_distribution<int64_t> jitter(-500, 500);
  return std::chrono::milliseconds(std::max<int64_t>(0, base + jitter(rng)));
}

}  // namespace rcan::client
