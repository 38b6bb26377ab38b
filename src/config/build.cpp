// Pass 2 of config loading: build() maps the typed tree onto NodeConfig, one step per block.
// The steps run in a fixed order: a later step may read what an earlier one set, and the
// order decides which error a file with several faults reports first.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <regex>
#include <set>

#include "base/http_client.h"
#include "config/config_internal.h"

namespace rcan::config::internal {
namespace {

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

LimitPolicy policy_of(const std::string& s) {
  return s == "clamp" ? LimitPolicy::kClamp : LimitPolicy::kReject;
}

// `rcan_version`, `ruri` (or metadata.ruri), `rrn` and `registry`.
void build_identity(const At& root, const ConfigOptions& opts, NodeConfig& c) {
  At ver = root["rcan_version"];
  if (!ver) fail("rcan_version", "required key is missing", "missing_key");
  if (!version_ok(ver.str()))
    fail(ver.path,
         "expected a version like \"1.2\" or \"1.3.0\", got \"" + printable(ver.str()) + "\"",
         "invalid_value");
  c.rcan_version = ver.str();

  At ruri_at = root["ruri"];
  At meta = root["metadata"];
  At meta_ruri = meta["ruri"];
  if (ruri_at && meta_ruri)
    fail(meta_ruri.path, "ruri is given twice (ruri and metadata.ruri); give one", "invalid_value");
  At id_at = ruri_at ? ruri_at : meta_ruri;
  if (!id_at)
    fail("ruri", "required key is missing (ruri, or metadata.ruri in the OpenCastor style)",
         "missing_key");
  std::string ruri_text = id_at.str();
  if (size_t p = ruri_text.find("{device_id}"); p != std::string::npos) {
    if (opts.device_id.empty())
      fail(id_at.path,
           "contains the {device_id} placeholder; replace it with the robot's 8-hex-digit id "
           "or UUID",
           "invalid_value");
    if (!is_hex_id(opts.device_id))
      fail(id_at.path,
           "the device id substituted for {device_id} must be 8 lower-case hex "
           "digits or a lower-case UUID",
           "invalid_value");
    ruri_text.replace(p, std::string_view("{device_id}").size(), opts.device_id);
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

  At rrn_top = root["rrn"];
  At rrn_reg = root["registry"]["rrn"];
  same_or_fail(rrn_top, rrn_top.str(), rrn_reg, rrn_reg.str());
  if (At rrn_at = rrn_top ? rrn_top : rrn_reg) {
    Result<Rrn> rrn = parse_rrn(rrn_at.str());
    if (!rrn.ok())
      fail(rrn_at.path, "invalid RRN \"" + printable(rrn_at.str()) + "\": " + rrn.error().message,
           "invalid_value");
    c.rrn = rrn->str();
  }
  At reg_url = root["registry"]["registry_url"];
  At proto_reg = root["rcan_protocol"]["registry"];
  same_or_fail(reg_url, reg_url.str(), proto_reg, proto_reg.str());
  c.registry_url = reg_url ? reg_url.str() : proto_reg.str();
}

// `robot`, or the OpenCastor `metadata` and `physics` keys.
void build_robot(const At& root, NodeConfig& c) {
  At meta = root["metadata"];
  At robot = root["robot"];
  auto pick = [&](const At& a, const At& b, std::string& out) {
    same_or_fail(a, a.str(), b, b.str());
    out = a ? a.str() : b.str();
  };
  pick(robot["name"], meta["robot_name"], c.robot.name);
  pick(robot["manufacturer"], meta["manufacturer"], c.robot.manufacturer);
  pick(robot["model"], meta["model"], c.robot.model);
  pick(robot["description"], meta["description"], c.robot.description);
  c.robot.type = robot["type"] ? robot["type"].str() : root["physics"]["type"].str();
  if (At d = robot["dof"])
    c.robot.dof = d.u32(0);
  else if (At pd = root["physics"]["dof"])
    c.robot.dof = pd.u32(0);
  c.robot.payload_kg = robot["payload_kg"].opt_num();
  c.robot.reach_mm = robot["reach_mm"].opt_num();
  c.robot.serial_pattern = robot["serial_pattern"].str();
  c.robot.tags = meta["tags"].strs();
  c.robot.robot_uuid = meta["robot_uuid"].str();
  if (!c.robot.robot_uuid.empty()) {
    std::string lower = c.robot.robot_uuid;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    if (lower.size() != 36 || !is_hex_id(lower))
      fail(meta["robot_uuid"].path, "expected a UUID", "invalid_value");
  }
}

// Protocol capabilities (configured or derived from the robot type) and hardware ones.
void build_capabilities(const At& root, NodeConfig& c) {
  At caps = root["capabilities"];
  At proto_caps = root["rcan_protocol"]["capabilities"];
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
  if (caps.is_object()) {
    c.hardware_capabilities.motion = caps["motion"].strs();
    c.hardware_capabilities.sensing = caps["sensing"].strs();
    c.hardware_capabilities.io = caps["io"].strs();
    c.hardware_capabilities.safety = caps["safety"].strs();
  }
  c.channel_admin_scope = root["rcan_protocol"]["channel_admin_scope"].str();
}

// `node`, `server` (or `rcan_protocol`), `grpc` and `udp`.
void build_node_and_server(const At& root, const ConfigOptions& opts, NodeConfig& c) {
  const std::string& base = opts.base_dir;
  At node = root["node"];
  if (At dd = node["data_dir"]) {
    if (dd.str().empty()) fail(dd.path, "must not be empty", "invalid_value");
    c.data_dir = resolve_path(dd.str(), base);
  } else if (!opts.default_data_dir.empty()) {
    c.data_dir = opts.default_data_dir;
  } else {
    Result<std::string> d = default_data_dir();
    if (!d.ok()) fail("node.data_dir", d.error().message, "missing_key");
    c.data_dir = *d;
  }
  c.log_level = node["log_level"].str("info");

  At server = root["server"];
  At proto = root["rcan_protocol"];
  same_or_fail(server["port"], server["port"].u32(0), proto["port"], proto["port"].u32(0));
  if (At p = server["port"] ? server["port"] : proto["port"])
    c.server.port = static_cast<uint16_t>(p.u32(8080));
  c.server.bind_address = server["bind"].str("127.0.0.1");
  {
    const std::string& b = c.server.bind_address;
    static const std::regex bind_re(R"(^[A-Za-z0-9.:_-]{1,255}$)");
    if (!std::regex_match(b, bind_re))
      fail(server["bind"].path, "expected an IP address or host name, got \"" + printable(b) + "\"",
           "invalid_value");
  }
  c.server.io_threads = server["io_threads"].u32(2);
  same_or_fail(server["enable_mdns"], server["enable_mdns"].flag(false), proto["enable_mdns"],
               proto["enable_mdns"].flag(false));
  c.server.enable_mdns =
      server["enable_mdns"] ? server["enable_mdns"].flag(false) : proto["enable_mdns"].flag(false);
  At tls = server["tls"];
  c.server.tls.enabled = tls["enabled"].flag(false);
  c.server.tls.cert_file = resolve_path(tls["cert_file"].str(), base);
  c.server.tls.key_file = resolve_path(tls["key_file"].str(), base);
  if (c.server.tls.enabled && c.server.tls.cert_file.empty())
    fail(tls["cert_file"].path, "required when tls.enabled is true", "missing_key");
  if (c.server.tls.enabled && c.server.tls.key_file.empty())
    fail(tls["key_file"].path, "required when tls.enabled is true", "missing_key");
  At lim = server["limits"];
  c.server.limits.max_body_bytes = lim["max_body_bytes"].u64(c.server.limits.max_body_bytes);
  c.server.limits.max_header_bytes = lim["max_header_bytes"].u64(c.server.limits.max_header_bytes);
  c.server.limits.read_timeout_ms = lim["read_timeout_ms"].u32(c.server.limits.read_timeout_ms);
  c.server.limits.idle_timeout_ms = lim["idle_timeout_ms"].u32(c.server.limits.idle_timeout_ms);
  c.server.limits.max_connections = lim["max_connections"].u32(c.server.limits.max_connections);
  build_transports(root, c, base);
  if (proto["enable_jwt"] && !proto["enable_jwt"].flag(true)) {
    c.enable_jwt_false_ignored = true;
    c.warnings.push_back(
        "rcan_protocol.enable_jwt: false is ignored: this node always requires a valid JWT");
  }
}

// `security`.
void build_security(const At& root, const std::string& base, NodeConfig& c) {
  At sec = root["security"];
  if (At kd = sec["key_dir"]) {
    c.security.key_dir = resolve_path(kd.str(), base);
    c.explicit_paths.key_dir = true;
  }
  At aud = sec["audit"];
  if (At d = aud["dir"]) {
    c.security.audit.dir = resolve_path(d.str(), base);
    c.explicit_paths.audit_dir = true;
  }
  if (At f = aud["chain_secret_file"]) {
    c.security.audit.chain_secret_file = resolve_path(f.str(), base);
    c.explicit_paths.chain_secret_file = true;
  }
  if (sec["key_dir"] && sec["key_dir"].str().empty())
    fail(sec["key_dir"].path, "must not be empty", "invalid_value");
  if (aud["dir"] && aud["dir"].str().empty())
    fail(aud["dir"].path, "must not be empty", "invalid_value");
  if (aud["chain_secret_file"] && aud["chain_secret_file"].str().empty())
    fail(aud["chain_secret_file"].path, "must not be empty", "invalid_value");
  c.security.audit.sync_policy = aud["sync"].str("per_group") == "interval"
                                     ? audit::SyncPolicy::kInterval
                                     : audit::SyncPolicy::kPerGroup;
  c.security.audit.sync_interval_ms =
      aud["sync_interval_ms"].u32(c.security.audit.sync_interval_ms);
  c.security.audit.max_segment_bytes =
      aud["max_segment_bytes"].u64(c.security.audit.max_segment_bytes);
  c.security.audit.retention_max_bytes = aud["retention"]["max_bytes"].u64(0);
  c.security.audit.retention_max_age_days = aud["retention"]["max_age_days"].u32(0);
  At jwt_at = sec["jwt"];
  for (size_t i = 0; i < jwt_at["issuers"].size(); ++i) {
    At is = jwt_at["issuers"][i];
    jwt::TrustStore::IssuerConfig ic;
    ic.issuer = is["issuer"].str();
    if (ic.issuer.empty()) fail(is["issuer"].path, "must not be empty", "invalid_value");
    ic.key_file = resolve_path(is["key_file"].str(), base);
    if (ic.key_file.empty()) fail(is["key_file"].path, "must not be empty", "invalid_value");
    ic.kind = is["kind"].str("auto");
    ic.kid = is["kid"].str();
    c.security.jwt.issuers.push_back(std::move(ic));
  }
  c.security.jwt.leeway_s = static_cast<int64_t>(jwt_at["leeway_s"].u32(60));
  c.security.replay_window_s = sec["replay_window_s"].u32(30);
  c.security.msg_id_cache_size = sec["msg_id_cache_size"].u32(10000);
  // trusted_robot_keys and trusted_signer_keys: the same shape; names unique across both.
  std::set<std::string> key_names;
  auto trusted_keys = [&](const char* member, std::vector<TrustedRobotKey>& into) {
    for (size_t i = 0; i < sec[member].size(); ++i) {
      At k = sec[member][i];
      TrustedRobotKey t;
      t.name = k["name"].str();
      if (t.name.empty()) fail(k["name"].path, "must not be empty", "invalid_value");
      if (!key_names.insert(t.name).second)
        fail(k["name"].path, "duplicate trusted key name \"" + printable(t.name) + "\"",
             "invalid_value");
      t.mldsa65_pub_file = resolve_path(k["mldsa65_pub_file"].str(), base);
      t.ed25519_pub_file = resolve_path(k["ed25519_pub_file"].str(), base);
      if (t.mldsa65_pub_file.empty() && t.ed25519_pub_file.empty())
        fail(k.path, "needs mldsa65_pub_file and/or ed25519_pub_file", "missing_key");
      into.push_back(std::move(t));
    }
  };
  trusted_keys("trusted_robot_keys", c.security.trusted_robot_keys);
  trusted_keys("trusted_signer_keys", c.security.trusted_signer_keys);
  At inj = sec["injection"];
  if (inj["use_defaults"].flag(true))
    for (const auto& p : default_injection_patterns())
      c.security.injection_patterns.push_back({p, false});
  for (size_t i = 0; i < inj["patterns"].size(); ++i) {
    At p = inj["patterns"][i];
    InjectionPattern ip;
    if (p.is_string()) {
      ip.text = p.str();
    } else {
      ip.text = p["regex"].str();
      ip.regex = true;
      try {
        std::regex test(ip.text, std::regex::ECMAScript | std::regex::icase);
        (void)test;
      } catch (const std::regex_error& e) {
        fail(p["regex"].path, std::string("invalid regular expression: ") + e.what(),
             "invalid_value");
      }
    }
    if (ip.text.empty()) fail(p.path, "empty pattern", "invalid_value");
    c.security.injection_patterns.push_back(std::move(ip));
  }
  At com = sec["commitment"];
  c.security.commitment.enabled = com["enabled"].flag(false);
  c.security.commitment.key_mode = com["key_mode"].str("classical");
  c.security.commitment.qber_threshold = com["qber_threshold"].opt_num();
  At kr = sec["key_rotation"];
  c.security.key_rotation.overlap_s = kr["overlap_s"].u32(3600);
  c.security.key_rotation.max_validity_days = kr["max_validity_days"].u32(365);
  c.security.key_rotation.auto_rotate = kr["auto_rotate"].flag(false);
  At rv = sec["revocation"];
  c.security.revocation.check_on_startup = rv["check_on_startup"].flag(false);
  c.security.revocation.cache_ttl_s = rv["cache_ttl_s"].u32(3600);
  c.security.revocation.max_staleness_s = rv["max_staleness_s"].u32(3600);
  c.security.revocation.quarantine_on_staleness = rv["quarantine_on_staleness"].flag(false);
}

// `rbac`, with the guest limits (top-level or rbac.guest_limits).
void build_rbac(const At& root, NodeConfig& c) {
  At rbac = root["rbac"];
  At grants = rbac["grants"];
  c.rbac.policy.user_arm = grants["user_arm"].flag(false);
  c.rbac.policy.user_record = grants["user_record"].flag(false);
  c.rbac.policy.leasee_training = grants["leasee_training"].flag(false);
  c.rbac.policy.leasee_diagnostics = grants["leasee_diagnostics"].flag(false);
  c.rbac.policy.owner_safety_config = grants["owner_safety_config"].flag(false);
  At rl = rbac["rate_limits"];
  c.rbac.rate_limits.guest = rl["guest"].u32(c.rbac.rate_limits.guest);
  c.rbac.rate_limits.user = rl["user"].u32(c.rbac.rate_limits.user);
  c.rbac.rate_limits.leasee = rl["leasee"].u32(c.rbac.rate_limits.leasee);
  c.rbac.rate_limits.owner = rl["owner"].u32(c.rbac.rate_limits.owner);
  c.rbac.rate_limits.creator = rl["creator"].u32(c.rbac.rate_limits.creator);
  At gl_top = root["guest_limits"];
  At gl_rbac = rbac["guest_limits"];
  if (gl_top && gl_rbac)
    fail(gl_top.path, "guest limits are given twice (guest_limits and rbac.guest_limits)",
         "invalid_value");
  if (At gl = gl_top ? gl_top : gl_rbac) {
    GuestLimitsConfig& g = c.rbac.guest_limits;
    g.chat_rate = parse_rate(gl["chat_rate"], g.chat_rate);
    g.query_rate = parse_rate(gl["query_rate"], g.query_rate);
    g.session_duration_s = parse_duration_s(gl["session_duration"], g.session_duration_s);
    if (g.session_duration_s == 0)
      fail(gl["session_duration"].path, "must be longer than zero", "out_of_range");
    g.concurrent_sessions = gl["concurrent_sessions"].u32(g.concurrent_sessions);
    if (gl["capabilities"]) g.capabilities = gl["capabilities"].strs();
    if (gl["blocked"]) g.blocked = gl["blocked"].strs();
  }
}

// `agent` and `brain`.
void build_agent_and_brain(const At& root, NodeConfig& c) {
  At agent = root["agent"];
  At brain = root["brain"];
  c.agent.provider = agent["provider"].str();
  c.agent.model = agent["model"].str();
  if (At lb = agent["latency_budget_ms"]) c.agent.latency_budget_ms = lb.u32(0);
  c.agent.safety_stop = agent["safety_stop"].flag(true);
  At mo_a = agent["min_obstacle_m"];
  At mo_r = root["reactive"]["min_obstacle_m"];
  same_or_fail(mo_a, mo_a.num(), mo_r, mo_r.num());
  c.agent.min_obstacle_m = mo_a ? mo_a.opt_num() : mo_r.opt_num();
  for (const char* k : {"confidence_gates", "hitl_gates"}) {
    if (agent[k] && brain[k])
      fail(brain[k].path,
           std::string("gates are given twice (agent.") + k + " and brain." + k + ")",
           "invalid_value");
  }
  c.agent.confidence_gates = build_confidence_gates(
      agent["confidence_gates"] ? agent["confidence_gates"] : brain["confidence_gates"]);
  c.agent.hitl_gates =
      build_hitl_gates(agent["hitl_gates"] ? agent["hitl_gates"] : brain["hitl_gates"]);
  At layers = agent["layers"];
  c.agent.reactive_layer = build_layer(layers["reactive"]);
  c.agent.fast_layer = build_layer(layers["fast"]);
  c.agent.planner_layer = build_layer(layers["planner"]);
  c.brain.provider = brain["provider"].str();
  c.brain.model = brain["model"].str();
  c.brain.fast_brain = brain["fast_brain"].str();
  c.brain.api_key_env = brain["api_key_env"].str();
  c.brain.max_tokens = brain["max_tokens"].opt_u32();
  c.brain.temperature = brain["temperature"].opt_num();
}

// `safety` and `watchdog`. Reads c.agent.latency_budget_ms (the heartbeat default).
void build_safety(const At& root, NodeConfig& c) {
  At s = root["safety"];
  if (At lsw = s["local_safety_wins"]; lsw && !lsw.flag(true))
    fail(lsw.path, "must be true: local safety always wins over network commands", "invalid_value");
  same_or_fail(s["max_linear_speed_mps"], s["max_linear_speed_mps"].num(), s["max_linear_x"],
               s["max_linear_x"].num());
  same_or_fail(s["max_angular_speed_radps"], s["max_angular_speed_radps"].num(), s["max_angular_z"],
               s["max_angular_z"].num());
  SafetyConfig& sf = c.safety;
  sf.max_linear_speed_mps = s["max_linear_speed_mps"]
                                ? s["max_linear_speed_mps"].num()
                                : s["max_linear_x"].num(sf.max_linear_speed_mps);
  sf.max_angular_speed_radps = s["max_angular_speed_radps"]
                                   ? s["max_angular_speed_radps"].num()
                                   : s["max_angular_z"].num(sf.max_angular_speed_radps);
  sf.max_speed_override = s["max_speed_override"].opt_num();
  if (s["emergency_stop_distance"] && s["estop_distance_mm"] &&
      std::fabs(s["emergency_stop_distance"].num() * 1000.0 - s["estop_distance_mm"].num()) > 1e-6)
    fail(s["estop_distance_mm"].path, "conflicts with safety.emergency_stop_distance (give one)",
         "invalid_value");
  if (s["emergency_stop_distance"])
    sf.estop_distance_m = s["emergency_stop_distance"].num();
  else if (s["estop_distance_mm"])
    sf.estop_distance_m = s["estop_distance_mm"].num() / 1000.0;
  sf.collision_monitor_stop_m = s["collision_monitor_stop_m"].opt_num();
  sf.collision_monitor_slowdown_m = s["collision_monitor_slowdown_m"].opt_num();
  if (sf.collision_monitor_stop_m && sf.collision_monitor_slowdown_m &&
      *sf.collision_monitor_slowdown_m < *sf.collision_monitor_stop_m)
    fail(s["collision_monitor_slowdown_m"].path,
         "must be at least collision_monitor_stop_m (slow down before stopping)", "out_of_range");
  sf.obstacle_stop_cm = s["obstacle_stop_cm"].opt_num();
  if (At jl = s["joint_limits"]) {
    for (size_t i = 0; i < jl.size(); ++i) {
      JointLimit j;
      j.name = jl[i]["name"].str();
      j.min_rad = jl[i]["min"].num();
      j.max_rad = jl[i]["max"].num();
      if (!(j.min_rad < j.max_rad))
        fail(jl[i]["max"].path,
             "must be greater than min (" + fmt_num(j.min_rad) + " ≥ " + fmt_num(j.max_rad) + ")",
             "out_of_range");
      sf.joint_limits.push_back(std::move(j));
    }
  } else {
    for (int i = 0; i < 6; ++i)
      sf.joint_limits.push_back({"joint" + std::to_string(i + 1), -3.14, 3.14});
  }
  if (At ws = s["workspace"]) {
    sf.workspace.x_min = ws["x_min"].num();
    sf.workspace.x_max = ws["x_max"].num();
    sf.workspace.y_min = ws["y_min"].num();
    sf.workspace.y_max = ws["y_max"].num();
    sf.workspace.z_min = ws["z_min"].opt_num();
    sf.workspace.z_max = ws["z_max"].opt_num();
    if (!(sf.workspace.x_min < sf.workspace.x_max))
      fail(ws["x_max"].path, "must be greater than x_min", "out_of_range");
    if (!(sf.workspace.y_min < sf.workspace.y_max))
      fail(ws["y_max"].path, "must be greater than y_min", "out_of_range");
    if (sf.workspace.z_min.has_value() != sf.workspace.z_max.has_value())
      fail(ws[sf.workspace.z_min ? "z_max" : "z_min"].path, "z_min and z_max go together",
           "missing_key");
    if (sf.workspace.z_min && !(*sf.workspace.z_min < *sf.workspace.z_max))
      fail(ws["z_max"].path, "must be greater than z_min", "out_of_range");
  }
  if (At lp = s["limit_policy"]) {
    if (lp.is_string()) {
      sf.speed_policy = sf.joint_policy = sf.workspace_policy = policy_of(lp.str());
    } else {
      if (lp["speed"]) sf.speed_policy = policy_of(lp["speed"].str());
      if (lp["joints"]) sf.joint_policy = policy_of(lp["joints"].str());
      if (lp["workspace"]) sf.workspace_policy = policy_of(lp["workspace"].str());
    }
  }
  sf.estop_on_startup = s["estop_on_startup"].flag(false);
  sf.estop_clear_requires_presence = s["estop_clear_requires_presence"].flag(false);
  if (At hb = s["heartbeat_timeout_ms"]) {
    sf.heartbeat_timeout_ms = hb.u32(2000);
  } else if (c.agent.latency_budget_ms && *c.agent.latency_budget_ms > 0) {
    sf.heartbeat_timeout_ms = std::clamp<uint32_t>(*c.agent.latency_budget_ms * 2, 100, 600'000);
  }
  sf.command_ttl_default_ms = s["command_ttl_default_ms"].u32(0);
  At wd = root["watchdog"];
  sf.watchdog.enabled = wd["enabled"].flag(true);
  sf.watchdog.timeout_s = wd["timeout_s"].u32(10);
  sf.max_walk_speed_mps = s["max_walk_speed_mps"].opt_num();
  sf.max_tcp_speed_mm_s = s["max_tcp_speed_mm_s"].opt_num();
  sf.max_tcp_force_n = s["max_tcp_force_n"].opt_num();
  sf.collision_threshold_scale = s["collision_threshold_scale"].opt_num();
  sf.protective_stop_distance_mm = s["protective_stop_distance_mm"].opt_num();
  sf.estop_heartbeat_interval_ms = s["estop_heartbeat_interval_ms"].opt_u32();
  sf.estop_timeout_ms = s["estop_timeout_ms"].opt_u32();
  sf.fri_heartbeat_timeout_ms = s["fri_heartbeat_timeout_ms"].opt_u32();
  if (At t = s["max_joint_torques_nm"])
    for (size_t i = 0; i < t.size(); ++i) sf.max_joint_torques_nm.push_back(t[i].num());
}

// `driver`.
void build_driver(const At& root, NodeConfig& c) {
  At drv = root["driver"];
  c.driver.type = drv["type"].str("sim");
  At sim = drv["sim"];
  SimDriverConfig& sd = c.driver.sim;
  sd.wheel_base_m = sim["wheel_base_m"].num(sd.wheel_base_m);
  sd.max_accel_mps2 = sim["max_accel_mps2"].num(sd.max_accel_mps2);
  sd.max_angular_accel_radps2 = sim["max_angular_accel_radps2"].num(sd.max_angular_accel_radps2);
  sd.tick_hz = sim["tick_hz"].u32(sd.tick_hz);
  sd.telemetry_hz = sim["telemetry_hz"].u32(sd.telemetry_hz);
  sd.arm_joints = sim["arm_joints"].u32(sd.arm_joints);
  if (sd.telemetry_hz > sd.tick_hz)
    fail(sim["telemetry_hz"].path, "must not exceed tick_hz", "out_of_range");
}

// The v1.5 blocks: `offline`, `control` and `qos`.
void build_v15_blocks(const At& root, NodeConfig& c) {
  At off = root["offline"];
  c.offline.grace_period_s = off["grace_period_s"].u32(c.offline.grace_period_s);
  c.offline.cross_owner_grace_s = off["cross_owner_grace_s"].u32(c.offline.cross_owner_grace_s);
  c.offline.max_key_ttl_s = off["max_key_ttl_s"].u32(c.offline.max_key_ttl_s);
  c.offline.issuer_url = off["issuer_url"].str();
  c.offline.issuer_poll_ms = off["issuer_poll_ms"].u32(c.offline.issuer_poll_ms);
  c.offline.issuer_timeout_ms = off["issuer_timeout_ms"].u32(c.offline.issuer_timeout_ms);
  if (!c.offline.issuer_url.empty() && !rcan::parse_http_url(c.offline.issuer_url).ok())
    fail(off["issuer_url"].path, "must be an http:// URL", "invalid_value");
  At ctl = root["control"];
  c.control.fleet_policy = ctl["fleet_policy"].str(c.control.fleet_policy);
  c.control.handoff_window_s = ctl["handoff_window_s"].u32(c.control.handoff_window_s);
  c.control.queue_max = ctl["queue_max"].u32(c.control.queue_max);
  c.control.queue_wait_s = ctl["queue_wait_s"].u32(c.control.queue_wait_s);
  c.control.max_session_s = ctl["max_session_s"].u32(c.control.max_session_s);
  c.control.transfer_window_s = ctl["transfer_window_s"].u32(c.control.transfer_window_s);
  c.control.consent_ttl_s = ctl["consent_ttl_s"].u32(c.control.consent_ttl_s);
  c.control.consent_webhook = ctl["consent_webhook"].str();
  if (!c.control.consent_webhook.empty() && !rcan::parse_http_url(c.control.consent_webhook).ok())
    fail(ctl["consent_webhook"].path, "must be an http:// URL", "invalid_value");
  At qos = root["qos"];
  c.qos.ack_timeout_ms = qos["ack_timeout_ms"].u32(c.qos.ack_timeout_ms);
  c.qos.max_retries = qos["max_retries"].u32(c.qos.max_retries);
  c.qos.backoff_base_ms = qos["backoff_base_ms"].u32(c.qos.backoff_base_ms);
}

// Blocks kept as they are for the profiles (NodeConfig::kept).
void keep_blocks(const At& root, NodeConfig& c) {
  for (const char* k : {"bridge", "hardware_safety", "messaging", "metadata", "physics", "drivers",
                        "network", "tiered_brain", "reactive", "learner", "camera", "audio",
                        "channels", "agent_roster", "swarm", "connection", "notes", "ros2"}) {
    if (At b = root[k]) c.kept.set(k, *b.v);
  }
}

}  // namespace

NodeConfig build(const json::Value& root_value, const ConfigOptions& opts) {
  NodeConfig c;
  At root{&root_value, ""};
  const std::string& base = opts.base_dir;

  build_identity(root, opts, c);
  build_robot(root, c);
  build_capabilities(root, c);           // reads c.robot.type
  build_node_and_server(root, opts, c);  // build_transports reads c.server.port
  build_security(root, base, c);
  build_rbac(root, c);
  build_agent_and_brain(root, c);
  build_safety(root, c);  // reads c.agent.latency_budget_ms
  build_driver(root, c);
  build_v15_blocks(root, c);
  parse_fleet_blocks(root, base, c);  // reads c.ruri_parts
  keep_blocks(root, c);

  derive_paths(c);
  return c;
}

}  // namespace rcan::config::internal
