// Pass 2 helpers shared by build.cpp's steps: path resolution, rate and duration formats,
// gates and layers, derived capabilities and paths, and the fleet and transport blocks.
#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <unordered_map>

#include "config/config_internal.h"
#include "rcan/mqtt_topics.h"
#include "transport/mqtt_client.h"

namespace rcan::config::internal {

std::string resolve_path(const std::string& p, const std::string& base_dir) {
  namespace fs = std::filesystem;
  if (p.empty()) return p;
  if (p == "~" || p.rfind("~/", 0) == 0) {
    const char* home = std::getenv("HOME");
    if (home != nullptr && *home == '/')
      return (fs::path(home) / p.substr(p.size() > 1 ? 2 : 1)).lexically_normal().string();
  }
  fs::path path(p);
  if (path.is_absolute() || base_dir.empty()) return path.lexically_normal().string();
  return (fs::path(base_dir) / path).lexically_normal().string();
}

// "10/minute", "10 / min", "30/s", or a bare integer (per minute).
RateSpec parse_rate(const At& a, RateSpec def) {
  if (!a) return def;
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
uint32_t parse_duration_s(const At& a, uint32_t def) {
  if (!a) return def;
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

std::vector<ConfidenceGate> build_confidence_gates(const At& a) {
  std::vector<ConfidenceGate> out;
  std::unordered_map<std::string, std::string> scope_at;
  for (size_t i = 0; i < a.size(); ++i) {
    At g = a[i];
    ConfidenceGate gate;
    gate.scope = g["scope"].str();
    static const std::regex scope_re(R"(^[a-z][a-z0-9_.:-]*$)");
    if (!std::regex_match(gate.scope, scope_re))
      fail(g["scope"].path,
           "invalid scope \"" + printable(gate.scope) +
               "\" (lower-case name like control, nav, admin)",
           "invalid_value");
    auto [it, inserted] = scope_at.emplace(gate.scope, g.path);
    if (!inserted)
      fail(g["scope"].path,
           "duplicate gate for scope \"" + gate.scope + "\" (also at " + it->second + ")",
           "invalid_value");
    gate.min_confidence = g["min_confidence"].num();
    std::string f = g["on_fail"].str();
    gate.on_fail = f == "block"      ? GateOnFail::kBlock
                   : f == "escalate" ? GateOnFail::kEscalate
                                     : GateOnFail::kAllow;  // allow | log
    out.push_back(std::move(gate));
  }
  return out;
}

std::vector<HitlGate> build_hitl_gates(const At& a) {
  std::vector<HitlGate> out;
  for (size_t i = 0; i < a.size(); ++i) {
    At g = a[i];
    HitlGate gate;
    if (g["action_types"] && g["action_type"])
      fail(g["action_type"].path, "give either action_types or action_type, not both",
           "invalid_value");
    if (g["action_type"])
      gate.action_types.push_back(g["action_type"].str());
    else
      gate.action_types = g["action_types"].strs();
    gate.require_auth = g["require_auth"].flag(true);
    if (gate.require_auth && gate.action_types.empty())
      fail(g["action_types"].path, "a gate with require_auth needs at least one action type",
           "missing_key");
    for (size_t j = 0; j < gate.action_types.size(); ++j) {
      if (gate.action_types[j].empty())
        fail(g["action_types"][j].path, "empty action type", "invalid_value");
    }
    gate.auth_timeout_ms = g["auth_timeout_ms"].u32(30000);
    gate.on_timeout =
        g["on_timeout"].str("block") == "allow" ? HitlOnTimeout::kAllow : HitlOnTimeout::kBlock;
    gate.notify = g["notify"].strs();
    if (At roles = g["authorized_roles"]) {
      gate.authorized_roles.clear();
      for (size_t j = 0; j < roles.size(); ++j) {
        std::string name = roles[j].str();
        std::optional<Role> r = role_from_name(name);
        if (!r) fail(roles[j].path, "unknown role \"" + printable(name) + "\"", "invalid_value");
        if (*r != Role::kOwner && *r != Role::kCreator)
          fail(roles[j].path,
               "HiTL approval needs OWNER or CREATOR (seed §16.4); authorized_roles may only "
               "narrow that set, not add " +
                   std::string(role_name(*r)),
               "invalid_value");
        if (std::find(gate.authorized_roles.begin(), gate.authorized_roles.end(), *r) ==
            gate.authorized_roles.end())
          gate.authorized_roles.push_back(*r);
      }
      if (gate.authorized_roles.empty())
        fail(roles.path, "must name OWNER and/or CREATOR", "invalid_value");
    }
    out.push_back(std::move(gate));
  }
  return out;
}

std::optional<AgentLayer> build_layer(const At& a) {
  if (!a) return std::nullopt;
  AgentLayer l;
  l.url = a["url"].str();
  if (l.url.rfind("http://", 0) != 0 && l.url.rfind("https://", 0) != 0)
    fail(a["url"].path, "expected an http:// or https:// URL", "invalid_value");
  l.timeout_ms = a["timeout_ms"].u32(1000);
  return l;
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

void derive_paths(NodeConfig& c) {
  namespace fs = std::filesystem;
  if (!c.explicit_paths.key_dir) c.security.key_dir = (fs::path(c.data_dir) / "keys").string();
  if (!c.explicit_paths.audit_dir) c.security.audit.dir = (fs::path(c.data_dir) / "audit").string();
  if (!c.explicit_paths.chain_secret_file)
    c.security.audit.chain_secret_file = (fs::path(c.data_dir) / "audit.secret").string();
}

// `mqtt`, `fleet` and the seed §5.2 keys of `swarm` (docs/FLEET.md).
void parse_fleet_blocks(const At& root, const std::string& base, NodeConfig& c) {
  At mq = root["mqtt"];
  c.mqtt.enabled = mq["enabled"].flag(false);
  c.mqtt.broker = mq["broker"].str(c.mqtt.broker);
  if (auto u = transport::parse_broker_url(c.mqtt.broker); !u.ok())
    fail(mq["broker"].path, u.error().message, "invalid_value");
  else if (u->tls && mq["tls"]["ca_file"].str().empty())
    fail(mq["tls"]["ca_file"].path, "required with an mqtts:// broker", "missing_key");
  c.mqtt.client_id = mq["client_id"].str();
  if (!c.mqtt.client_id.empty() && !mqtt::valid_topic_segment(c.mqtt.client_id))
    fail(mq["client_id"].path, "expected 1-128 characters of [A-Za-z0-9._-]", "invalid_value");
  c.mqtt.topic_prefix = mq["topic_prefix"].str(c.mqtt.topic_prefix);
  if (!mqtt::valid_topic_prefix(c.mqtt.topic_prefix))
    fail(mq["topic_prefix"].path,
         "expected '/'-separated segments of [A-Za-z0-9._-] (no wildcards)", "invalid_value");
  c.mqtt.keepalive_s = mq["keepalive_s"].u32(c.mqtt.keepalive_s);
  c.mqtt.username = mq["username"].str();
  c.mqtt.password_file = resolve_path(mq["password_file"].str(), base);
  if (!c.mqtt.username.empty() && c.mqtt.password_file.empty())
    fail(mq["password_file"].path, "required with mqtt.username", "missing_key");
  c.mqtt.ca_file = resolve_path(mq["tls"]["ca_file"].str(), base);
  c.mqtt.cert_file = resolve_path(mq["tls"]["cert_file"].str(), base);
  c.mqtt.key_file = resolve_path(mq["tls"]["key_file"].str(), base);
  if (c.mqtt.cert_file.empty() != c.mqtt.key_file.empty())
    fail(mq["tls"].path, "cert_file and key_file go together", "missing_key");
  c.mqtt.reconnect_min_s = mq["reconnect"]["min_s"].u32(c.mqtt.reconnect_min_s);
  c.mqtt.reconnect_max_s = mq["reconnect"]["max_s"].u32(c.mqtt.reconnect_max_s);
  if (c.mqtt.reconnect_max_s < c.mqtt.reconnect_min_s)
    fail(mq["reconnect"]["max_s"].path, "must be at least reconnect.min_s", "out_of_range");
  c.mqtt.telemetry_hz = mq["telemetry_hz"].u32(c.mqtt.telemetry_hz);
  c.mqtt.publish_audit = mq["publish_audit"].flag(true);
  c.mqtt.estop_qos = static_cast<int>(mq["estop_qos"].u32(static_cast<uint32_t>(c.mqtt.estop_qos)));

  auto segment = [](const At& at) {
    if (at && !mqtt::valid_topic_segment(at.str()))
      fail(at.path,
           "expected 1-128 characters of [A-Za-z0-9._-], got \"" + printable(at.str()) + "\"",
           "invalid_value");
  };
  auto segments = [&](const At& list) {
    for (size_t i = 0; i < list.size(); ++i) segment(list[i]);
  };
  if (At fl = root["fleet"]) {
    if (!c.mqtt.enabled)
      fail(fl.path, "a fleet needs the MQTT transport (mqtt.enabled: true)", "invalid_value");
    segment(fl["fleet_id"]);
    segments(fl["robots"]);
    segment(fl["member_id"]);
    c.fleet.fleet_id = fl["fleet_id"].str();
    c.fleet.robots = fl["robots"].strs();
    c.fleet.member_id = fl["member_id"].str(c.ruri_parts.device_id);
    if (std::find(c.fleet.robots.begin(), c.fleet.robots.end(), c.fleet.member_id) ==
        c.fleet.robots.end())
      fail(fl["robots"].path,
           "must list this robot (\"" + printable(c.fleet.member_id) +
               "\", fleet.member_id or the RURI device id)",
           "invalid_value");
    c.fleet.access_mode = fl["access_mode"].str(c.fleet.access_mode);
    c.fleet.broadcast = fl["commands"]["broadcast"].flag(true);
    c.fleet.individual = fl["commands"]["individual"].flag(true);
    c.fleet.choreographed = fl["commands"]["choreographed"].flag(true);
  }
  At sw = root["swarm"];
  if (At id = sw["swarm_id"]) {
    if (!c.mqtt.enabled)
      fail(id.path, "a swarm needs the MQTT transport (mqtt.enabled: true)", "invalid_value");
    segment(id);
    segments(sw["members"]);
    segment(sw["member_id"]);
    segment(sw["leader"]);
    c.swarm.swarm_id = id.str();
    c.swarm.members = sw["members"].strs();
    c.swarm.member_id =
        sw["member_id"].str(c.fleet.member_id.empty() ? c.ruri_parts.device_id : c.fleet.member_id);
    if (std::find(c.swarm.members.begin(), c.swarm.members.end(), c.swarm.member_id) ==
        c.swarm.members.end())
      c.swarm.members.push_back(c.swarm.member_id);
    std::sort(c.swarm.members.begin(), c.swarm.members.end());
    c.swarm.members.erase(std::unique(c.swarm.members.begin(), c.swarm.members.end()),
                          c.swarm.members.end());
    c.swarm.leader = sw["leader"].str(c.swarm.members.front());
    if (std::find(c.swarm.members.begin(), c.swarm.members.end(), c.swarm.leader) ==
        c.swarm.members.end())
      fail(sw["leader"].path, "the leader must be one of swarm.members", "invalid_value");
    c.swarm.formation = sw["formation"].str(c.swarm.formation);
    c.swarm.join_policy = sw["join_policy"].str(c.swarm.join_policy);
    c.swarm.heartbeat_ms = sw["heartbeat_ms"].u32(c.swarm.heartbeat_ms);
    c.swarm.leader_timeout_ms = sw["leader_timeout_ms"].u32(c.swarm.leader_timeout_ms);
    if (c.swarm.leader_timeout_ms < 2 * c.swarm.heartbeat_ms)
      fail(sw["leader_timeout_ms"].path, "must be at least twice swarm.heartbeat_ms",
           "out_of_range");
  }
}

// `grpc` and `udp` (docs/CONFIG.md).
void build_transports(const At& root, NodeConfig& c, const std::string& base) {
  static const std::regex bind_re(R"(^[A-Za-z0-9.:_-]{1,255}$)");
  At g = root["grpc"];
  c.grpc.enabled = g["enabled"].flag(false);
  c.grpc.port = static_cast<uint16_t>(g["port"].u32(8081));
  c.grpc.bind_address = g["bind"].str("127.0.0.1");
  if (!std::regex_match(c.grpc.bind_address, bind_re))
    fail(g["bind"].path, "expected an IP address or host name", "invalid_value");
  c.grpc.max_streams = g["max_streams"].u32(64);
  c.grpc.module = resolve_path(g["module"].str(), base);
  At gt = g["tls"];
  c.grpc.tls.enabled = gt["enabled"].flag(false);
  c.grpc.tls.cert_file = resolve_path(gt["cert_file"].str(), base);
  c.grpc.tls.key_file = resolve_path(gt["key_file"].str(), base);
  c.grpc.client_ca_file = resolve_path(gt["client_ca_file"].str(), base);
  if (c.grpc.tls.enabled && c.grpc.tls.cert_file.empty())
    fail(gt["cert_file"].path, "required when tls.enabled is true", "missing_key");
  if (c.grpc.tls.enabled && c.grpc.tls.key_file.empty())
    fail(gt["key_file"].path, "required when tls.enabled is true", "missing_key");
  if (!c.grpc.tls.enabled && !c.grpc.client_ca_file.empty())
    fail(gt["client_ca_file"].path, "needs tls.enabled: true", "invalid_value");
  At u = root["udp"];
  c.udp.enabled = u["enabled"].flag(false);
  c.udp.port = static_cast<uint16_t>(u["port"].u32(8082));
  c.udp.bind_address = u["bind"].str("127.0.0.1");
  if (!std::regex_match(c.udp.bind_address, bind_re))
    fail(u["bind"].path, "expected an IP address", "invalid_value");
  c.udp.heartbeat = u["heartbeat"].flag(true);
  c.udp.discovery = u["discovery"].flag(true);
  c.udp.discovery_per_source_per_min = u["discovery_per_source_per_min"].u32(30);
  if (c.udp.enabled && !c.udp.heartbeat && !c.udp.discovery)
    fail(u["enabled"].path, "udp is enabled but both heartbeat and discovery are off",
         "invalid_value");
  if (c.grpc.enabled && c.grpc.port != 0 && c.grpc.port == c.server.port)
    fail(g["port"].path, "must differ from server.port (" + std::to_string(c.server.port) + ")",
         "invalid_value");
}

}  // namespace rcan::config::internal
