#include "rcan/message.h"

#include <array>
#include <cmath>

#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/ruri.h"

namespace rcan {
namespace {

struct TypeName {
  MessageType type;
  std::string_view name;
};
constexpr std::array<TypeName, 28> kTypeNames{{
    {MessageType::kDiscover, "DISCOVER"},
    {MessageType::kStatus, "STATUS"},
    {MessageType::kCommand, "COMMAND"},
    {MessageType::kStream, "STREAM"},
    {MessageType::kEvent, "EVENT"},
    {MessageType::kHandoff, "HANDOFF"},
    {MessageType::kAck, "ACK"},
    {MessageType::kError, "ERROR"},
    {MessageType::kAnnounce, "ANNOUNCE"},
    {MessageType::kGranted, "GRANTED"},
    {MessageType::kDenied, "DENIED"},
    {MessageType::kReleased, "RELEASED"},
    {MessageType::kAvailable, "AVAILABLE"},
    {MessageType::kHeartbeat, "HEARTBEAT"},
    {MessageType::kSafety, "SAFETY"},
    {MessageType::kPendingAuth, "PENDING_AUTH"},
    {MessageType::kAuthorize, "AUTHORIZE"},
    {MessageType::kConsentRequest, "CONSENT_REQUEST"},
    {MessageType::kTransferRequest, "TRANSFER_REQUEST"},
    {MessageType::kTransferAccept, "TRANSFER_ACCEPT"},
    {MessageType::kFleetCommand, "FLEET_COMMAND"},
    {MessageType::kClaim, "CLAIM"},
    {MessageType::kRelease, "RELEASE"},
    {MessageType::kConsentGrant, "CONSENT_GRANT"},
    {MessageType::kConsentDeny, "CONSENT_DENY"},
    {MessageType::kTransferCancel, "TRANSFER_CANCEL"},
    {MessageType::kSwarmAnnounce, "SWARM_ANNOUNCE"},
    {MessageType::kInvoke, "INVOKE"},
}};

Error schema(std::string field, std::string msg) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field));
}

// A required field that is absent: detail.missing_field names it (conformance L1-SCHEMA-001).
Error missing(std::string field, std::string msg) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field),
               "missing_field");
}

// Typed field readers: absent (or null, where allowed) → null (ok); wrong type → error.
class Reader {
 public:
  explicit Reader(const json::Object& o) : o_(o) {}

  const json::Value* get(std::string_view k) const { return o_.find(k); }

  // The member's string, in place: null when absent (or JSON null, with `allow_null`). A token
  // or a signature is then copied once, into the message, not once more on the way.
  Result<const std::string*> str(std::string_view k, size_t max_len,
                                 bool allow_null = false) const {
    const json::Value* v = o_.find(k);
    if (!v || (allow_null && v->is_null())) return static_cast<const std::string*>(nullptr);
    if (!v->is_string()) return schema(std::string(k), std::string(k) + " must be a string");
    if (v->as_string().size() > max_len)
      return schema(std::string(k),
                    std::string(k) + " is longer than " + std::to_string(max_len) + " bytes");
    return &v->as_string();
  }

 private:
  const json::Object& o_;
};

bool major_version_is_one(std::string_view v, bool& parsed) {
  size_t dot = v.find('.');
  std::string_view major = v.substr(0, dot);
  parsed = !major.empty() && major.size() <= 4;
  for (char c : major)
    if (c < '0' || c > '9') parsed = false;
  return parsed && major == "1";
}

bool is_version_1_0(std::string_view v) {
  return v == "1.0" || v == "1.0.0" || v.rfind("1.0.", 0) == 0;
}

Result<std::string> normalise_ruri_field(const std::string& value, std::string_view field) {
  auto r = parse_ruri(value);
  if (!r.ok()) {
    Error e = r.error();
    e.message = std::string(field) + ": " + e.message;
    e.field = std::string(field) + (e.field.empty() ? "" : "." + e.field);
    return e;
  }
  return r->str();
}

Result<std::vector<std::string>> read_scope(const json::Value* v, const CodecLimits& lim) {
  std::vector<std::string> out;
  if (!v || v->is_null()) return out;
  auto add = [&](const std::string& s) -> Status {
    if (s.empty() || s.size() > 64) return schema("scope", "a scope is 1 to 64 characters");
    for (char c : s) {
      bool ok = (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.' ||
                c == '-' || c == ':';
      if (!ok) return schema("scope", "a scope uses a-z, 0-9, '_', '.', '-', ':'");
    }
    out.push_back(s);
    return Status::Ok();
  };
  if (v->is_string()) {
    // A single scope, or space-separated scopes (OAuth style).
    const std::string& s = v->as_string();
    size_t i = 0;
    while (i < s.size()) {
      size_t j = s.find(' ', i);
      if (j == std::string::npos) j = s.size();
      if (j > i) {
        Status st = add(s.substr(i, j - i));
        if (!st.ok()) return st.error();
      }
      i = j + 1;
    }
  } else if (v->is_array()) {
    for (const auto& e : v->as_array()) {
      if (!e.is_string()) return schema("scope", "scope entries must be strings");
      Status st = add(e.as_string());
      if (!st.ok()) return st.error();
    }
  } else {
    return schema("scope", "scope must be a string or an array of strings");
  }
  if (out.size() > lim.max_scopes) return schema("scope", "too many scopes");
  return out;
}

Result<AiBlock> read_ai(const json::Value& v) {
  if (!v.is_object()) return schema("ai", "ai must be an object");
  const auto& o = v.as_object();
  Reader r(o);
  AiBlock ai;
  auto incomplete = [](std::string field) {
    return Error(ErrorCode::kSchemaValidationFailed,
                 field + " is required in an ai block (AUDIT_INCOMPLETE_AI_IDENTITY)", field,
                 "AUDIT_INCOMPLETE_AI_IDENTITY");
  };
  auto provider = r.str("provider", 128);
  if (!provider.ok()) return schema("ai.provider", "ai.provider must be a string");
  if (!*provider || (*provider)->empty()) return incomplete("ai.provider");
  ai.provider = **provider;
  auto model = r.str("model", 256);
  if (!model.ok()) return schema("ai.model", "ai.model must be a string");
  if (!*model || (*model)->empty()) return incomplete("ai.model");
  ai.model = **model;
  for (auto [key, dest] :
       {std::pair{"model_version", &ai.model_version}, std::pair{"layer", &ai.layer},
        std::pair{"thought_id", &ai.thought_id}}) {
    auto s = r.str(key, 128, true);
    if (!s.ok())
      return schema(std::string("ai.") + key, std::string("ai.") + key + " must be a string");
    *dest = *s ? std::optional<std::string>(**s) : std::nullopt;
  }
  if (const json::Value* c = o.find("confidence"); c && !c->is_null()) {
    if (!c->is_number()) return schema("ai.confidence", "ai.confidence must be a number");
    double d = c->to_double();
    if (!(d >= 0.0 && d <= 1.0))
      return schema("ai.confidence", "ai.confidence must be within [0, 1]");
    ai.confidence = d;
  }
  if (const json::Value* l = o.find("inference_latency_ms"); l && !l->is_null()) {
    if (!l->is_number() || l->to_double() < 0)
      return schema("ai.inference_latency_ms",
                    "ai.inference_latency_ms must be a non-negative number");
    ai.inference_latency_ms = l->to_double();
  }
  if (const json::Value* e = o.find("escalated"); e && !e->is_null()) {
    if (!e->is_bool()) return schema("ai.escalated", "ai.escalated must be a boolean");
    ai.escalated = e->as_bool();
  }
  return ai;
}

// `sig` {alg, kid, value} (rcan-py), `sig` {ml_dsa, ed25519, ed25519_pub} (hybrid signed body:
// kid from the top-level pq_kid), or rcan-ts's `signature` {alg, kid, sig} (`member` names it).
Result<SignatureBlock> read_sig(const json::Object& msg, std::string_view member) {
  const json::Value& v = *msg.find(member);
  const std::string m(member);
  if (!v.is_object()) return schema(m, m + " must be an object");
  Reader r(v.as_object());
  SignatureBlock s;
  const bool hybrid = member == "sig" && v.as_object().contains("ml_dsa");
  if (hybrid) {
    s.alg = "hybrid-ed25519-ml-dsa-65";
    if (const json::Value* k = msg.find("pq_kid");
        k && k->is_string() && k->as_string().size() <= 64)
      s.kid = k->as_string();
  }
  const char* value_key = member == "signature" ? "sig" : (hybrid ? "ml_dsa" : "value");
  for (auto [key, dest, max] :
       {std::tuple{"alg", &s.alg, size_t{32}}, std::tuple{"kid", &s.kid, size_t{64}},
        std::tuple{value_key, &s.value, size_t{16384}}}) {
    if (hybrid && dest != &s.value) continue;
    auto f = r.str(key, max);
    if (!f.ok() || !*f || (*f)->empty())
      return schema(m + "." + key, m + "." + key + " must be a non-empty string");
    *dest = **f;
  }
  if (hybrid && s.kid.empty()) return missing("pq_kid", "a hybrid signature needs pq_kid");
  return s;
}

// The member's name as the message spells it: rcan-py's snake_case, or rcan-ts's camelCase
// (senderType, cloudProvider, delegationChain) when the snake_case one is absent.
const char* spelled(const json::Object& o, const char* snake, const char* camel) {
  return o.find(snake) == nullptr && o.find(camel) != nullptr ? camel : snake;
}

// Fields common to both shapes: sender identity, ai, sig, delegation chain.
Status read_common(const json::Object& o, Message& m, const CodecLimits& lim) {
  Reader r(o);
  const char* st_key = spelled(o, "sender_type", "senderType");
  auto st = r.str(st_key, 32, true);
  if (!st.ok()) return st.error();
  if (*st) {
    auto s = sender_type_from_name(**st);
    if (!s)
      return schema(st_key,
                    std::string(st_key) + " must be human, robot, cloud_function or system");
    m.sender_type = *s;
    m.sender_type_explicit = true;
  }
  for (auto [key, dest] :
       {std::pair{spelled(o, "cloud_provider", "cloudProvider"), &m.cloud_provider},
        std::pair{"function_name", &m.function_name},
        std::pair{"function_region", &m.function_region}}) {
    auto f = r.str(key, 128, true);
    if (!f.ok()) return f.error();
    if (*f) *dest = **f;
  }
  if (m.sender_type == SenderType::kCloudFunction) {
    if (m.cloud_provider.empty())
      return schema("cloud_provider", "sender_type cloud_function requires cloud_provider");
    if (m.function_name.empty())
      return schema("function_name", "sender_type cloud_function requires function_name");
  }
  const char* dc_key = spelled(o, "delegation_chain", "delegationChain");
  if (const json::Value* dc = o.find(dc_key); dc && !dc->is_null()) {
    const std::string k = dc_key;
    if (!dc->is_array()) return schema(k, k + " must be an array");
    if (dc->as_array().size() > lim.max_delegation_hops)
      return schema(k, k + " has more than " + std::to_string(lim.max_delegation_hops) + " hops");
    for (const auto& hop : dc->as_array())
      if (!hop.is_object()) return schema(k, "each delegation hop must be an object");
    if (!dc->as_array().empty()) m.delegation_chain = *dc;
  }
  if (m.sender_type == SenderType::kRobot && m.delegation_chain.is_null()) {
    return Error(ErrorCode::kMissingDelegationChain,
                 "sender_type robot requires a delegation_chain", "delegation_chain");
  }
  for (const char* member : {"sig", "signature"}) {
    if (const json::Value* s = o.find(member); s && !s->is_null()) {
      auto sig = read_sig(o, member);
      if (!sig.ok()) return sig.error();
      m.sig = std::move(*sig);
      break;
    }
  }
  return Status::Ok();
}

Status read_ai_blocks(const json::Object& o, Message& m) {
  const json::Value* top = o.find("ai");
  const json::Value* in_payload = m.payload.find("ai");
  if (top && !top->is_null() && in_payload && !in_payload->is_null())
    return schema("ai", "ai is given both at the top level and in the payload");
  const json::Value* ai = (top && !top->is_null()) ? top : in_payload;
  if (ai && !ai->is_null()) {
    auto a = read_ai(*ai);
    if (!a.ok()) return a.error();
    m.ai = std::move(*a);
  }
  return Status::Ok();
}

// The seed's type (or message_type): a name, or a number (0..7) under an explicit 1.0.x
// `version` (null: none given).
Status read_seed_type(const json::Object& o, const std::string* version, Message& m) {
  const json::Value* t = o.find("type");
  const json::Value* mt = o.find("message_type");
  if (t && mt && !(*t == *mt)) return schema("type", "type and message_type disagree");
  const json::Value* tv = t ? t : mt;
  if (!tv) return missing("type", "type is required");
  if (tv->is_string()) {
    auto type = message_type_from_name(tv->as_string());
    if (!type)
      return schema("type", "unknown message type '" + tv->as_string().substr(0, 40) + "'");
    m.type = *type;
  } else if (tv->is_int()) {
    if (!version || !is_version_1_0(*version))
      return schema("type", "a numeric type needs an explicit version 1.0.x; send the type name");
    int64_t n = tv->as_int();
    if (n < 0 || n > 7) return schema("type", "numeric type must be 0..7 (seed table)");
    m.type = static_cast<MessageType>(n);
  } else {
    return schema("type", "type must be a string name");
  }
  return Status::Ok();
}

// The seed's priority, when given: a name, or a number (0..3) under an explicit 1.0.x `version`.
Status read_seed_priority(const json::Object& o, const std::string* version, Message& m) {
  const json::Value* pr = o.find("priority");
  if (!pr || pr->is_null()) return Status::Ok();
  if (pr->is_string()) {
    auto prio = priority_from_name(pr->as_string());
    if (!prio) return schema("priority", "priority must be LOW, NORMAL, HIGH or SAFETY");
    m.priority = *prio;
  } else if (pr->is_int()) {
    if (!version || !is_version_1_0(*version))
      return schema("priority", "a numeric priority needs an explicit version 1.0.x");
    if (pr->as_int() < 0 || pr->as_int() > 3)
      return schema("priority", "numeric priority must be 0..3");
    m.priority = static_cast<Priority>(pr->as_int());
  } else {
    return schema("priority", "priority must be a string name");
  }
  return Status::Ok();
}

Result<Message> decode_seed(const json::Object& o, const CodecLimits& lim) {
  Message m;
  m.shape = WireShape::kSeed;
  Reader r(o);
  // 1. version first (v1.5 processing order): absent → "1.0.0".
  auto ver = r.str("version", 32);
  if (!ver.ok()) return ver.error();
  if (*ver) {
    bool parsed = false;
    bool one = major_version_is_one(**ver, parsed);
    if (!parsed) return schema("version", "version must look like MAJOR.MINOR[.PATCH]");
    if (!one)
      return Error(ErrorCode::kVersionIncompatible,
                   "version " + **ver + " is not compatible with RCAN 1.x", "version");
    m.version = **ver;
  }
  // 2. type (or message_type): a name, or a number under an explicit 1.0.x version.
  const std::string* version = *ver ? &**ver : nullptr;
  if (Status st = read_seed_type(o, version, m); !st.ok()) return st.error();
  // 3. payload: an object, required.
  const json::Value* p = o.find("payload");
  if (!p) return missing("payload", "payload is required");
  if (!p->is_object()) return schema("payload", "payload must be an object");
  m.payload = p->as_object();
  // 4. identity and timing.
  auto id = r.str("message_id", 64);
  if (!id.ok()) return id.error();
  if (!*id) return missing("message_id", "message_id is required");
  if (!is_uuid(**id)) return schema("message_id", "message_id must be a UUID (8-4-4-4-12 hex)");
  m.message_id = **id;
  const json::Value* ts = o.find("timestamp_ms");
  if (!ts) return missing("timestamp_ms", "timestamp_ms is required");
  if (!ts->is_int() || ts->as_int() <= 0 || ts->as_int() > 9999999999999)
    return schema("timestamp_ms", "timestamp_ms must be a positive integer of Unix milliseconds");
  m.timestamp_ms = ts->as_int();
  if (const json::Value* ttl = o.find("ttl_ms"); ttl && !ttl->is_null()) {
    if (!ttl->is_int() || ttl->as_int() < 0 || ttl->as_int() > 2147483647)
      return schema("ttl_ms", "ttl_ms must be an integer in 0..2147483647 (0 = no expiry)");
    m.ttl_ms = ttl->as_int();
  }
  // 5. priority.
  if (Status st = read_seed_priority(o, version, m); !st.ok()) return st.error();
  if (m.type == MessageType::kSafety) m.priority = Priority::kSafety;
  // 6. addressing.
  for (auto [key, dest] :
       {std::pair{"source_ruri", &m.source_ruri}, std::pair{"target_ruri", &m.target_ruri}}) {
    auto f = r.str(key, 512, true);
    if (!f.ok()) return f.error();
    if (*f && !(*f)->empty()) {
      if (std::string_view(key) == "target_ruri" && **f == "broadcast") {
        *dest = "broadcast";
        continue;
      }
      auto n = normalise_ruri_field(**f, key);
      if (!n.ok()) return n.error();
      *dest = *n;
    }
  }
  auto tok = r.str("auth_token", lim.max_token_bytes, true);
  if (!tok.ok()) return tok.error();
  if (*tok) m.auth_token = **tok;
  auto rt = r.str("reply_to", 512, true);
  if (!rt.ok()) return rt.error();
  if (*rt) m.reply_to = **rt;
  auto sc = read_scope(o.find("scope"), lim);
  if (!sc.ok()) return sc.error();
  m.scope = *sc;
  if (Status st = read_common(o, m, lim); !st.ok()) return st.error();
  if (Status st = read_ai_blocks(o, m); !st.ok()) return st.error();
  return m;
}

// rcan-py's msg_id (any short printable id) and timestamp (float Unix seconds).
Status read_rcanpy_id_and_time(const json::Object& o, Message& m) {
  Reader r(o);
  auto id = r.str("msg_id", 128);
  if (!id.ok()) return id.error();
  if (!*id) return missing("msg_id", "msg_id is required");
  // rcan-py uses uuid4 ids but does not require them; any short printable id is accepted.
  if ((*id)->empty() || (*id)->size() > 128)
    return schema("msg_id", "msg_id must be 1 to 128 characters");
  for (char c : **id) {
    if (static_cast<unsigned char>(c) <= 0x20 || static_cast<unsigned char>(c) >= 0x7f)
      return schema("msg_id", "msg_id must be printable ASCII without spaces");
  }
  m.message_id = **id;
  const json::Value* ts = o.find("timestamp");
  if (!ts) return missing("timestamp", "timestamp (Unix seconds) is required");
  if (!ts->is_number()) return schema("timestamp", "timestamp must be a number of Unix seconds");
  double secs = ts->to_double();
  if (!(secs > 0 && secs < 9999999999.0)) return schema("timestamp", "timestamp is out of range");
  m.timestamp_ms = static_cast<int64_t>(std::llround(secs * 1000.0));
  return Status::Ok();
}

// "2026-11-26T23:10:00.123Z" (rcan-ts's Date.toISOString) or with a ±HH:MM offset; fraction
// of 0–9 digits (milliseconds kept). Nothing else.
std::optional<int64_t> parse_iso8601_ms(std::string_view s) {
  auto num = [&](size_t pos, size_t len) -> std::optional<int64_t> {
    if (pos + len > s.size()) return std::nullopt;
    int64_t v = 0;
    for (size_t i = pos; i < pos + len; ++i) {
      if (s[i] < '0' || s[i] > '9') return std::nullopt;
      v = v * 10 + (s[i] - '0');
    }
    return v;
  };
  if (s.size() < 20 || s.size() > 40 || s[4] != '-' || s[7] != '-' || s[10] != 'T' ||
      s[13] != ':' || s[16] != ':')
    return std::nullopt;
  auto y = num(0, 4), mo = num(5, 2), d = num(8, 2), h = num(11, 2), mi = num(14, 2),
       se = num(17, 2);
  if (!y || !mo || !d || !h || !mi || !se || *y < 1970 || *mo < 1 || *mo > 12 || *d < 1 ||
      *d > 31 || *h > 23 || *mi > 59 || *se > 60)
    return std::nullopt;
  size_t pos = 19;
  int64_t frac_ms = 0;
  if (pos < s.size() && s[pos] == '.') {
    size_t start = ++pos;
    while (pos < s.size() && s[pos] >= '0' && s[pos] <= '9') ++pos;
    if (pos == start || pos - start > 9) return std::nullopt;
    for (size_t i = start; i < start + 3; ++i) frac_ms = frac_ms * 10 + (i < pos ? s[i] - '0' : 0);
  }
  int64_t offset_min = 0;
  if (pos < s.size() && s[pos] == 'Z' && pos + 1 == s.size()) {
  } else if (pos + 6 == s.size() && (s[pos] == '+' || s[pos] == '-') && s[pos + 3] == ':') {
    auto oh = num(pos + 1, 2), om = num(pos + 4, 2);
    if (!oh || !om || *oh > 23 || *om > 59) return std::nullopt;
    offset_min = (s[pos] == '-' ? -1 : 1) * (*oh * 60 + *om);
  } else {
    return std::nullopt;
  }
  // Days from the civil date (H. Hinnant's algorithm).
  int64_t yy = *y - (*mo <= 2 ? 1 : 0);
  int64_t era = yy / 400, yoe = yy - era * 400;
  int64_t doy = (153 * (*mo + (*mo > 2 ? -3 : 9)) + 2) / 5 + *d - 1;
  int64_t days = era * 146097 + yoe * 365 + yoe / 4 - yoe / 100 + doy - 719468;
  int64_t secs = days * 86400 + *h * 3600 + *mi * 60 + *se - offset_min * 60;
  return secs * 1000 + frac_ms;
}

// The replay identity of an rcan-ts message (it carries no msg_id): "ts-" + the first 32 hex
// of SHA-256 over the canonical JSON of exactly what rcan-ts's signature covers — {cmd, params
// (absent: {}), rcan, target, timestamp} as received. Fields outside the signature are left out
// so that changing one cannot make a captured message look new.
Result<std::string> rcants_id(const json::Object& o) {
  json::Object id;
  for (const char* key : {"cmd", "rcan", "target", "timestamp"}) {
    const json::Value* v = o.find(key);
    if (!v || !v->is_string()) return schema(key, std::string(key) + " must be a string");
    id.set(key, *v);
  }
  const json::Value* params = o.find("params");
  id.set("params", params && !params->is_null() ? *params : json::Value(json::Object{}));
  return "ts-" + sha256_hex(json::canonical(id)).substr(0, 32);
}

Result<Message> decode_rcanpy(const json::Object& o, const CodecLimits& lim) {
  Message m;
  m.shape = WireShape::kRcanPy;
  m.type = MessageType::kCommand;
  // The SDKs' RCANMessage never writes its type; a sender may add rcan-py's MessageType.INVOKE
  // (11, or "INVOKE") to ask for a skill. Any other `type` is ignored like an unknown field.
  if (const json::Value* t = o.find("type");
      t && ((t->is_int() && t->as_int() == 11) || (t->is_string() && t->as_string() == "INVOKE")))
    m.type = MessageType::kInvoke;
  Reader r(o);
  auto rc = r.str("rcan", 32);
  if (!rc.ok()) return rc.error();
  if (!*rc || (*rc)->empty())
    return missing("rcan", "rcan (protocol version) is required in the rcan-py shape");
  m.version = **rc;
  for (const char* key : {"rcan_version", "rcanVersion"}) {  // rcan-py / rcan-ts spelling
    auto rv = r.str(key, 32, true);
    if (!rv.ok()) return rv.error();
  }
  auto cmd = r.str("cmd", 128);
  if (!cmd.ok()) return cmd.error();
  if (!*cmd || (*cmd)->empty()) return missing("cmd", "cmd is required in the rcan-py shape");
  auto target = r.str("target", 512);
  if (!target.ok()) return target.error();
  if (!*target || (*target)->empty())
    return missing("target", "target is required in the rcan-py shape");
  {
    // rcan-py strips surrounding whitespace and one trailing '/'.
    std::string t = **target;
    size_t b = t.find_first_not_of(" \t\r\n"), e = t.find_last_not_of(" \t\r\n");
    t = b == std::string::npos ? "" : t.substr(b, e - b + 1);
    auto n = normalise_ruri_field(t, "target");
    if (!n.ok()) return n.error();
    m.target_ruri = *n;
  }
  if (const json::Value* ts = o.find("timestamp"); ts && ts->is_string()) {
    // rcan-ts: ISO-8601 timestamp and no msg_id; the replay identity is derived (rcants_id).
    m.shape = WireShape::kRcanTs;
    auto ms = parse_iso8601_ms(ts->as_string());
    if (!ms)
      return schema("timestamp",
                    "timestamp must be an ISO-8601 UTC time (rcan-ts) or Unix seconds (rcan-py)");
    m.timestamp_ms = *ms;
    auto id = rcants_id(o);
    if (!id.ok()) return id.error();
    m.message_id = *id;
  } else {
    auto idt = read_rcanpy_id_and_time(o, m);
    if (!idt.ok()) return idt.error();
  }
  json::Object payload;
  if (const json::Value* params = o.find("params"); params && !params->is_null()) {
    if (!params->is_object()) return schema("params", "params must be an object");
    payload = params->as_object();
  }
  if (const json::Value* a = payload.find("action");
      a && !(a->is_string() && a->as_string() == **cmd))
    return schema("params.action", "params.action disagrees with cmd");
  payload.set("action", **cmd);
  m.payload = std::move(payload);
  if (const json::Value* c = o.find("confidence"); c && !c->is_null()) {
    if (!c->is_number() || !(c->to_double() >= 0.0 && c->to_double() <= 1.0))
      return schema("confidence", "confidence must be a number within [0, 1]");
    m.confidence = c->to_double();
  }
  auto sc = read_scope(o.find("scope"), lim);
  if (!sc.ok()) return sc.error();
  m.scope = *sc;
  auto tok = r.str("auth_token", lim.max_token_bytes, true);
  if (!tok.ok()) return tok.error();
  if (*tok) m.auth_token = **tok;
  if (Status st = read_common(o, m, lim); !st.ok()) return st.error();
  if (Status st = read_ai_blocks(o, m); !st.ok()) return st.error();
  return m;
}

bool looks_rcanpy(const json::Object& o) {
  return o.contains("cmd") || (o.contains("rcan") && !o.contains("payload"));
}

}  // namespace

std::string_view message_type_name(MessageType t) {
  for (const auto& e : kTypeNames)
    if (e.type == t) return e.name;
  return "COMMAND";
}

std::optional<MessageType> message_type_from_name(std::string_view name) {
  for (const auto& e : kTypeNames)
    if (e.name == name) return e.type;
  return std::nullopt;
}

std::string_view priority_name(Priority p) {
  switch (p) {
    case Priority::kLow:
      return "LOW";
    case Priority::kNormal:
      return "NORMAL";
    case Priority::kHigh:
      return "HIGH";
    case Priority::kSafety:
      return "SAFETY";
  }
  return "NORMAL";
}

std::optional<Priority> priority_from_name(std::string_view name) {
  if (name == "LOW") return Priority::kLow;
  if (name == "NORMAL") return Priority::kNormal;
  if (name == "HIGH") return Priority::kHigh;
  if (name == "SAFETY") return Priority::kSafety;
  return std::nullopt;
}

std::string_view sender_type_name(SenderType s) {
  switch (s) {
    case SenderType::kHuman:
      return "human";
    case SenderType::kRobot:
      return "robot";
    case SenderType::kCloudFunction:
      return "cloud_function";
    case SenderType::kSystem:
      return "system";
  }
  return "human";
}

std::optional<SenderType> sender_type_from_name(std::string_view name) {
  if (name == "human") return SenderType::kHuman;
  if (name == "robot") return SenderType::kRobot;
  if (name == "cloud_function") return SenderType::kCloudFunction;
  if (name == "system") return SenderType::kSystem;
  return std::nullopt;
}

json::Value AiBlock::to_json() const {
  json::Object o;
  o.set("provider", provider);
  o.set("model", model);
  if (model_version) o.set("model_version", *model_version);
  if (layer) o.set("layer", *layer);
  if (confidence) o.set("confidence", *confidence);
  if (inference_latency_ms) o.set("inference_latency_ms", *inference_latency_ms);
  if (thought_id) o.set("thought_id", *thought_id);
  o.set("escalated", escalated);
  return o;
}

std::string Message::action() const {
  for (const char* k : {"action_type", "action", "command"}) {
    const json::Value* v = payload.find(k);
    if (v && v->is_string() && !v->as_string().empty()) return v->as_string();
  }
  return {};
}

Status check_shape(const json::Value& value) {
  if (!value.is_object()) return schema("", "a message must be a JSON object");
  const auto& o = value.as_object();
  if (looks_rcanpy(o)) {
    if (!o.contains("cmd")) return missing("cmd", "cmd is required in the rcan-py shape");
    return Status::Ok();
  }
  const json::Value* p = o.find("payload");
  if (!p) return missing("payload", "payload is required");
  if (!p->is_object()) return schema("payload", "payload must be an object");
  return Status::Ok();
}

Result<Message> decode_message(const json::Value& value, const CodecLimits& limits) {
  if (!value.is_object()) return schema("", "a message must be a JSON object");
  const auto& o = value.as_object();
  Result<Message> m = looks_rcanpy(o) ? decode_rcanpy(o, limits) : decode_seed(o, limits);
  if (m.ok()) m->wire = o;
  return m;
}

Result<Message> decode_message(json::Value&& value, const CodecLimits& limits) {
  if (!value.is_object()) return schema("", "a message must be a JSON object");
  auto& o = value.as_object();
  Result<Message> m = looks_rcanpy(o) ? decode_rcanpy(o, limits) : decode_seed(o, limits);
  if (m.ok()) m->wire = std::move(o);
  return m;
}

Result<Message> parse_message(std::string_view body, const CodecLimits& limits) {
  if (body.size() > limits.max_body_bytes) {
    return Error(ErrorCode::kBodyTooLarge, "message of " + std::to_string(body.size()) +
                                               " bytes exceeds the limit of " +
                                               std::to_string(limits.max_body_bytes));
  }
  json::ParseOptions po;
  po.max_bytes = limits.max_body_bytes;
  po.max_depth = 32;
  auto v = json::parse(body, po);
  if (!v.ok()) return v.error();
  return decode_message(*v, limits);
}

json::Value encode_message(const Message& m, const EncodeOptions& opts) {
  json::Object o;
  o.set("version", m.shape == WireShape::kSeed ? m.version : std::string("1.0.0"));
  o.set("message_id", m.message_id);
  if (!m.source_ruri.empty()) o.set("source_ruri", m.source_ruri);
  if (!m.target_ruri.empty()) o.set("target_ruri", m.target_ruri);
  if (opts.include_auth_token && !m.auth_token.empty()) o.set("auth_token", m.auth_token);
  o.set("type", std::string(message_type_name(m.type)));
  o.set("payload", m.payload);
  o.set("timestamp_ms", m.timestamp_ms);
  o.set("ttl_ms", m.ttl_ms);
  o.set("priority", std::string(priority_name(m.priority)));
  if (!m.reply_to.empty()) o.set("reply_to", m.reply_to);
  if (!m.scope.empty()) {
    json::Array s;
    for (const auto& x : m.scope) s.emplace_back(x);
    o.set("scope", std::move(s));
  }
  o.set("sender_type", std::string(sender_type_name(m.sender_type)));
  if (!m.cloud_provider.empty()) o.set("cloud_provider", m.cloud_provider);
  if (!m.function_name.empty()) o.set("function_name", m.function_name);
  if (!m.function_region.empty()) o.set("function_region", m.function_region);
  if (m.ai) {
    // The ai block travels at the top level in the seed shape.
    o.set("ai", m.ai->to_json());
    if (json::Value* p = o.find("payload"); p && p->is_object()) p->as_object().erase("ai");
  }
  if (m.confidence) o.set("confidence", *m.confidence);
  if (!m.delegation_chain.is_null()) o.set("delegation_chain", m.delegation_chain);
  if (m.sig) {
    o.set("sig", json::Object{{"alg", m.sig->alg}, {"kid", m.sig->kid}, {"value", m.sig->value}});
  }
  return o;
}

}  // namespace rcan
