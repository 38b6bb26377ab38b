// Who the robot is and what it offers: `rcan_version`, `ruri` (or metadata.ruri), `rrn`,
// `registry`, `robot` (or the OpenCastor `metadata` and `physics` keys), `capabilities` and
// `rcan_protocol` (docs/CONFIG.md §Identity and protocol, §Robot).
#include <algorithm>
#include <cctype>
#include <regex>

#include "config/blocks/blocks.h"
#include "runtime/http_client.h"

namespace rcan::config::internal {
namespace {

using R = Rows<NodeConfig>;

bool is_hex_id(std::string_view s) {
  if (s.size() == 8) {
    for (char c : s)
      if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
    return true;
  }
  if (s.size() == 36) {
    for (size_t i = 0; i < s.size(); ++i) {
      char c = s[i];
      if (i == 8 || i == 13 || i == 18 || i == 23) {
        if (c != '-') return false;
      } else if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) {
        return false;
      }
    }
    return true;
  }
  return false;
}

bool version_ok(std::string_view v) {
  // ^\d+\.\d+(\.\d+(-[a-zA-Z0-9.]+)?)?$
  static const std::regex re(R"(^[0-9]{1,6}\.[0-9]{1,6}(\.[0-9]{1,6}(-[a-zA-Z0-9.]{1,32})?)?$)");
  return std::regex_match(v.begin(), v.end(), re);
}

// Protocol capabilities derived from the robot type when none are configured.
std::vector<std::string> derived_capabilities(const std::string& type) {
  std::vector<std::string> caps{"status", "chat"};
  auto has = [&](std::string_view w) { return type.find(w) != std::string::npos; };
  bool arm = has("arm") || has("manipulator");
  bool mobile = has("mobile") || has("quadruped") || has("differential") || has("drive") ||
                has("rover") || has("ackermann") || has("holonomic") || has("mecanum") ||
                has("omni") || has("wheel");
  if (mobile) {
    caps.emplace_back("teleop");
    caps.emplace_back("nav");
  }
  if (arm) caps.emplace_back("arm");
  return caps;
}

// `ruri`, or metadata.ruri: {device_id} substituted, parsed, normalised.
void read_ruri(const At& ruri_at, NodeConfig& c, Ctx& x) {
  At meta_ruri = x.root["metadata"]["ruri"];
  if (ruri_at && meta_ruri)
    fail(meta_ruri.path, "ruri is given twice (ruri and metadata.ruri); give one", "invalid_value");
  At id_at = ruri_at ? ruri_at : meta_ruri;
  if (!id_at)
    fail("ruri", "required key is missing (ruri, or metadata.ruri in the OpenCastor style)",
         "missing_key");
  std::string ruri_text = id_at.str();
  if (size_t p = ruri_text.find("{device_id}"); p != std::string::npos) {
    if (x.opts.device_id.empty())
      fail(id_at.path,
           "contains the {device_id} placeholder; replace it with the robot's 8-hex-digit id "
           "or UUID",
           "invalid_value");
    if (!is_hex_id(x.opts.device_id))
      fail(id_at.path,
           "the device id substituted for {device_id} must be 8 lower-case hex "
           "digits or a lower-case UUID",
           "invalid_value");
    ruri_text.replace(p, std::string_view("{device_id}").size(), x.opts.device_id);
  }
  Result<Ruri> parsed = parse_ruri(ruri_text);
  if (!parsed.ok())
    fail(id_at.path,
         "invalid RURI \"" + printable(ruri_text, 128) + "\": " + parsed.error().message +
             (parsed.error().field.empty() ? "" : " (segment " + parsed.error().field + ")"),
         "invalid_value");
  if (parsed->form == Ruri::Form::kDiscovered)
    fail(id_at.path, "a robot's own RURI cannot be a discovered/<ip> address", "invalid_value");
  if (!parsed->capability.empty() || parsed->port)
    fail(id_at.path, "the robot's RURI must not carry a port or capability", "invalid_value");
  c.ruri_parts = std::move(parsed).value();
  c.ruri = c.ruri_parts.str();
  // The normalised form must itself be canonical (parse_ruri's shorthand reading is laxer
  // than the canonical grammar, e.g. about the device id).
  if (Result<Ruri> again = parse_ruri(c.ruri); !again.ok() || again->str() != c.ruri)
    fail(id_at.path,
         "invalid RURI \"" + printable(ruri_text, 128) + "\": its canonical form " + c.ruri +
             (again.ok() ? std::string(" does not re-parse to itself")
                         : " is invalid: " + again.error().message),
         "invalid_value");
}

// The protocol capabilities: the `capabilities` list, rcan_protocol.capabilities, or derived
// from robot.type; the mapping form of `capabilities` is the hardware capabilities.
void read_capabilities(const At& caps, NodeConfig& c, Ctx& x) {
  At proto_caps = x.root["rcan_protocol"]["capabilities"];
  static const std::regex cap_re(R"(^[a-z][a-z0-9_-]*$)");
  auto check_caps = [&](const At& list) {
    std::vector<std::string> out;
    for (size_t i = 0; i < list.size(); ++i) {
      std::string s = list[i].str();
      if (!std::regex_match(s, cap_re))
        fail(list[i].path, "invalid capability name \"" + printable(s) + "\"", "invalid_value");
      if (std::find(out.begin(), out.end(), s) == out.end()) out.push_back(s);
    }
    return out;
  };
  if (caps.is_array() && proto_caps)
    fail(proto_caps.path,
         "capabilities are given twice (capabilities and rcan_protocol.capabilities)",
         "invalid_value");
  if (caps.is_array()) {
    c.capabilities = check_caps(caps);
  } else if (proto_caps) {
    c.capabilities = check_caps(proto_caps);
  } else {
    c.capabilities = derived_capabilities(c.robot.type);
  }
}

// The mapping form of `capabilities` (the profile style).
const Table<HardwareCapabilities>& hardware_capability_rows() {
  using H = Rows<HardwareCapabilities>;
  static const Table<HardwareCapabilities> rows = {
      H::field("motion", StrList(), &HardwareCapabilities::motion),
      H::field("sensing", StrList(), &HardwareCapabilities::sensing),
      H::field("io", StrList(), &HardwareCapabilities::io),
      H::field("safety", StrList(), &HardwareCapabilities::safety),
  };
  return rows;
}

// A `robot` key that OpenCastor files give as metadata.<meta_key> (both, different: error).
Row<RobotInfo> robot_or_metadata(std::string key, size_t max_len, const char* meta_key,
                                 std::string RobotInfo::*member) {
  return Rows<RobotInfo>::read(std::move(key), Str(max_len),
                               [meta_key, member](const At& a, RobotInfo& r, Ctx& x) {
                                 At b = x.root["metadata"][meta_key];
                                 same_or_fail(a, a.str(), b, b.str());
                                 r.*member = a ? a.str() : b.str();
                               });
}

Table<RobotInfo> robot_rows() {
  using B = Rows<RobotInfo>;
  return {
      robot_or_metadata("name", 256, "robot_name", &RobotInfo::name),
      robot_or_metadata("manufacturer", 256, "manufacturer", &RobotInfo::manufacturer),
      robot_or_metadata("model", 256, "model", &RobotInfo::model),
      robot_or_metadata("description", 4096, "description", &RobotInfo::description),
      B::read("type", Str(128),
              [](const At& a, RobotInfo& r, Ctx& x) {
                r.type = a ? a.str() : x.root["physics"]["type"].str();
              }),
      B::read("dof", Int(1, 1000),
              [](const At& a, RobotInfo& r, Ctx& x) {
                if (a)
                  r.dof = a.u32(0);
                else if (At pd = x.root["physics"]["dof"])
                  r.dof = pd.u32(0);
              }),
      B::field("payload_kg", NonNeg(), &RobotInfo::payload_kg),
      B::field("reach_mm", NonNeg(), &RobotInfo::reach_mm),
      B::field("serial_pattern", Str(256), &RobotInfo::serial_pattern),
      B::schema_only("arm_payload", Obj({{"fitted", Bool()},
                                         {"dof", Int(1, 1000)},
                                         {"payload_kg", NonNeg()},
                                         {"reach_mm", NonNeg()}})),
  };
}

// OpenCastor `metadata`: what is not an alias of `ruri` or a `robot` key fills the robot's
// tags and UUID; the whole block is kept.
Table<RobotInfo> metadata_rows() {
  using B = Rows<RobotInfo>;
  return {
      B::schema_only("ruri", Str(512)),  // read by `ruri`
      B::schema_only("robot_name", Str(256)),
      B::schema_only("manufacturer", Str(256)),
      B::schema_only("model", Str(256)),
      B::schema_only("description", Str()),
      B::field("tags", StrList(), &RobotInfo::tags),
      B::read("robot_uuid", Str(64),
              [](const At& a, RobotInfo& r, Ctx&) {
                r.robot_uuid = a.str();
                if (r.robot_uuid.empty()) return;
                std::string lower = r.robot_uuid;
                std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char ch) {
                  return static_cast<char>(std::tolower(ch));
                });
                if (lower.size() != 36 || !is_hex_id(lower))
                  fail(a.path, "expected a UUID", "invalid_value");
              }),
      B::schema_only("author", Str(256)),
      B::schema_only("license", Str(256)),
      B::schema_only("created_at", Str(64)),
      B::schema_only("version", Str(64)),
      B::schema_only("device_id", Str(64)),
  };
}

// `rcan_protocol` (OpenCastor): mostly aliases of this node's keys.
Table<NodeConfig> rcan_protocol_rows() {
  return {
      R::schema_only("port", Int(1, 65535)),         // read by server.port
      R::schema_only("capabilities", Arr(Str(64))),  // read by `capabilities`
      R::schema_only("enable_mdns", Bool()),         // read by server.enable_mdns
      R::read("enable_jwt", Bool(),
              [](const At& a, NodeConfig& c, Ctx&) {
                if (a && !a.flag(true)) {
                  c.enable_jwt_false_ignored = true;
                  c.warnings.push_back(
                      "rcan_protocol.enable_jwt: false is ignored: this node always requires a "
                      "valid JWT");
                }
              }),
      R::schema_only("registry", Str()),  // read by registry.registry_url
      R::field("channel_admin_scope", Str(64), &NodeConfig::channel_admin_scope),
  };
}

}  // namespace

// registry: the registry the robot joins (its URL, the key it registers with, what it
// refreshes) and whether it trusts the registry's tokens.
Table<NodeConfig> registry_rows() {
  return {
      R::schema_only("rrn", Str(64)),  // read by `rrn`
      R::read("registry_url", Str(),
              [](const At& reg_url, NodeConfig& c, Ctx& x) {
                At proto_reg = x.root["rcan_protocol"]["registry"];
                same_or_fail(reg_url, reg_url.str(), proto_reg, proto_reg.str());
                c.registry_url = reg_url ? reg_url.str() : proto_reg.str();
              }),
      R::read("key_file", Str(),
              [](const At& a, NodeConfig& c, Ctx& x) {
                if (!a) return;
                if (a.str().empty()) fail(a.path, "must not be empty", "invalid_value");
                At url = x.root["registry"]["registry_url"];
                if (!url) url = x.root["rcan_protocol"]["registry"];
                if (!url || !parse_web_url(url.str()).ok())
                  fail(a.path,
                       "joining a registry needs registry.registry_url, an http:// "
                       "or https:// URL",
                       "invalid_value");
                c.registry.key_file = resolve_path(a.str(), x.opts.base_dir);
              }),
      R::read(
          "register", Bool(),
          [](const At& a, NodeConfig& c, Ctx&) { c.registry.register_at_start = a.flag(true); }),
      R::read("endpoint", Str(2048),
              [](const At& a, NodeConfig& c, Ctx&) {
                if (!a) return;
                const std::string& u = a.str();
                if (u.rfind("http://", 0) != 0 && u.rfind("https://", 0) != 0)
                  fail(a.path, "must be an http:// or https:// URL", "invalid_value");
                c.registry.endpoint = u;
              }),
      R::read("refresh_s", Int(10, 86'400),
              [](const At& a, NodeConfig& c, Ctx&) { c.registry.refresh_s = a.u32(300); }),
      R::read("ca_file", Str(),
              [](const At& a, NodeConfig& c, Ctx& x) {
                if (a) c.registry.ca_file = resolve_path(a.str(), x.opts.base_dir);
              }),
      R::read("trust_tokens", Bool(),
              [](const At& a, NodeConfig& c, Ctx& x) {
                c.registry.trust_tokens = a.flag(false);
                if (!c.registry.trust_tokens) return;
                At url = x.root["registry"]["registry_url"];
                if (!url) url = x.root["rcan_protocol"]["registry"];
                if (!url || !parse_web_url(url.str()).ok())
                  fail(a.path,
                       "trusting the registry's tokens needs registry.registry_url, "
                       "an http:// or https:// URL",
                       "invalid_value");
                At iss = x.root["registry"]["issuer"];
                c.registry.issuer = iss ? iss.str() : url.str();
              }),
      R::read("issuer", Str(2048),
              [](const At& a, NodeConfig&, Ctx&) {
                if (a && a.str().empty()) fail(a.path, "must not be empty", "invalid_value");
              }),
      R::read("jwks_refresh_s", Int(1, 86'400),
              [](const At& a, NodeConfig& c, Ctx&) { c.registry.jwks_refresh_s = a.u32(300); }),
      R::read(
          "revocations_refresh_s", Int(1, 86'400),
          [](const At& a, NodeConfig& c, Ctx&) { c.registry.revocations_refresh_s = a.u32(30); }),
      R::read("max_feed_revocations", Int(1, 100'000),
              [](const At& a, NodeConfig& c, Ctx&) {
                c.registry.max_feed_revocations = a.u32(10'000);
              }),
      R::read("max_key_age_s", Int(1, 30 * 86'400),
              [](const At& a, NodeConfig& c, Ctx&) { c.registry.max_key_age_s = a.u32(86400); }),
  };
}

Table<NodeConfig> identity_blocks() {
  return {
      R::read("rcan_version", Str(32),
              [](const At& ver, NodeConfig& c, Ctx&) {
                if (!ver) fail("rcan_version", "required key is missing", "missing_key");
                if (!version_ok(ver.str()))
                  fail(ver.path,
                       "expected a version like \"1.2\" or \"1.3.0\", got \"" +
                           printable(ver.str()) + "\"",
                       "invalid_value");
                c.rcan_version = ver.str();
              }),
      R::read("ruri", Str(512), read_ruri),
      R::read("rrn", Str(64),
              [](const At& rrn_top, NodeConfig& c, Ctx& x) {
                At rrn_reg = x.root["registry"]["rrn"];
                same_or_fail(rrn_top, rrn_top.str(), rrn_reg, rrn_reg.str());
                if (At rrn_at = rrn_top ? rrn_top : rrn_reg) {
                  Result<Rrn> rrn = parse_rrn(rrn_at.str());
                  if (!rrn.ok())
                    fail(rrn_at.path,
                         "invalid RRN \"" + printable(rrn_at.str()) + "\": " + rrn.error().message,
                         "invalid_value");
                  c.rrn = rrn->str();
                }
              }),
      R::block("registry", registry_rows()),
      R::block("robot", robot_rows(), &NodeConfig::robot),
      R::block("metadata", metadata_rows(), &NodeConfig::robot),
      R::read("capabilities", Either({Arr(Str(64)), object_of(hardware_capability_rows())}),
              [](const At& caps, NodeConfig& c, Ctx& x) {
                read_capabilities(caps, c, x);  // reads c.robot.type
                if (caps.is_object())
                  walk(hardware_capability_rows(), caps, c.hardware_capabilities, x);
              }),
      R::block("rcan_protocol", rcan_protocol_rows()),
  };
}

}  // namespace rcan::config::internal
