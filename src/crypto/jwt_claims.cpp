// RCAN claim policy (steps 4–9 of the verification order in include/rcan/crypto/jwt.h): the
// registered claims' types and times, the audience against the robot's RURI (and its fleet
// audiences), §8.5 sender identity, the role (named or rcan-py numeric), scopes against the
// scope's minimum role (PROFILE.md §5), and fleet membership.
//
// Contract: check_claims() looks only at the claims object and the options, never at the
// signature; each refusal is kAuthInvalid naming the claim and a reason, except a missing scope
// or a role too low for it (kInsufficientPrivileges).
#include <algorithm>
#include <cmath>

#include "crypto/jwt_internal.h"
#include "rcan/crypto/jwt.h"
#include "rcan/roles.h"
#include "rcan/ruri.h"

namespace rcan::jwt {

using detail::auth_invalid;

int role_level(std::string_view r) {
  auto role = rcan::role_from_name(r);
  return role ? rcan::role_level(*role) : 0;
}

std::string_view role_name(int level) {
  if (level < 1 || level > 5) return "";
  return rcan::role_claim_name(static_cast<rcan::Role>(level));
}

int role_level_from_rcan_role(const json::Value& v) {
  if (!v.is_int() && !v.is_double()) return 0;
  double d = v.is_int() ? static_cast<double>(v.as_int()) : v.as_double();
  auto role = rcan::role_from_rcan_level(d);
  return role ? rcan::role_level(*role) : 0;
}

int scope_min_level(std::string_view s) {
  auto role = rcan::scope_min_role(s);
  return role ? rcan::role_level(*role) : rcan::role_level(rcan::Role::kUser);
}

namespace {

// NumericDate (RFC 7519 §2): integer or finite float seconds; floats are floored.
Result<std::optional<int64_t>> numeric_date(const json::Object& c, const char* name) {
  const json::Value* v = c.find(name);
  if (!v) return std::optional<int64_t>{};
  if (v->is_int()) return std::optional<int64_t>{v->as_int()};
  if (v->is_double()) {
    double d = v->as_double();
    if (std::isfinite(d) && std::fabs(d) < 1e15)
      return std::optional<int64_t>{static_cast<int64_t>(std::floor(d))};
  }
  return auth_invalid(std::string(name) + " is not a valid NumericDate", name, "malformed");
}

// Appends scopes from a claim that is an array of strings or a space-separated string.
Status collect_scopes(const json::Object& c, const char* name, std::vector<std::string>& out) {
  const json::Value* v = c.find(name);
  if (!v) return Status::Ok();
  auto add = [&](std::string_view s) {
    if (std::find(out.begin(), out.end(), s) == out.end()) out.emplace_back(s);
  };
  if (v->is_string()) {
    std::string_view s = v->as_string();
    size_t i = 0;
    while (i < s.size()) {
      size_t sp = s.find(' ', i);
      std::string_view tok =
          s.substr(i, sp == std::string_view::npos ? std::string_view::npos : sp - i);
      if (!tok.empty()) add(tok);
      if (sp == std::string_view::npos) break;
      i = sp + 1;
    }
    return Status::Ok();
  }
  if (v->is_array()) {
    for (const auto& e : v->as_array()) {
      if (!e.is_string() || e.as_string().empty())
        return auth_invalid(std::string(name) + " must contain only non-empty strings", name,
                            "malformed");
      add(e.as_string());
    }
    return Status::Ok();
  }
  return auth_invalid(std::string(name) + " must be an array or a space-separated string", name,
                      "malformed");
}

Result<std::string> optional_string(const json::Object& c, const char* name) {
  const json::Value* v = c.find(name);
  if (!v) return std::string();
  if (!v->is_string())
    return auth_invalid(std::string(name) + " must be a string", name, "malformed");
  return v->as_string();
}

// Each step below reads its claims from `c` into `out` and refuses what the policy refuses, in
// the order check_claims() runs them (the first refusal is the one reported).

// iss, sub (required), jti: strings when present.
Status read_identity(const json::Object& c, Claims& out) {
  auto iss = optional_string(c, "iss");
  if (!iss.ok()) return iss.error();
  out.iss = *iss;
  auto sub = optional_string(c, "sub");
  if (!sub.ok()) return sub.error();
  if (sub->empty()) return auth_invalid("sub is missing", "sub", "missing_claim");
  out.sub = *sub;
  auto jti = optional_string(c, "jti");
  if (!jti.ok()) return jti.error();
  out.jti = *jti;
  return Status::Ok();
}

// exp (required), nbf, iat: NumericDates, checked against `now` with the leeway.
Status check_times(const json::Object& c, const VerifyOptions& opts, int64_t now, Claims& out) {
  auto exp = numeric_date(c, "exp");
  if (!exp.ok()) return exp.error();
  auto nbf = numeric_date(c, "nbf");
  if (!nbf.ok()) return nbf.error();
  auto iat = numeric_date(c, "iat");
  if (!iat.ok()) return iat.error();
  out.exp = *exp;
  out.nbf = *nbf;
  out.iat = *iat;
  const int64_t leeway = std::max<int64_t>(0, opts.leeway_s);
  if (!out.exp) return auth_invalid("exp is missing", "exp", "missing_claim");
  if (now >= *out.exp + leeway) return auth_invalid("token expired", "exp", "expired");
  if (out.nbf && now + leeway < *out.nbf)
    return auth_invalid("token not yet valid (nbf)", "nbf", "not_yet_valid");
  if (opts.require_iat && !out.iat) return auth_invalid("iat is missing", "iat", "missing_claim");
  if (out.iat && now + leeway < *out.iat)
    return auth_invalid("token issued in the future (iat)", "iat", "iat_in_future");
  return Status::Ok();
}

// aud (string or non-empty array of strings) must match the robot's RURI, or — for a token with
// a `fleet` claim — equal one of this device's fleet audiences.
Status check_audience(const json::Object& c, const VerifyOptions& opts, Claims& out) {
  if (const json::Value* aud = c.find("aud")) {
    if (aud->is_string()) {
      out.aud.push_back(aud->as_string());
    } else if (aud->is_array() && !aud->as_array().empty()) {
      for (const auto& a : aud->as_array()) {
        if (!a.is_string())
          return auth_invalid("aud must contain only strings", "aud", "malformed");
        out.aud.push_back(a.as_string());
      }
    } else {
      return auth_invalid("aud must be a string or a non-empty array of strings", "aud",
                          "malformed");
    }
  }
  if (opts.skip_audience) return Status::Ok();
  if (out.aud.empty()) return auth_invalid("aud is missing", "aud", "missing_claim");
  if (opts.audience.empty())
    return auth_invalid("this verifier has no audience (robot RURI) configured", "aud",
                        "aud_mismatch");
  bool fleet_token = c.find("fleet") != nullptr;
  bool match = std::any_of(out.aud.begin(), out.aud.end(), [&](const std::string& a) {
    if (fleet_token && std::find(opts.fleet_audiences.begin(), opts.fleet_audiences.end(), a) !=
                           opts.fleet_audiences.end())
      return true;
    return aud_matches(a, opts.audience);
  });
  if (!match)
    return auth_invalid("aud does not match this robot (" + opts.audience + ")", "aud",
                        "aud_mismatch");
  return Status::Ok();
}

// §8.5 sender identity: sender_type one of human/robot/cloud_function/system, and
// cloud_function only with a cloud_provider.
Status check_sender(const json::Object& c, Claims& out) {
  auto st = optional_string(c, "sender_type");
  if (!st.ok()) return st.error();
  out.sender_type = *st;
  auto cp = optional_string(c, "cloud_provider");
  if (!cp.ok()) return cp.error();
  out.cloud_provider = *cp;
  auto fn = optional_string(c, "function_name");
  if (!fn.ok()) return fn.error();
  out.function_name = *fn;
  if (c.find("sender_type")) {
    const std::string& s = out.sender_type;
    if (s != "human" && s != "robot" && s != "cloud_function" && s != "system")
      return auth_invalid("unknown sender_type \"" + s + "\"", "sender_type", "bad_sender_type");
    if (s == "cloud_function" && out.cloud_provider.empty())
      return auth_invalid("sender_type cloud_function without cloud_provider (RCAN §8.5)",
                          "cloud_provider", "missing_cloud_provider");
  }
  return Status::Ok();
}

// role (name) and rcan_role (rcan-py level) must be known and agree; neither → GUEST unless a
// role is required.
Status check_role(const json::Object& c, const VerifyOptions& opts, Claims& out) {
  int level_named = 0, level_numeric = 0;
  if (const json::Value* r = c.find("role")) {
    if (!r->is_string()) return auth_invalid("role must be a string", "role", "bad_role");
    level_named = role_level(r->as_string());
    if (level_named == 0)
      return auth_invalid("unknown role \"" + r->as_string() + "\"", "role", "bad_role");
  }
  if (const json::Value* r = c.find("rcan_role")) {
    level_numeric = role_level_from_rcan_role(*r);
    if (level_numeric == 0)
      return auth_invalid("rcan_role must be 1, 2, 2.5, 3 or 5", "rcan_role", "bad_role");
  }
  if (level_named && level_numeric && level_named != level_numeric)
    return auth_invalid("role and rcan_role disagree", "role", "bad_role");
  out.role_level = level_named ? level_named : level_numeric;
  if (out.role_level == 0) {
    if (opts.require_role) return auth_invalid("token carries no role", "role", "missing_claim");
    out.role_level = 1;
  }
  out.role = std::string(role_name(out.role_level));
  return Status::Ok();
}

// The union of scope, scopes and rcan_scopes; the required scope, when set, must be there and
// the role must reach its minimum.
Status check_scopes(const json::Object& c, const VerifyOptions& opts, Claims& out) {
  for (const char* name : {"scope", "scopes", "rcan_scopes"}) {
    Status s = collect_scopes(c, name, out.scopes);
    if (!s.ok()) return s.error();
  }
  if (opts.required_scope.empty()) return Status::Ok();
  if (!out.has_scope(opts.required_scope))
    return Error(ErrorCode::kInsufficientPrivileges, "token lacks scope " + opts.required_scope,
                 "scope");
  if (out.role_level < scope_min_level(opts.required_scope))
    return Error(ErrorCode::kInsufficientPrivileges,
                 "role " + out.role + " may not use scope " + opts.required_scope, "scope");
  return Status::Ok();
}

// fleet, when present: an array of strings naming one of this device's identifiers.
Status check_fleet(const json::Object& c, const VerifyOptions& opts, Claims& out) {
  const json::Value* f = c.find("fleet");
  if (!f) return Status::Ok();
  if (!f->is_array())
    return auth_invalid("fleet must be an array of strings", "fleet", "malformed");
  std::vector<std::string> fleet;
  for (const auto& e : f->as_array()) {
    if (!e.is_string())
      return auth_invalid("fleet must be an array of strings", "fleet", "malformed");
    fleet.push_back(e.as_string());
  }
  bool member = std::any_of(fleet.begin(), fleet.end(), [&](const std::string& id) {
    return std::find(opts.fleet_ids.begin(), opts.fleet_ids.end(), id) != opts.fleet_ids.end();
  });
  if (!member && !opts.skip_fleet)
    return auth_invalid("this device is not in the token's fleet", "fleet", "fleet_mismatch");
  out.fleet = std::move(fleet);
  return Status::Ok();
}

}  // namespace

bool aud_matches(std::string_view pattern, std::string_view ruri) {
  auto robot = rcan::parse_ruri(ruri);
  if (!robot.ok()) return false;
  return rcan::aud_matches(pattern, *robot);
}

bool Claims::has_scope(std::string_view s) const {
  return std::find(scopes.begin(), scopes.end(), s) != scopes.end();
}

Result<Claims> check_claims(json::Object c, const VerifyOptions& opts, int64_t now) {
  Claims out;
  Status s = read_identity(c, out);
  if (s.ok()) s = check_times(c, opts, now, out);
  if (s.ok()) s = check_audience(c, opts, out);
  if (s.ok()) s = check_sender(c, out);
  if (s.ok()) s = check_role(c, opts, out);
  if (s.ok()) s = check_scopes(c, opts, out);
  if (s.ok()) s = check_fleet(c, opts, out);
  if (!s.ok()) return s.error();
  out.raw = std::move(c);
  return out;
}

}  // namespace rcan::jwt
