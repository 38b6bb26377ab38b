#include "node/admission/registry_feed.h"

#include <algorithm>
#include <cctype>
#include <ctime>
#include <limits>

#include "rcan/json.h"
#include "rcan/registry.h"

namespace rcan::node {
namespace {

Error bad(const std::string& msg, const std::string& field = {}) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field);
}

// A string member of at most 512 bytes, or null / absent (→ empty). False when it is neither.
bool opt_string(const json::Value& e, const char* key, std::string& out) {
  const json::Value* v = e.get(key);
  if (v == nullptr || v->is_null()) return true;
  if (!v->is_string() || v->as_string().size() > 512) return false;
  out = v->as_string();
  return true;
}

bool digits(std::string_view s, size_t at, size_t n, int& out) {
  if (at + n > s.size()) return false;
  out = 0;
  for (size_t i = at; i < at + n; ++i) {
    if (!std::isdigit(static_cast<unsigned char>(s[i]))) return false;
    out = out * 10 + (s[i] - '0');
  }
  return true;
}

}  // namespace

Result<RegistryKeySet> parse_registry_jwks(std::string_view text) {
  if (text.size() > kMaxRegistryJwksBytes) return bad("the JWKS is too large");
  auto doc = json::parse(text, {.max_depth = 8, .max_bytes = kMaxRegistryJwksBytes});
  if (!doc.ok()) return bad("the JWKS is not JSON: " + doc.error().message);
  const json::Value* keys = doc->is_object() ? doc->get("keys") : nullptr;
  if (keys == nullptr || !keys->is_array()) return bad("the JWKS has no keys array", "keys");
  if (keys->as_array().size() > kMaxRegistryKeys)
    return bad("the JWKS lists too many keys", "keys");
  RegistryKeySet out;
  for (const json::Value& jwk : keys->as_array()) {
    const json::Value* kid = jwk.is_object() ? jwk.get("kid") : nullptr;
    auto key = jwt::VerificationKey::from_jwk(jwk, false);
    if (kid == nullptr || !kid->is_string() || kid->as_string().empty() ||
        kid->as_string().size() > 128 || !key.ok()) {
      ++out.skipped;
      continue;
    }
    key->set_kid(kid->as_string());
    out.keys.push_back(std::move(key).value());
  }
  if (out.keys.empty()) return bad("the JWKS holds no usable signing key", "keys");
  return out;
}

Result<RevocationPage> parse_revocation_page(std::string_view text, int64_t since) {
  auto doc = json::parse(text, {.max_depth = 8, .max_bytes = 1 << 20});
  if (!doc.ok()) return bad("the revocation page is not JSON: " + doc.error().message);
  const json::Value* list = doc->is_object() ? doc->get("revocations") : nullptr;
  if (list == nullptr || !list->is_array())
    return bad("the revocation page has no revocations array", "revocations");
  if (list->as_array().size() > kRevocationPageSize)
    return bad("the revocation page is longer than a page", "revocations");
  const json::Value* next = doc->get("next_since");
  if (next == nullptr || !next->is_int() || next->as_int() < since)
    return bad("next_since must be an integer not below since", "next_since");
  RevocationPage page;
  page.next_since = next->as_int();
  int64_t last = since;
  for (const json::Value& e : list->as_array()) {
    RegistryRevocation r;
    const json::Value* seq = e.is_object() ? e.get("seq") : nullptr;
    if (seq == nullptr || !seq->is_int() || seq->as_int() <= last)
      return bad("revocation seq must be an integer above the previous one", "seq");
    r.seq = last = seq->as_int();
    if (!opt_string(e, "jti", r.jti) || !opt_string(e, "sub", r.sub))
      return bad("jti and sub must be strings of at most 512 bytes or null", "jti");
    if (r.jti.empty() && r.sub.empty()) return bad("a revocation names no jti and no sub", "jti");
    if (const json::Value* x = e.get("exp"); x != nullptr && !x->is_null()) {
      if (!x->is_int()) return bad("exp must be an integer or null", "exp");
      r.exp = x->as_int();
    }
    if (const json::Value* at = e.get("revoked_at"); at != nullptr && at->is_string())
      r.revoked_at_ms = parse_iso8601_ms(at->as_string());
    page.entries.push_back(std::move(r));
  }
  if (page.next_since < last) return bad("next_since is below the page's last seq", "next_since");
  return page;
}

std::optional<int64_t> parse_iso8601_ms(std::string_view s) {
  int y, mo, d, h, mi, se;
  if (s.size() < 19 || !digits(s, 0, 4, y) || s[4] != '-' || !digits(s, 5, 2, mo) || s[7] != '-' ||
      !digits(s, 8, 2, d) || (s[10] != 'T' && s[10] != 't' && s[10] != ' ') ||
      !digits(s, 11, 2, h) || s[13] != ':' || !digits(s, 14, 2, mi) || s[16] != ':' ||
      !digits(s, 17, 2, se))
    return std::nullopt;
  if (mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59 || se > 60) return std::nullopt;
  size_t i = 19;
  int64_t ms = 0;
  if (i < s.size() && s[i] == '.') {
    int64_t scale = 100;
    for (++i; i < s.size() && std::isdigit(static_cast<unsigned char>(s[i])); ++i) {
      ms += (s[i] - '0') * scale;
      scale /= 10;
    }
  }
  int64_t offset_s = 0;
  if (i < s.size() && (s[i] == 'Z' || s[i] == 'z')) {
    ++i;
  } else if (i < s.size() && (s[i] == '+' || s[i] == '-')) {
    int oh, om;
    if (!digits(s, i + 1, 2, oh) || i + 3 >= s.size() || s[i + 3] != ':' ||
        !digits(s, i + 4, 2, om))
      return std::nullopt;
    offset_s = (oh * 3600 + om * 60) * (s[i] == '+' ? 1 : -1);
    i += 6;
  } else {
    return std::nullopt;
  }
  if (i != s.size()) return std::nullopt;
  // Days from the civil date (Howard Hinnant's algorithm), no time zone database involved.
  const int64_t yy = y - (mo <= 2 ? 1 : 0);
  const int64_t era = (yy >= 0 ? yy : yy - 399) / 400;
  const int64_t yoe = yy - era * 400;
  const int64_t doy = (153 * (mo + (mo > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const int64_t doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  const int64_t days = era * 146097 + doe - 719468;
  return (days * 86400 + h * 3600 + mi * 60 + se - offset_s) * 1000 + ms;
}

namespace {

Result<json::Value> answer_json(std::string_view body) {
  auto v = json::parse(body, {.max_depth = 16, .max_bytes = kMaxRegistryAnswerBytes});
  if (!v.ok()) return bad("the registry's answer is not JSON: " + v.error().message);
  if (!v->is_object()) return bad("the registry's answer is not a JSON object");
  return v;
}

}  // namespace

Result<IntrospectionAnswer> parse_introspection_answer(std::string_view body, int64_t now_ms,
                                                       int64_t active_ms, int64_t inactive_ms) {
  auto doc = answer_json(body);
  if (!doc.ok()) return doc.error();
  const json::Value* active = doc->get("active");
  if (active == nullptr || !active->is_bool())
    return bad("the introspection answer is not RFC 7662 JSON (no boolean active)", "active");
  IntrospectionAnswer out{std::nullopt, now_ms + inactive_ms};
  if (!active->as_bool()) return out;
  json::Object claims = doc->as_object();
  claims.erase("active");
  const json::Value* exp = claims.find("exp");
  if (exp == nullptr || !exp->is_int()) return out;  // unusable: treated as inactive
  // exp is seconds; an absurd one must not overflow into the past or the far future.
  const int64_t limit = std::numeric_limits<int64_t>::max() / 1000;
  const int64_t exp_ms = exp->as_int() >= limit    ? std::numeric_limits<int64_t>::max()
                         : exp->as_int() <= -limit ? std::numeric_limits<int64_t>::min()
                                                   : exp->as_int() * 1000;
  out.until_ms = std::min(exp_ms, now_ms + active_ms);
  out.claims = std::move(claims);
  return out;
}

Result<RegistryChallenge> parse_registry_challenge(std::string_view body) {
  auto doc = answer_json(body);
  if (!doc.ok()) return doc.error();
  RegistryChallenge c;
  if (!opt_string(*doc, "challenge_id", c.id) || !opt_string(*doc, "nonce", c.nonce) ||
      c.id.empty() || c.nonce.empty())
    return bad("the registry's challenge needs challenge_id and nonce (strings, 1-512 bytes)");
  return c;
}

Result<RegistrationAnswer> parse_registration_answer(std::string_view body) {
  auto doc = answer_json(body);
  if (!doc.ok()) return doc.error();
  RegistrationAnswer a;
  std::string rrn;
  if (!opt_string(*doc, "rrn", rrn)) return bad("the registration answer's rrn is not a string");
  auto normal = registry::normalize_rrn(rrn);
  if (!normal) return bad("the registration answer holds no RRN", "rrn");
  a.rrn = *normal;
  const json::Value* key = doc->get("api_key");
  if (key != nullptr && key->is_string() && key->as_string().size() <= 4096)
    a.robot_key = key->as_string();
  return a;
}

std::string registry_refusal(int status, std::string_view body) {
  std::string msg;
  auto v = json::parse(body, {.max_depth = 16, .max_bytes = kMaxRegistryAnswerBytes});
  if (v.ok() && v->is_object()) {
    msg = json::string_field(*v, "message");
    if (msg.empty()) msg = json::string_field(*v, "error");
  }
  if (msg.size() > 512) {  // cut at a character boundary: the line goes into logs and records
    size_t n = 512;
    while (n > 0 && (static_cast<unsigned char>(msg[n]) & 0xC0) == 0x80) --n;
    msg.resize(n);
  }
  return "the registry answered " + std::to_string(status) + (msg.empty() ? "" : ": " + msg);
}

}  // namespace rcan::node
