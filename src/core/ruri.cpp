#include "rcan/ruri.h"

#include <charconv>
#include <cstdio>
#include <vector>

#include "base/strings.h"

namespace rcan {
namespace {

constexpr std::string_view kScheme = "rcan://";

bool is_lower_alnum(char c) { return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9'); }
bool is_digit(char c) { return c >= '0' && c <= '9'; }
bool is_lower_hex(char c) { return is_digit(c) || (c >= 'a' && c <= 'f'); }
bool has_upper(std::string_view s) {
  for (char c : s)
    if (c >= 'A' && c <= 'Z') return true;
  return false;
}

Error invalid(std::string field, std::string msg) {
  return Error(ErrorCode::kInvalidRuri, std::move(msg), std::move(field));
}

std::string quoted(std::string_view s) {
  std::string out = "'";
  for (char c : s.substr(0, 80)) out.push_back(static_cast<unsigned char>(c) < 0x20 ? '?' : c);
  out += "'";
  return out;
}

// [a-z0-9]([a-z0-9<extra>]*[a-z0-9])?  with a minimum length.
std::optional<std::string> check_label(std::string_view s, std::string_view name,
                                       std::string_view extra, size_t min_len) {
  if (s.empty()) return "the " + std::string(name) + " segment is empty";
  if (has_upper(s))
    return "the " + std::string(name) + " segment " + quoted(s) +
           " has upper-case letters; RURIs are lower case";
  if (s.size() < min_len)
    return "the " + std::string(name) + " segment " + quoted(s) + " is shorter than " +
           std::to_string(min_len) + " characters";
  if (!is_lower_alnum(s.front()) || !is_lower_alnum(s.back()))
    return "the " + std::string(name) + " segment " + quoted(s) +
           " must start and end with a letter or digit";
  for (char c : s) {
    if (c == '*')
      return "the " + std::string(name) +
             " segment is a wildcard; wildcards are only allowed in a JWT aud";
    if (!is_lower_alnum(c) && extra.find(c) == std::string_view::npos)
      return "the " + std::string(name) + " segment " + quoted(s) + " contains the character " +
             quoted(std::string_view(&c, 1)) + ", allowed are a-z, 0-9 and " + quoted(extra);
  }
  return std::nullopt;
}

bool is_device_id(std::string_view s) {
  auto hex_run = [&](size_t from, size_t n) {
    for (size_t i = from; i < from + n; ++i)
      if (!is_lower_hex(s[i])) return false;
    return true;
  };
  if (s.size() == 8) return hex_run(0, 8);
  if (s.size() == 36) {
    return hex_run(0, 8) && s[8] == '-' && hex_run(9, 4) && s[13] == '-' && hex_run(14, 4) &&
           s[18] == '-' && hex_run(19, 4) && s[23] == '-' && hex_run(24, 12);
  }
  return false;
}

std::optional<std::string> parse_port(std::string_view p, std::optional<uint16_t>& out) {
  if (p.empty() || p.size() > 5) return "the port " + quoted(p) + " must be 1 to 5 digits";
  for (char c : p)
    if (!is_digit(c)) return "the port " + quoted(p) + " must be decimal digits";
  unsigned v = 0;
  std::from_chars(p.data(), p.data() + p.size(), v);
  if (v < 1 || v > 65535) return "the port " + std::string(p) + " is outside 1..65535";
  out = static_cast<uint16_t>(v);
  return std::nullopt;
}

std::optional<std::string> check_capability(const std::vector<std::string_view>& parts, size_t from,
                                            std::string& out) {
  out.clear();
  for (size_t i = from; i < parts.size(); ++i) {
    std::string_view p = parts[i];
    if (has_upper(p))
      return "the capability " + quoted(p) + " has upper-case letters; RURIs are lower case";
    if (i == from && !(p.front() >= 'a' && p.front() <= 'z'))
      return "the capability " + quoted(p) + " must start with a letter";
    for (char c : p)
      if (!is_lower_alnum(c) && c != '-')
        return "the capability " + quoted(p) + " contains " + quoted(std::string_view(&c, 1)) +
               ", allowed are a-z, 0-9 and '-'";
    if (!out.empty()) out.push_back('/');
    out.append(p);
  }
  return std::nullopt;
}

bool parse_ipv4(std::string_view s) {
  int parts = 0;
  size_t i = 0;
  while (i <= s.size()) {
    size_t j = s.find('.', i);
    if (j == std::string_view::npos) j = s.size();
    std::string_view p = s.substr(i, j - i);
    if (p.empty() || p.size() > 3) return false;
    unsigned v = 0;
    for (char c : p) {
      if (!is_digit(c)) return false;
      v = v * 10 + static_cast<unsigned>(c - '0');
    }
    if (v > 255 || (p.size() > 1 && p[0] == '0')) return false;
    ++parts;
    i = j + 1;
    if (j == s.size()) break;
  }
  return parts == 4;
}

Result<Ruri> parse_canonical(const std::vector<std::string_view>& parts) {
  Ruri r;
  if (auto e = check_label(parts[0], "registry", ".-", 2)) return invalid("registry", *e);
  if (auto e = check_label(parts[1], "manufacturer", "-", 2)) return invalid("manufacturer", *e);
  if (auto e = check_label(parts[2], "model", "-", 2)) return invalid("model", *e);
  std::string_view dev = parts[3];
  std::string_view port;
  if (auto colon = dev.find(':'); colon != std::string_view::npos) {
    port = dev.substr(colon + 1);
    dev = dev.substr(0, colon);
    if (auto e = parse_port(port, r.port)) return invalid("port", *e);
  }
  if (dev == "*")
    return invalid("device-id",
                   "the device-id segment is a wildcard; wildcards are only allowed in a JWT aud");
  if (has_upper(dev))
    return invalid("device-id", "the device-id " + quoted(dev) +
                                    " has upper-case letters; RURIs are lower case");
  if (!is_device_id(dev))
    return invalid("device-id",
                   "the device-id " + quoted(dev) + " must be 8 hex digits or a UUID (8-4-4-4-12)");
  if (parts.size() > 4) {
    if (auto e = check_capability(parts, 4, r.capability)) return invalid("capability", *e);
  }
  r.form = Ruri::Form::kCanonical;
  r.registry = std::string(parts[0]);
  r.manufacturer = std::string(parts[1]);
  r.model = std::string(parts[2]);
  r.device_id = std::string(dev);
  return r;
}

std::optional<Ruri> parse_sdk5(const std::vector<std::string_view>& parts) {
  if (parts.size() != 5) return std::nullopt;
  if (check_label(parts[0], "registry", ".-", 2)) return std::nullopt;
  if (check_label(parts[1], "manufacturer", "-", 1)) return std::nullopt;
  if (check_label(parts[2], "model", "-", 1)) return std::nullopt;
  if (check_label(parts[3], "version", ".-_", 1)) return std::nullopt;
  if (check_label(parts[4], "device-id", ".-_", 1)) return std::nullopt;
  Ruri r;
  r.form = Ruri::Form::kSdk5;
  r.registry = std::string(parts[0]);
  r.manufacturer = std::string(parts[1]);
  r.model = std::string(parts[2]);
  r.version = std::string(parts[3]);
  r.device_id = std::string(parts[4]);
  return r;
}

// The expanded form of the v1.1 dot shorthand: rcan://local.rcan/<mfr>/<model>/<id>[/cap],
// whose id is 4..36 alphanumerics (not necessarily hex). Accepting it keeps the shorthand's
// normalised output a fixed point of the parser.
std::optional<Ruri> parse_local_expanded(const std::vector<std::string_view>& parts) {
  if (parts.size() < 4 || parts[0] != "local.rcan") return std::nullopt;
  auto label = [](std::string_view s) {
    if (s.empty() || !is_lower_alnum(s[0])) return false;
    for (char c : s)
      if (!is_lower_alnum(c) && c != '-') return false;
    return true;
  };
  if (!label(parts[1]) || !label(parts[2])) return std::nullopt;
  std::string_view id = parts[3];
  if (id.size() < 4 || id.size() > 36) return std::nullopt;
  for (char c : id)
    if (!is_lower_alnum(c)) return std::nullopt;
  Ruri r;
  if (parts.size() > 4 && check_capability(parts, 4, r.capability)) return std::nullopt;
  r.form = Ruri::Form::kShorthand;
  r.registry = "local.rcan";
  r.manufacturer = std::string(parts[1]);
  r.model = std::string(parts[2]);
  r.device_id = std::string(id);
  return r;
}

std::optional<Ruri> parse_shorthand(const std::vector<std::string_view>& parts) {
  std::string_view head = parts[0];
  size_t d1 = head.find('.');
  if (d1 == std::string_view::npos) return std::nullopt;
  size_t d2 = head.find('.', d1 + 1);
  if (d2 == std::string_view::npos || head.find('.', d2 + 1) != std::string_view::npos)
    return std::nullopt;
  std::string_view mfr = head.substr(0, d1), model = head.substr(d1 + 1, d2 - d1 - 1),
                   id = head.substr(d2 + 1);
  auto label = [](std::string_view s) {
    if (s.empty() || !is_lower_alnum(s[0])) return false;
    for (char c : s)
      if (!is_lower_alnum(c) && c != '-') return false;
    return true;
  };
  if (!label(mfr) || !label(model)) return std::nullopt;
  if (id.size() < 4 || id.size() > 36) return std::nullopt;
  for (char c : id)
    if (!is_lower_alnum(c)) return std::nullopt;
  Ruri r;
  if (parts.size() > 1 && check_capability(parts, 1, r.capability)) return std::nullopt;
  r.form = Ruri::Form::kShorthand;
  r.registry = "local.rcan";
  r.manufacturer = std::string(mfr);
  r.model = std::string(model);
  r.device_id = std::string(id);
  return r;
}

}  // namespace

std::string_view ruri_form_name(Ruri::Form f) {
  switch (f) {
    case Ruri::Form::kCanonical:
      return "canonical";
    case Ruri::Form::kShorthand:
      return "shorthand";
    case Ruri::Form::kSdk5:
      return "sdk5";
    case Ruri::Form::kDiscovered:
      return "discovered";
  }
  return "canonical";
}

std::string Ruri::base() const {
  if (form == Form::kDiscovered) return str();
  std::string s = "rcan://" + registry + "/" + manufacturer + "/" + model + "/";
  if (form == Form::kSdk5) s += version + "/";
  s += device_id;
  return s;
}

std::string sdk_form(const Ruri& ruri, std::string_view version) {
  if (ruri.form == Ruri::Form::kDiscovered) return {};
  if (ruri.form == Ruri::Form::kSdk5) return ruri.base();
  return "rcan://" + ruri.registry + "/" + ruri.manufacturer + "/" + ruri.model + "/" +
         std::string(version) + "/" + ruri.device_id;
}

std::string Ruri::str() const {
  if (form == Form::kDiscovered) {
    return "rcan://local.rcan/discovered/" + device_id + ":" + std::to_string(port.value_or(8080));
  }
  std::string s = base();
  if (port) s += ":" + std::to_string(*port);
  if (!capability.empty()) s += "/" + capability;
  return s;
}

namespace {

Result<Ruri> parse_ruri_text(std::string_view text) {
  if (text.size() > 512) return invalid("ruri", "the RURI is longer than 512 characters");
  for (char c : text) {
    if (static_cast<unsigned char>(c) <= 0x20 || static_cast<unsigned char>(c) >= 0x7f)
      return invalid("ruri", "the RURI contains whitespace, a control or a non-ASCII character");
  }
  if (text.substr(0, kScheme.size()) != kScheme) {
    if (text.size() >= kScheme.size() && has_upper(text.substr(0, 4)))
      return invalid("scheme", "the scheme must be lower-case 'rcan://'");
    return invalid("scheme", "a RURI starts with 'rcan://'");
  }
  std::string_view rest = text.substr(kScheme.size());
  if (rest.find_first_of("?#") != std::string_view::npos)
    return invalid("ruri", "a RURI has no query or fragment");
  if (rest.empty()) return invalid("registry", "missing registry segment");
  if (rest.size() > 1 && rest.back() == '/') rest.remove_suffix(1);  // one trailing slash
  std::vector<std::string_view> parts;
  size_t i = 0;
  while (true) {
    size_t j = rest.find('/', i);
    std::string_view p =
        rest.substr(i, j == std::string_view::npos ? std::string_view::npos : j - i);
    if (p.empty()) return invalid("ruri", "empty segment (two consecutive '/' or a trailing '//')");
    parts.push_back(p);
    if (j == std::string_view::npos) break;
    i = j + 1;
  }
  // The mDNS-discovered form.
  if (parts.size() == 3 && parts[0] == "local.rcan" && parts[1] == "discovered") {
    std::string_view hp = parts[2];
    size_t colon = hp.rfind(':');
    if (colon == std::string_view::npos)
      return invalid("port", "a discovered RURI needs <ip>:<port>");
    if (!parse_ipv4(hp.substr(0, colon)))
      return invalid("device-id", "a discovered RURI needs a dotted IPv4 address, got " +
                                      quoted(hp.substr(0, colon)));
    Ruri r;
    r.form = Ruri::Form::kDiscovered;
    r.registry = "local.rcan";
    r.manufacturer = "discovered";
    r.device_id = std::string(hp.substr(0, colon));
    if (auto e = parse_port(hp.substr(colon + 1), r.port)) return invalid("port", *e);
    return r;
  }
  if (parts.size() >= 4) {
    auto canon = parse_canonical(parts);
    if (canon.ok()) return canon;
    if (auto sdk = parse_sdk5(parts)) return *sdk;
    if (auto ex = parse_local_expanded(parts)) return *ex;
    if (auto sh = parse_shorthand(parts)) return *sh;
    return canon;
  }
  if (auto sh = parse_shorthand(parts)) return *sh;
  // Too few segments: name the first missing one, after checking the ones present.
  static const char* kNames[] = {"registry", "manufacturer", "model", "device-id"};
  if (auto e = check_label(parts[0], "registry", ".-", 2)) return invalid("registry", *e);
  if (parts.size() > 1)
    if (auto e = check_label(parts[1], "manufacturer", "-", 2)) return invalid("manufacturer", *e);
  if (parts.size() > 2)
    if (auto e = check_label(parts[2], "model", "-", 2)) return invalid("model", *e);
  std::string missing = kNames[parts.size()];
  std::string msg = "missing " + missing + " segment";
  if (parts.size() < 3) msg = "missing " + missing + " and later segments";
  return invalid(missing, msg);
}

}  // namespace

Result<Ruri> parse_ruri(std::string_view text) {
  auto r = parse_ruri_text(text);
  // The normalised form (a shorthand gains "local.rcan/…") must itself be a RURI, so the limit
  // applies to it too (found by ruri_fuzz).
  if (r.ok() && r->str().size() > 512)
    return invalid("ruri", "the RURI is longer than 512 characters once normalised");
  return r;
}

bool addresses_robot(const Ruri& target, const Ruri& self, std::string* why) {
  auto differs = [&](const char* segment, const std::string& got, const std::string& own) {
    if (why) *why = std::string(segment) + " '" + got + "' is not this robot's ('" + own + "')";
    return false;
  };
  if (target.form == Ruri::Form::kDiscovered) {
    if (why) *why = "a discovered RURI names an address, not a robot";
    return false;
  }
  if (target.registry != self.registry && target.registry != "local.rcan")
    return differs("registry", target.registry, self.registry);
  if (target.manufacturer != self.manufacturer)
    return differs("manufacturer", target.manufacturer, self.manufacturer);
  if (target.model != self.model) return differs("model", target.model, self.model);
  if (target.device_id != self.device_id)
    return differs("device-id", target.device_id, self.device_id);
  return true;
}

bool aud_matches(std::string_view pattern, const Ruri& robot) {
  if (pattern.substr(0, kScheme.size()) != kScheme) return false;
  std::string_view rest = pattern.substr(kScheme.size());
  if (!rest.empty() && rest.back() == '/') rest.remove_suffix(1);
  std::vector<std::string_view> parts;
  size_t i = 0;
  while (i <= rest.size()) {
    size_t j = rest.find('/', i);
    if (j == std::string_view::npos) j = rest.size();
    parts.push_back(rest.substr(i, j - i));
    i = j + 1;
  }
  std::vector<std::string> target{robot.registry, robot.manufacturer, robot.model};
  if (robot.form == Ruri::Form::kSdk5) target.push_back(robot.version);
  target.push_back(robot.device_id);
  if (robot.form == Ruri::Form::kDiscovered) return pattern == robot.str();
  if (parts.size() < target.size()) return false;
  for (size_t k = 0; k < target.size(); ++k) {
    std::string_view p = parts[k];
    if (k == target.size() - 1) {
      if (auto colon = p.find(':'); colon != std::string_view::npos) p = p.substr(0, colon);
    }
    if (p.empty()) return false;
    if (p != "*" && p != target[k]) return false;
  }
  if (parts.size() == target.size()) return true;
  // Pattern names a capability: it must match the robot's (with '*' per segment).
  std::string cap;
  for (size_t k = target.size(); k < parts.size(); ++k) {
    if (!cap.empty()) cap.push_back('/');
    cap.append(parts[k]);
  }
  if (cap == "*") return true;
  return cap == robot.capability;
}

namespace {

// "RRN-" + digits, or "RRN-<prefix>-" + digits.
std::string rrn_text(std::string_view prefix, std::string_view digits) {
  std::string out = "RRN-";
  if (!prefix.empty()) out.append(prefix).push_back('-');
  return out.append(digits);
}

}  // namespace

std::string Rrn::str() const { return rrn_text(prefix, digits); }

std::string format_rrn(int64_t n, std::string_view prefix) {
  char digits[32];
  std::snprintf(digits, sizeof digits, "%012lld", static_cast<long long>(n));
  return rrn_text(ascii_upper(prefix), digits);
}

Result<Rrn> parse_rrn(std::string_view text) {
  auto bad = [&](std::string msg) {
    return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), "rrn");
  };
  if (text.substr(0, 4) != "RRN-") return bad("an RRN starts with 'RRN-'");
  std::string_view rest = text.substr(4);
  Rrn r;
  if (auto dash = rest.find('-'); dash != std::string_view::npos) {
    std::string_view pfx = rest.substr(0, dash);
    if (pfx.size() < 2 || pfx.size() > 8) return bad("an RRN prefix has 2 to 8 characters");
    for (char c : pfx)
      if (!((c >= 'A' && c <= 'Z') || is_digit(c)))
        return bad("an RRN prefix is upper-case letters and digits");
    r.prefix = std::string(pfx);
    rest = rest.substr(dash + 1);
  }
  if (rest.size() < 8 || rest.size() > 16) return bad("an RRN number has 8 to 16 digits");
  for (char c : rest)
    if (!is_digit(c)) return bad("an RRN number is decimal digits");
  r.digits = std::string(rest);
  if (r.digits.size() < 12) r.digits.insert(0, 12 - r.digits.size(), '0');
  return r;
}

}  // namespace rcan
