// `rbac`: the role policy grants, per-role rate limits and the seed §6.3 guest limits, which
// a file may also give at the top level as `guest_limits` (docs/CONFIG.md §rbac).
#include <algorithm>
#include <cctype>
#include <regex>

#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

// "10/minute", "10 / min", "30/s", or a bare integer (per minute).
RateSpec parse_rate(const At& a) {
  if (a.is_int()) return RateSpec{static_cast<uint32_t>(a.v->as_int()), 60};
  std::string s = a.str();
  static const std::regex re(R"(^\s*([0-9]{1,7})\s*(/|per)\s*([a-z]+)\s*$)", std::regex::icase);
  std::smatch m;
  if (!std::regex_match(s, m, re))
    fail(a.path, "expected a rate like \"10/minute\", got \"" + printable(s) + "\"",
         "invalid_value");
  uint32_t count = static_cast<uint32_t>(std::stoul(m[1].str()));
  std::string unit = m[3].str();
  std::transform(unit.begin(), unit.end(), unit.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  uint32_t window = 0;
  if (is_one_of(unit, {"s", "sec", "second"}))
    window = 1;
  else if (is_one_of(unit, {"m", "min", "minute"}))
    window = 60;
  else if (is_one_of(unit, {"h", "hr", "hour"}))
    window = 3600;
  else if (is_one_of(unit, {"d", "day"}))
    window = 86400;
  else
    fail(a.path, "unknown rate unit \"" + printable(unit) + "\" (second, minute, hour, day)",
         "invalid_value");
  return RateSpec{count, window};
}

// "15min", "900s", "1h30m", "2 hours", or a bare integer (seconds).
uint32_t parse_duration_s(const At& a) {
  if (a.is_int()) return static_cast<uint32_t>(a.v->as_int());
  std::string s = a.str();
  static const std::regex part(R"(\s*([0-9]{1,9})\s*([a-zA-Z]+))");
  uint64_t total = 0;
  size_t pos = 0;
  bool any = false;
  auto bad = [&] {
    fail(a.path,
         "expected a duration like \"15min\", \"900s\" or \"1h30m\", got \"" + printable(s) + "\"",
         "invalid_value");
  };
  while (pos < s.size()) {
    std::smatch m;
    std::string rest = s.substr(pos);
    if (!std::regex_search(rest, m, part, std::regex_constants::match_continuous)) {
      if (rest.find_first_not_of(" \t") == std::string::npos) break;
      bad();
    }
    std::string unit = m[2].str();
    std::transform(unit.begin(), unit.end(), unit.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    uint64_t mult = 0;
    if (is_one_of(unit, {"s", "sec", "secs", "second", "seconds"}))
      mult = 1;
    else if (is_one_of(unit, {"m", "min", "mins", "minute", "minutes"}))
      mult = 60;
    else if (is_one_of(unit, {"h", "hr", "hrs", "hour", "hours"}))
      mult = 3600;
    else if (is_one_of(unit, {"d", "day", "days"}))
      mult = 86400;
    else
      bad();
    total += std::stoull(m[1].str()) * mult;
    if (total > 31'536'000) fail(a.path, "duration longer than a year", "out_of_range");
    pos += static_cast<size_t>(m.length(0));
    any = true;
  }
  if (!any) bad();
  return static_cast<uint32_t>(total);
}

// The seed §6.3 shape, at rbac.guest_limits or at the top level.
const Table<GuestLimitsConfig>& guest_limit_rows() {
  using G = Rows<GuestLimitsConfig>;
  static const SP rate = Either({Int(0, 1'000'000), Str(64)});
  static const Table<GuestLimitsConfig> rows = {
      G::read("chat_rate", rate,
              [](const At& a, GuestLimitsConfig& g, Ctx&) {
                if (a) g.chat_rate = parse_rate(a);
              }),
      G::read("query_rate", rate,
              [](const At& a, GuestLimitsConfig& g, Ctx&) {
                if (a) g.query_rate = parse_rate(a);
              }),
      G::read("session_duration", Either({Int(0, 31'536'000), Str(64)}),
              [](const At& a, GuestLimitsConfig& g, Ctx&) {
                if (!a) return;
                g.session_duration_s = parse_duration_s(a);
                if (g.session_duration_s == 0)
                  fail(a.path, "must be longer than zero", "out_of_range");
              }),
      G::field("concurrent_sessions", Int(0, 100'000), &GuestLimitsConfig::concurrent_sessions),
      G::field("capabilities", StrList(), &GuestLimitsConfig::capabilities),
      G::field("blocked", StrList(), &GuestLimitsConfig::blocked),
  };
  return rows;
}

Table<RolePolicy> grant_rows() {
  using P = Rows<RolePolicy>;
  return {
      P::field("user_arm", Bool(), &RolePolicy::user_arm),
      P::field("user_record", Bool(), &RolePolicy::user_record),
      P::field("leasee_training", Bool(), &RolePolicy::leasee_training),
      P::field("leasee_diagnostics", Bool(), &RolePolicy::leasee_diagnostics),
      P::field("owner_safety_config", Bool(), &RolePolicy::owner_safety_config),
  };
}

Table<RateLimits> rate_limit_rows() {
  using L = Rows<RateLimits>;
  return {
      L::field("guest", Int(0, 1'000'000), &RateLimits::guest),
      L::field("user", Int(0, 1'000'000), &RateLimits::user),
      L::field("leasee", Int(0, 1'000'000), &RateLimits::leasee),
      L::field("owner", Int(0, 1'000'000), &RateLimits::owner),
      L::field("creator", Int(0, 1'000'000), &RateLimits::creator),
  };
}

}  // namespace

Table<NodeConfig> rbac_blocks() {
  using B = Rows<RbacConfig>;
  Table<RbacConfig> rbac = {
      B::block("grants", grant_rows(), &RbacConfig::policy),
      B::block("rate_limits", rate_limit_rows(), &RbacConfig::rate_limits),
      B::read("guest_limits", object_of(guest_limit_rows()),
              [](const At& gl_rbac, RbacConfig& r, Ctx& x) {
                At gl_top = x.root["guest_limits"];
                if (gl_top && gl_rbac)
                  fail(gl_top.path,
                       "guest limits are given twice (guest_limits and rbac.guest_limits)",
                       "invalid_value");
                if (At gl = gl_top ? gl_top : gl_rbac)
                  walk(guest_limit_rows(), gl, r.guest_limits, x);
              }),
  };
  using R = Rows<NodeConfig>;
  return {
      R::block("rbac", std::move(rbac), &NodeConfig::rbac),
      R::schema_only("guest_limits", object_of(guest_limit_rows())),  // read by rbac.guest_limits
  };
}

}  // namespace rcan::config::internal
