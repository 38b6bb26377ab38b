// Node configuration: strict `.rcan.yaml` loading. See config.h and docs/CONFIG.md.
//
// Two passes:
//   1. validate(): walks the YAML tree against a declarative schema (every key of every
//      block enumerated) and produces a typed json::Value tree. Unknown and duplicate keys,
//      wrong types, enum and range violations fail here, with the key path and the
//      YAML line/column. Node and depth budgets bound the walk (alias bombs, cycles).
//   2. build(): maps the typed tree onto NodeConfig: aliases between the two published
//      styles, cross-field checks (min < max, RURI, RRN), defaults and path resolution.
// yaml-cpp exceptions and this file's own ConfigError never leave the module.
#include "node/config.h"
#include "node/http_client.h"

#include <pwd.h>
#include <unistd.h>
#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <limits>
#include <memory>
#include <regex>
#include <set>
#include <sstream>
#include <unordered_map>
#include <utility>

#include "node/mqtt_topics.h"
#include "rcan/hash.h"
#include "transport/mqtt_client.h"

namespace rcan::config {
namespace {

// ---------------------------------------------------------------------------------------
// Errors

struct ConfigError {
  std::string path;
  std::string message;
  std::string reason;
};

[[noreturn]] void fail(std::string path, std::string message, std::string reason) {
  throw ConfigError{std::move(path), std::move(message), std::move(reason)};
}

std::string printable(std::string_view s, size_t max = 48) {
  std::string out;
  for (unsigned char c : s) {
    if (out.size() >= max) {
      out += "…";
      break;
    }
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out;
}

std::string key_segment(const std::string& parent, std::string_view key) {
  bool plain = !key.empty() && key.size() <= 64;
  for (char c : key) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) plain = false;
  }
  if (plain) return parent.empty() ? std::string(key) : parent + "." + std::string(key);
  return parent + "[\"" + printable(key, 64) + "\"]";
}

std::string index_segment(const std::string& parent, size_t i) {
  return parent + "[" + std::to_string(i) + "]";
}

// ---------------------------------------------------------------------------------------
// Scalars: YAML 1.2 core schema resolution of plain scalars, plus the YAML 1.1 booleans
// (yes/no/on/off) that Python tools read as booleans.

enum class ScalarKind { kNull, kBool, kInt, kFloat, kString };

struct Scalar {
  ScalarKind kind = ScalarKind::kString;
  std::string text;
  bool b = false;
  int64_t i = 0;
  double d = 0;
  bool int_overflow = false;
};

bool is_one_of(std::string_view s, std::initializer_list<std::string_view> list) {
  return std::find(list.begin(), list.end(), s) != list.end();
}

bool all_digits(std::string_view s, int base) {
  if (s.empty()) return false;
  for (char c : s) {
    if (base == 10 && !(c >= '0' && c <= '9')) return false;
    if (base == 8 && !(c >= '0' && c <= '7')) return false;
    if (base == 16 && !std::isxdigit(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

bool parse_int(std::string_view s, Scalar& out) {
  std::string_view body = s;
  bool neg = false;
  if (!body.empty() && (body[0] == '+' || body[0] == '-')) {
    neg = body[0] == '-';
    body.remove_prefix(1);
  }
  int base = 10;
  if (body.size() > 2 && body[0] == '0' && (body[1] == 'x' || body[1] == 'o')) {
    if (s.size() != body.size()) return false;  // no sign on 0x / 0o
    base = body[1] == 'x' ? 16 : 8;
    body.remove_prefix(2);
  }
  if (!all_digits(body, base)) return false;
  out.kind = ScalarKind::kInt;
  // Magnitude limit: INT64_MAX, or INT64_MAX + 1 for a negative number.
  const uint64_t limit = static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) + (neg ? 1u : 0u);
  uint64_t v = 0;
  for (char c : body) {
    unsigned digit = std::isdigit(static_cast<unsigned char>(c))
                         ? static_cast<unsigned>(c - '0')
                         : static_cast<unsigned>(std::tolower(static_cast<unsigned char>(c)) - 'a' + 10);
    if (v > (limit - digit) / static_cast<unsigned>(base)) {
      out.int_overflow = true;
      return true;
    }
    v = v * static_cast<unsigned>(base) + digit;
  }
  if (neg) {
    out.i = v == static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) + 1u
                ? std::numeric_limits<int64_t>::min()
                : -static_cast<int64_t>(v);
  } else {
    out.i = static_cast<int64_t>(v);
  }
  return true;
}

bool parse_float(std::string_view s, Scalar& out) {
  std::string_view body = s;
  bool neg = false;
  if (!body.empty() && (body[0] == '+' || body[0] == '-')) {
    neg = body[0] == '-';
    body.remove_prefix(1);
  }
  if (is_one_of(body, {".inf", ".Inf", ".INF"})) {
    out.kind = ScalarKind::kFloat;
    out.d = neg ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
    return true;
  }
  if (s.size() == body.size() && is_one_of(body, {".nan", ".NaN", ".NAN"})) {
    out.kind = ScalarKind::kFloat;
    out.d = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  // [0-9]+(\.[0-9]*)?([eE][-+]?[0-9]+)?  |  \.[0-9]+([eE][-+]?[0-9]+)?
  size_t p = 0;
  size_t int_digits = 0, frac_digits = 0;
  while (p < body.size() && std::isdigit(static_cast<unsigned char>(body[p]))) ++p, ++int_digits;
  if (p < body.size() && body[p] == '.') {
    ++p;
    while (p < body.size() && std::isdigit(static_cast<unsigned char>(body[p]))) ++p, ++frac_digits;
  }
  if (int_digits == 0 && frac_digits == 0) return false;
  if (p < body.size() && (body[p] == 'e' || body[p] == 'E')) {
    ++p;
    if (p < body.size() && (body[p] == '+' || body[p] == '-')) ++p;
    size_t exp_digits = 0;
    while (p < body.size() && std::isdigit(static_cast<unsigned char>(body[p]))) ++p, ++exp_digits;
    if (exp_digits == 0) return false;
  }
  if (p != body.size()) return false;
  std::string copy(s);
  errno = 0;
  char* end = nullptr;
  double d = std::strtod(copy.c_str(), &end);
  if (end != copy.c_str() + copy.size()) return false;
  out.kind = ScalarKind::kFloat;
  out.d = d;  // ±HUGE_VAL on overflow → reported as not finite
  return true;
}

Scalar resolve(const YAML::Node& n) {
  Scalar s;
  s.text = n.Scalar();
  const std::string& tag = n.Tag();
  if (tag == "!" || tag == "tag:yaml.org,2002:str") return s;  // quoted / block / !!str
  if (tag != "?" && !tag.empty()) return s;                    // rejected by the caller
  const std::string& t = s.text;
  if (is_one_of(t, {"", "~", "null", "Null", "NULL"})) {
    s.kind = ScalarKind::kNull;
  } else if (is_one_of(t, {"true", "True", "TRUE", "yes", "Yes", "YES", "on", "On", "ON"})) {
    s.kind = ScalarKind::kBool;
    s.b = true;
  } else if (is_one_of(t, {"false", "False", "FALSE", "no", "No", "NO", "off", "Off", "OFF"})) {
    s.kind = ScalarKind::kBool;
    s.b = false;
  } else if (parse_int(t, s) || parse_float(t, s)) {
    // kind set
  }
  return s;
}

std::string describe(const YAML::Node& n) {
  switch (n.Type()) {
    case YAML::NodeType::Map: return "a mapping";
    case YAML::NodeType::Sequence: return "a list";
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined: return "null";
    case YAML::NodeType::Scalar: break;
  }
  Scalar s = resolve(n);
  switch (s.kind) {
    case ScalarKind::kNull: return "null";
    case ScalarKind::kBool: return "boolean " + s.text;
    case ScalarKind::kInt: return "integer " + printable(s.text);
    case ScalarKind::kFloat: return "number " + printable(s.text);
    case ScalarKind::kString: break;
  }
  return "string \"" + printable(s.text) + "\"";
}

// ---------------------------------------------------------------------------------------
// Schema

struct Schema;
using SP = std::shared_ptr<const Schema>;

struct Schema {
  enum class K { kString, kInt, kNumber, kBool, kObject, kArray, kEither, kFree };
  K k = K::kString;
  // kString
  std::vector<std::string> enums;
  size_t max_len = 4096;
  // kInt / kNumber
  std::optional<double> min, max;
  bool min_exclusive = false;
  // kObject
  std::vector<std::pair<std::string, SP>> props;
  std::vector<std::string> required;
  // kArray
  SP items;
  size_t max_items = 1024;
  // kEither: alternatives tried by the YAML node's kind (and, for scalars, resolved type)
  std::vector<SP> alts;
};

SP make(Schema s) { return std::make_shared<const Schema>(std::move(s)); }

SP Str(size_t max_len = 4096) {
  Schema s;
  s.k = Schema::K::kString;
  s.max_len = max_len;
  return make(std::move(s));
}
SP Enum(std::initializer_list<const char*> values) {
  Schema s;
  s.k = Schema::K::kString;
  for (const char* v : values) s.enums.emplace_back(v);
  return make(std::move(s));
}
SP Int(std::optional<double> lo = std::nullopt, std::optional<double> hi = std::nullopt) {
  Schema s;
  s.k = Schema::K::kInt;
  s.min = lo;
  s.max = hi;
  return make(std::move(s));
}
SP Num(std::optional<double> lo = std::nullopt, std::optional<double> hi = std::nullopt,
       bool lo_exclusive = false) {
  Schema s;
  s.k = Schema::K::kNumber;
  s.min = lo;
  s.max = hi;
  s.min_exclusive = lo_exclusive;
  return make(std::move(s));
}
SP Pos() { return Num(0.0, std::nullopt, true); }    // > 0
SP NonNeg() { return Num(0.0); }                      // ≥ 0
SP Bool() {
  Schema s;
  s.k = Schema::K::kBool;
  return make(std::move(s));
}
SP Obj(std::vector<std::pair<std::string, SP>> props, std::vector<std::string> required = {}) {
  Schema s;
  s.k = Schema::K::kObject;
  s.props = std::move(props);
  s.required = std::move(required);
  return make(std::move(s));
}
SP Arr(SP items, size_t max_items = 1024) {
  Schema s;
  s.k = Schema::K::kArray;
  s.items = std::move(items);
  s.max_items = max_items;
  return make(std::move(s));
}
SP Either(std::vector<SP> alts) {
  Schema s;
  s.k = Schema::K::kEither;
  s.alts = std::move(alts);
  return make(std::move(s));
}
SP Free() {
  Schema s;
  s.k = Schema::K::kFree;
  return make(std::move(s));
}
SP StrList() { return Arr(Str()); }

std::string expected_name(const Schema& s) {
  switch (s.k) {
    case Schema::K::kString: return s.enums.empty() ? "a string" : "one of the listed strings";
    case Schema::K::kInt: return "an integer";
    case Schema::K::kNumber: return "a number";
    case Schema::K::kBool: return "a boolean";
    case Schema::K::kObject: return "a mapping";
    case Schema::K::kArray: return "a list";
    case Schema::K::kFree: return "a value";
    case Schema::K::kEither: break;
  }
  std::string out;
  for (size_t i = 0; i < s.alts.size(); ++i) {
    if (i) out += i + 1 == s.alts.size() ? " or " : ", ";
    out += expected_name(*s.alts[i]);
  }
  return out;
}

std::string join_enum(const std::vector<std::string>& v) {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) {
    if (i) out += ", ";
    out += v[i];
  }
  return out;
}

std::string fmt_num(double d) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", d);
  return buf;
}

// The whole document's schema.
SP config_schema() {
  static const SP schema = [] {
    SP confidence_gate = Obj({{"scope", Str(64)},
                              {"min_confidence", Num(0.0, 1.0)},
                              {"on_fail", Enum({"block", "escalate", "allow", "log"})}},
                             {"scope", "min_confidence", "on_fail"});
    SP hitl_gate = Obj({{"action_types", Arr(Str(128))},
                        {"action_type", Str(128)},
                        {"require_auth", Bool()},
                        {"auth_timeout_ms", Int(1, 86'400'000)},
                        {"on_timeout", Enum({"block", "allow", "escalate"})},
                        {"notify", Arr(Str(128))},
                        {"authorized_roles", Arr(Str(32))}},
                       {"require_auth"});
    SP gates_c = Arr(confidence_gate, 256);
    SP gates_h = Arr(hitl_gate, 256);
    SP layer = Obj({{"url", Str()}, {"timeout_ms", Int(1, 600'000)}}, {"url"});
    SP rate = Either({Int(0, 1'000'000), Str(64)});
    SP duration = Either({Int(0, 31'536'000), Str(64)});
    SP guest_limits = Obj({{"chat_rate", rate},
                           {"query_rate", rate},
                           {"session_duration", duration},
                           {"concurrent_sessions", Int(0, 100'000)},
                           {"capabilities", StrList()},
                           {"blocked", StrList()}});
    SP policy = Enum({"clamp", "reject"});
    SP agent_providers = Enum({"none", "local", "sim", "openai", "anthropic", "google", "mistral",
                               "ollama", "openrouter", "huggingface", "llamacpp", "llama.cpp",
                               "llama-cpp", "mlx", "mlx-lm", "vllm-mlx", "apple", "claude_oauth",
                               "groq"});
    SP channel = Free();  // OpenCastor channels carry provider-specific credentials keys

    return Obj({
        {"rcan_version", Str(32)},
        {"ruri", Str(512)},
        {"rrn", Str(64)},
        {"registry", Obj({{"rrn", Str(64)}, {"registry_url", Str()}})},
        {"robot", Obj({{"manufacturer", Str(256)},
                       {"name", Str(256)},
                       {"model", Str(256)},
                       {"type", Str(128)},
                       {"dof", Int(1, 1000)},
                       {"payload_kg", NonNeg()},
                       {"reach_mm", NonNeg()},
                       {"serial_pattern", Str(256)},
                       {"description", Str()},
                       {"arm_payload", Obj({{"fitted", Bool()},
                                            {"dof", Int(1, 1000)},
                                            {"payload_kg", NonNeg()},
                                            {"reach_mm", NonNeg()}})}})},
        {"capabilities", Either({Arr(Str(64)), Obj({{"motion", StrList()},
                                                    {"sensing", StrList()},
                                                    {"io", StrList()},
                                                    {"safety", StrList()}})})},
        {"metadata", Obj({{"robot_name", Str(256)},
                          {"robot_uuid", Str(64)},
                          {"author", Str(256)},
                          {"license", Str(256)},
                          {"ruri", Str(512)},
                          {"manufacturer", Str(256)},
                          {"model", Str(256)},
                          {"tags", StrList()},
                          {"created_at", Str(64)},
                          {"description", Str()},
                          {"version", Str(64)},
                          {"device_id", Str(64)}})},
        {"brain", Obj({{"provider", Enum({"openai", "anthropic", "google", "mistral", "local", "none"})},
                       {"model", Str(256)},
                       {"fast_brain", Str(256)},
                       {"api_key_env", Str(256)},
                       {"max_tokens", Int(1, 10'000'000)},
                       {"temperature", Num(0.0, 2.0)},
                       {"confidence_gates", gates_c},
                       {"hitl_gates", gates_h}})},
        {"agent", Obj({{"provider", agent_providers},
                       {"model", Str(256)},
                       {"vision_enabled", Bool()},
                       {"latency_budget_ms", Int(0, 600'000)},
                       {"safety_stop", Bool()},
                       {"api_key", Str()},
                       {"base_url", Str()},
                       {"agentic_vision", Bool()},
                       {"tools", StrList()},
                       {"secondary_models", Arr(Obj({{"provider", Str(128)},
                                                     {"model", Str(256)},
                                                     {"role", Str(128)}}))},
                       {"prompt_caching", Bool()},
                       {"cache_alert_threshold", Num(0.0, 1.0)},
                       {"min_obstacle_m", NonNeg()},
                       {"confidence_gates", gates_c},
                       {"hitl_gates", gates_h},
                       {"layers", Obj({{"reactive", layer}, {"fast", layer}, {"planner", layer}})},
                       {"runtimes", Arr(Obj({{"id", Str(128)},
                                             {"harness", Str(128)},
                                             {"default", Bool()},
                                             {"models", StrList()}}))}})},
        {"safety",
         Obj({{"local_safety_wins", Bool()},
              {"max_linear_speed_mps", Pos()},
              {"max_angular_speed_radps", Pos()},
              {"max_linear_x", Pos()},
              {"max_angular_z", Pos()},
              {"emergency_stop_distance", NonNeg()},
              {"estop_distance_mm", NonNeg()},
              {"max_speed_override", Num(0.0, 1.0)},
              {"collision_monitor_stop_m", NonNeg()},
              {"collision_monitor_slowdown_m", NonNeg()},
              {"obstacle_stop_cm", NonNeg()},
              {"estop_on_startup", Bool()},
              {"estop_clear_requires_presence", Bool()},
              {"joint_limits", Arr(Obj({{"name", Str(64)}, {"min", Num()}, {"max", Num()}},
                                       {"min", "max"}),
                                   64)},
              {"workspace", Obj({{"x_min", Num()}, {"x_max", Num()}, {"y_min", Num()},
                                 {"y_max", Num()}, {"z_min", Num()}, {"z_max", Num()}},
                                {"x_min", "x_max", "y_min", "y_max"})},
              {"limit_policy", Either({policy, Obj({{"speed", policy},
                                                    {"joints", policy},
                                                    {"workspace", policy}})})},
              {"heartbeat_timeout_ms", Int(100, 600'000)},
              {"command_ttl_default_ms", Int(0, 3'600'000)},
              // vendor keys used by the profiles
              {"max_walk_speed_mps", Pos()},
              {"estop_heartbeat_interval_ms", Int(1, 600'000)},
              {"estop_timeout_ms", Int(1, 600'000)},
              {"max_tcp_speed_mm_s", Pos()},
              {"collision_threshold_scale", Num(0.0, 1.0)},
              {"max_joint_torques_nm", Arr(NonNeg(), 64)},
              {"max_tcp_force_n", Pos()},
              {"fri_heartbeat_timeout_ms", Int(1, 600'000)},
              {"protective_stop_distance_mm", NonNeg()}})},
        {"watchdog", Obj({{"timeout_s", Int(1, 300)}, {"enabled", Bool()}})},
        {"hardware_safety", Obj({{"physical_estop", Bool()},
                                 {"hardware_watchdog_mcu", Bool()},
                                 {"sil_level", Either({Int(0, 4), Str(16)})},
                                 {"human_proximity_sensors", Bool()}})},
        {"bridge", Obj({{"type", Str(128)},
                        {"notes", Str(65536)},
                        {"hostname", Str(256)},
                        {"host", Str(256)},
                        {"username", Str(256)},
                        {"client_name", Str(256)},
                        {"ros_domain_id", Int(0, 232)},
                        {"namespace", Str(256)},
                        {"cmd_vel_topic", Str(256)},
                        {"odom_topic", Str(256)},
                        {"scan_topic", Str(256)},
                        {"nav2_action", Str(256)},
                        {"waypoint_action", Str(256)},
                        {"map_frame", Str(256)},
                        {"base_frame", Str(256)},
                        {"launch_package", Str(256)},
                        {"launch_file", Str(256)},
                        {"launch_args", Free()},
                        {"ros_driver", Str(256)},
                        {"fri_client_ip", Str(256)},
                        {"fri_port", Int(1, 65535)},
                        {"fri_library", Str(256)},
                        {"fri_version", Str(64)},
                        {"rtde_port", Int(1, 65535)},
                        {"dashboard_port", Int(1, 65535)},
                        {"recipe_file", Str(1024)}})},
        {"messaging", Obj({{"whatsapp", Obj({{"enabled", Bool()}, {"recipient", Str(256)}})},
                           {"slack", Obj({{"enabled", Bool()},
                                          {"channel", Str(256)},
                                          {"webhook_url", Str(2048)}})}})},
        // OpenCastor style (schemas/rcan-config.schema.json)
        {"physics",
         Obj({{"type", Enum({"differential_drive", "ackermann", "serial_manipulator",
                             "parallel_manipulator", "holonomic", "custom", "mecanum",
                             "four_wheel_drive", "self_balancing", "omni"})},
              {"dof", Int(1, 1000)},
              {"chassis", Obj({{"wheel_base_mm", NonNeg()},
                               {"wheelbase_mm", NonNeg()},
                               {"track_width_mm", NonNeg()},
                               {"wheel_radius_mm", NonNeg()}})},
              {"kinematics", Arr(Obj({{"id", Str(128)},
                                      {"length_mm", NonNeg()},
                                      {"mass_g", NonNeg()},
                                      {"axis", Enum({"x", "y", "z"})},
                                      {"limits_deg", Arr(Num(), 2)}},
                                     {"id", "length_mm", "axis"}),
                                 64)}})},
        {"drivers", Arr(Obj({{"id", Str(128)},
                             {"link_id", Str(128)},
                             {"protocol", Str(128)},
                             {"port", Either({Int(0, 65535), Str(256)})},
                             {"address", Str(256)},
                             {"frequency", Int(0, 100'000'000)},
                             {"baud_rate", Int(0, 100'000'000)},
                             {"hardware_id", Int(0, 1'000'000)}},
                            {"protocol"}),
                        64)},
        {"network", Obj({{"telemetry_stream", Bool()},
                         {"sim_to_real_sync", Bool()},
                         {"allow_remote_override", Bool()}})},
        {"rcan_protocol", Obj({{"port", Int(1, 65535)},
                               {"capabilities", Arr(Str(64))},
                               {"enable_mdns", Bool()},
                               {"enable_jwt", Bool()},
                               {"registry", Str()},
                               {"channel_admin_scope", Str(64)}})},
        {"tiered_brain", Obj({{"planner_interval", Int(1, 1'000'000)},
                              {"uncertainty_threshold", Num(0.0, 1.0)}})},
        {"reactive", Obj({{"hailo_vision", Bool()},
                          {"hailo_confidence", Num(0.0, 1.0)},
                          {"hailo_model_path", Str(1024)},
                          {"hailo_stop_distance_m", NonNeg()},
                          {"hailo_warn_distance_m", NonNeg()},
                          {"hailo_calibration", NonNeg()},
                          {"min_obstacle_m", NonNeg()},
                          {"fallback_provider", Obj({{"provider", Str(128)}, {"model", Str(256)}})}})},
        {"learner", Obj({{"enabled", Bool()},
                         {"provider", Str(128)},
                         {"model", Str(256)},
                         {"cadence", Str(64)},
                         {"cadence_n", Int(1, 1'000'000)},
                         {"max_retries", Int(0, 1000)},
                         {"auto_apply_config", Bool()},
                         {"auto_apply_behavior", Bool()},
                         {"auto_apply_code", Bool()}})},
        {"camera", Obj({{"type", Str(128)},
                        {"resolution", Arr(Int(1, 100'000), 2)},
                        {"framerate", Int(1, 10'000)},
                        {"depth_enabled", Bool()},
                        {"fps", Int(1, 10'000)},
                        {"imu_enabled", Bool()}})},
        {"audio", Obj({{"tts_enabled", Bool()},
                       {"engine", Str(128)},
                       {"language", Str(64)},
                       {"output_device", Str(256)}})},
        {"channels", Obj({{"whatsapp", channel},
                          {"telegram", channel},
                          {"discord", channel},
                          {"slack", channel}})},
        {"agent_roster", Arr(Obj({{"name", Str(128)}, {"enabled", Bool()}, {"config", Free()}},
                                 {"name", "enabled"}),
                             256)},
        {"swarm", Obj({{"enabled", Bool()},
                       {"sync_interval_s", Num(1.0)},
                       {"patch_sync", Bool()},
                       {"shared_memory_path", Str(1024)},
                       // seed §5.2 (docs/FLEET.md)
                       {"swarm_id", Str(128)},
                       {"member_id", Str(128)},
                       {"members", Arr(Str(128), 256)},
                       {"leader", Str(128)},
                       {"formation", Str(64)},
                       {"join_policy", Enum({"open", "approval", "closed"})},
                       {"heartbeat_ms", Int(50, 60'000)},
                       {"leader_timeout_ms", Int(200, 600'000)}})},
        {"mqtt", Obj({{"enabled", Bool()},
                      {"broker", Str(512)},
                      {"client_id", Str(128)},
                      {"topic_prefix", Str(256)},
                      {"keepalive_s", Int(5, 3600)},
                      {"username", Str(256)},
                      {"password_file", Str()},
                      {"tls", Obj({{"ca_file", Str()}, {"cert_file", Str()}, {"key_file", Str()}})},
                      {"reconnect", Obj({{"min_s", Int(1, 3600)}, {"max_s", Int(1, 3600)}})},
                      {"telemetry_hz", Int(0, 50)},
                      {"publish_audit", Bool()},
                      {"estop_qos", Int(1, 2)}})},
        {"fleet", Obj({{"fleet_id", Str(128)},
                       {"member_id", Str(128)},
                       {"robots", Arr(Str(128), 10'000)},
                       {"access_mode", Enum({"coordinated", "independent"})},
                       {"commands", Obj({{"broadcast", Bool()},
                                         {"individual", Bool()},
                                         {"choreographed", Bool()}})}},
                      {"fleet_id", "robots"})},
        {"connection", Free()},
        {"notes", Either({Str(65536), Free()})},
        {"ros2", Obj({{"enabled", Bool()}, {"namespace", Str(256)}, {"domain_id", Int(0, 232)}})},
        // v1.5 blocks
        {"offline", Obj({{"grace_period_s", Int(0, 31'536'000)},
                         {"cross_owner_grace_s", Int(0, 31'536'000)},
                         {"max_key_ttl_s", Int(0, 31'536'000)},
                         {"issuer_url", Str(2048)},
                         {"issuer_poll_ms", Int(50, 3'600'000)},
                         {"issuer_timeout_ms", Int(50, 60'000)}})},
        {"control", Obj({{"fleet_policy", Enum({"role", "fleet_wins", "individual_wins"})},
                         {"handoff_window_s", Int(1, 3600)},
                         {"queue_max", Int(0, 1024)},
                         {"queue_wait_s", Int(1, 86400)},
                         {"max_session_s", Int(0, 31'536'000)},
                         {"transfer_window_s", Int(1, 31'536'000)},
                         {"consent_ttl_s", Int(1, 31'536'000)},
                         {"consent_webhook", Str(2048)}})},
        {"qos", Obj({{"ack_timeout_ms", Int(1, 600'000)},
                     {"max_retries", Int(0, 100)},
                     {"backoff_base_ms", Int(1, 600'000)}})},
        // seed §6.3 (top-level form)
        {"guest_limits", guest_limits},
        // this node's own blocks
        {"node", Obj({{"data_dir", Str()},
                      {"log_level", Enum({"trace", "debug", "info", "warn", "error"})}})},
        {"server", Obj({{"port", Int(1, 65535)},
                        {"bind", Str(256)},
                        {"io_threads", Int(1, 64)},
                        {"enable_mdns", Bool()},
                        {"tls", Obj({{"enabled", Bool()}, {"cert_file", Str()}, {"key_file", Str()}})},
                        {"limits", Obj({{"max_body_bytes", Int(1024, 64 << 20)},
                                        {"max_header_bytes", Int(1024, 1 << 20)},
                                        {"read_timeout_ms", Int(100, 600'000)},
                                        {"idle_timeout_ms", Int(100, 86'400'000)},
                                        {"max_connections", Int(1, 1'000'000)}})}})},
        {"grpc", Obj({{"enabled", Bool()},
                      {"port", Int(0, 65535)},
                      {"bind", Str(256)},
                      {"max_streams", Int(1, 100'000)},
                      {"module", Str()},
                      {"tls", Obj({{"enabled", Bool()},
                                   {"cert_file", Str()},
                                   {"key_file", Str()},
                                   {"client_ca_file", Str()}})}})},
        {"udp", Obj({{"enabled", Bool()},
                     {"port", Int(0, 65535)},
                     {"bind", Str(256)},
                     {"heartbeat", Bool()},
                     {"discovery", Bool()},
                     {"discovery_per_source_per_min", Int(1, 6000)}})},
        {"security",
         Obj({{"key_dir", Str()},
              {"replay_window_s", Int(5, 300)},
              {"msg_id_cache_size", Int(100, 10'000'000)},
              {"audit", Obj({{"dir", Str()},
                             {"chain_secret_file", Str()},
                             {"sync", Enum({"per_group", "interval"})},
                             {"sync_interval_ms", Int(1, 10'000)},
                             {"max_segment_bytes", Int(64 * 1024, 4.0 * 1024 * 1024 * 1024)},
                             {"retention", Obj({{"max_bytes", Int(0, 9.0e15)},
                                                {"max_age_days", Int(0, 36'500)}})}})},
              {"jwt", Obj({{"issuers", Arr(Obj({{"issuer", Str(512)},
                                                {"key_file", Str()},
                                                {"kind", Enum({"auto", "hs256_secret"})},
                                                {"kid", Str(128)}},
                                               {"issuer", "key_file"}),
                                           64)},
                           {"leeway_s", Int(0, 3600)}})},
              {"trusted_robot_keys", Arr(Obj({{"name", Str(128)},
                                              {"mldsa65_pub_file", Str()},
                                              {"ed25519_pub_file", Str()}},
                                             {"name"}),
                                         256)},
              {"trusted_signer_keys", Arr(Obj({{"name", Str(128)},
                                               {"mldsa65_pub_file", Str()},
                                               {"ed25519_pub_file", Str()}},
                                              {"name"}),
                                          256)},
              {"injection", Obj({{"use_defaults", Bool()},
                                 {"patterns", Arr(Either({Str(256), Obj({{"regex", Str(256)}},
                                                                        {"regex"})}),
                                                  512)}})},
              {"commitment", Obj({{"enabled", Bool()},
                                  {"key_mode", Enum({"classical", "quantum", "hybrid"})},
                                  {"qber_threshold", Num(0.0, 1.0)}})},
              {"key_rotation", Obj({{"overlap_s", Int(0, 31'536'000)},
                                    {"max_validity_days", Int(1, 36'500)},
                                    {"auto_rotate", Bool()}})},
              {"revocation", Obj({{"check_on_startup", Bool()},
                                  {"cache_ttl_s", Int(0, 31'536'000)},
                                  {"max_staleness_s", Int(0, 31'536'000)},
                                  {"quarantine_on_staleness", Bool()}})}})},
        {"rbac", Obj({{"grants", Obj({{"user_arm", Bool()},
                                      {"user_record", Bool()},
                                      {"leasee_training", Bool()},
                                      {"leasee_diagnostics", Bool()},
                                      {"owner_safety_config", Bool()}})},
                      {"rate_limits", Obj({{"guest", Int(0, 1'000'000)},
                                           {"user", Int(0, 1'000'000)},
                                           {"leasee", Int(0, 1'000'000)},
                                           {"owner", Int(0, 1'000'000)},
                                           {"creator", Int(0, 1'000'000)}})},
                      {"guest_limits", guest_limits}})},
        {"driver", Obj({{"type", Enum({"sim"})},
                        {"sim", Obj({{"wheel_base_m", Pos()},
                                     {"max_accel_mps2", Pos()},
                                     {"max_angular_accel_radps2", Pos()},
                                     {"tick_hz", Int(1, 1000)},
                                     {"telemetry_hz", Int(1, 100)},
                                     {"arm_joints", Int(1, 16)}})}})},
    });
  }();
  return schema;
}

// ---------------------------------------------------------------------------------------
// Document count. yaml-cpp 0.7's LoadAll() loops forever on a stray flow token at document
// level (e.g. a file starting with ","): each HandleNextDocument() yields a null document
// without consuming the token. So documents are counted with a bounded loop of our own.

class DiscardEvents : public YAML::EventHandler {
 public:
  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t, const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

// 0, 1 or 2 (= more than one). Throws YAML::Exception on syntax errors.
int count_documents(const std::string& text) {
  std::istringstream in(text);
  YAML::Parser parser(in);
  DiscardEvents discard;
  int n = 0;
  while (n < 2 && parser.HandleNextDocument(discard)) ++n;
  return n;
}

// ---------------------------------------------------------------------------------------
// Pass 1: YAML → typed JSON

class Validator {
 public:
  json::Value run(const YAML::Node& root) { return walk(root, *config_schema(), "", 0); }

  // Where a path was in the text (for pass-2 errors).
  const YAML::Mark* mark_of(const std::string& path) const {
    auto it = marks_.find(path);
    return it == marks_.end() ? nullptr : &it->second;
  }

  // Mark of the node being reported (pass-1 errors).
  std::optional<YAML::Mark> last_mark;

 private:
  [[noreturn]] void error(const YAML::Node& n, const std::string& path, std::string msg,
                          std::string reason) {
    last_mark = n.Mark();
    fail(path, std::move(msg), std::move(reason));
  }

  void count(const YAML::Node& n, const std::string& path, size_t depth) {
    if (++nodes_ > kMaxConfigNodes)
      error(n, path,
            "document too large: more than " + std::to_string(kMaxConfigNodes) +
                " nodes (alias expansion counts every use)",
            "too_large");
    if (depth > 64) error(n, path, "nesting too deep", "too_large");
  }

  void remember(const YAML::Node& n, const std::string& path) {
    if (marks_.size() < kMaxConfigNodes) marks_.emplace(path, n.Mark());
  }

  void check_tag(const YAML::Node& n, const std::string& path) {
    const std::string& tag = n.Tag();
    if (n.IsScalar()) {
      if (tag == "?" || tag == "!" || tag == "tag:yaml.org,2002:str") return;
    } else if (n.IsMap() || n.IsSequence()) {
      if (tag == "?" || tag.empty() || tag == "tag:yaml.org,2002:map" ||
          tag == "tag:yaml.org,2002:seq")
        return;
    } else {
      return;
    }
    error(n, path, "unsupported YAML tag \"" + printable(tag) + "\"", "wrong_type");
  }

  [[noreturn]] void wrong_type(const YAML::Node& n, const Schema& s, const std::string& path) {
    error(n, path, "expected " + expected_name(s) + ", got " + describe(n), "wrong_type");
  }

  json::Value walk(const YAML::Node& n, const Schema& s, const std::string& path, size_t depth) {
    count(n, path, depth);
    check_tag(n, path);
    remember(n, path);
    switch (s.k) {
      case Schema::K::kString: return walk_string(n, s, path);
      case Schema::K::kInt: return walk_int(n, s, path);
      case Schema::K::kNumber: return walk_number(n, s, path);
      case Schema::K::kBool: {
        if (!n.IsScalar()) wrong_type(n, s, path);
        Scalar sc = resolve(n);
        if (sc.kind != ScalarKind::kBool) wrong_type(n, s, path);
        return json::Value(sc.b);
      }
      case Schema::K::kObject: return walk_object(n, s, path, depth);
      case Schema::K::kArray: {
        if (!n.IsSequence()) wrong_type(n, s, path);
        if (n.size() > s.max_items)
          error(n, path, "too many items: " + std::to_string(n.size()) + " (at most " +
                             std::to_string(s.max_items) + ")",
                "out_of_range");
        json::Array out;
        size_t i = 0;
        for (const auto& item : n) {
          out.push_back(walk(item, *s.items, index_segment(path, i), depth + 1));
          ++i;
        }
        return json::Value(std::move(out));
      }
      case Schema::K::kEither: {
        for (const SP& alt : s.alts) {
          if (accepts_kind(n, *alt)) return walk(n, *alt, path, depth);
        }
        // Report against the alternative of the same YAML kind when there is one, so that
        // e.g. an out-of-range integer is reported as such.
        wrong_type(n, s, path);
      }
      case Schema::K::kFree: return walk_free(n, path, depth);
    }
    wrong_type(n, s, path);
  }

  static bool accepts_kind(const YAML::Node& n, const Schema& s) {
    switch (s.k) {
      case Schema::K::kObject: return n.IsMap();
      case Schema::K::kArray: return n.IsSequence();
      case Schema::K::kFree: return n.IsMap() || n.IsSequence() || n.IsScalar();
      case Schema::K::kEither: return false;
      case Schema::K::kString:
      case Schema::K::kInt:
      case Schema::K::kNumber:
      case Schema::K::kBool: break;
    }
    if (!n.IsScalar()) return false;
    Scalar sc = resolve(n);
    switch (s.k) {
      case Schema::K::kString: return sc.kind == ScalarKind::kString;
      case Schema::K::kInt: return sc.kind == ScalarKind::kInt;
      case Schema::K::kNumber: return sc.kind == ScalarKind::kInt || sc.kind == ScalarKind::kFloat;
      case Schema::K::kBool: return sc.kind == ScalarKind::kBool;
      default: return false;
    }
  }

  json::Value walk_string(const YAML::Node& n, const Schema& s, const std::string& path) {
    if (!n.IsScalar()) wrong_type(n, s, path);
    Scalar sc = resolve(n);
    if (sc.kind != ScalarKind::kString) {
      std::string msg = "expected " + expected_name(s) + ", got " + describe(n);
      if (sc.kind != ScalarKind::kNull) msg += " (quote it to make it a string)";
      error(n, path, msg, "wrong_type");
    }
    if (!json::valid_utf8(sc.text)) error(n, path, "string is not valid UTF-8", "invalid_value");
    if (sc.text.size() > s.max_len)
      error(n, path, "string too long: " + std::to_string(sc.text.size()) + " bytes (at most " +
                         std::to_string(s.max_len) + ")",
            "out_of_range");
    if (!s.enums.empty() && std::find(s.enums.begin(), s.enums.end(), sc.text) == s.enums.end())
      error(n, path,
            "expected one of " + join_enum(s.enums) + ", got \"" + printable(sc.text) + "\"",
            "invalid_value");
    return json::Value(std::move(sc.text));
  }

  void check_range(const YAML::Node& n, const Schema& s, const std::string& path, double v,
                   const std::string& shown) {
    bool low = s.min && (s.min_exclusive ? !(v > *s.min) : v < *s.min);
    bool high = s.max && v > *s.max;
    if (!low && !high) return;
    std::string range;
    if (s.min && s.max) {
      range = "between " + fmt_num(*s.min) + " and " + fmt_num(*s.max);
    } else if (s.min) {
      range = (s.min_exclusive ? "greater than " : "at least ") + fmt_num(*s.min);
    } else {
      range = "at most " + fmt_num(*s.max);
    }
    error(n, path, "out of range: " + shown + " (must be " + range + ")", "out_of_range");
  }

  json::Value walk_int(const YAML::Node& n, const Schema& s, const std::string& path) {
    if (!n.IsScalar()) wrong_type(n, s, path);
    Scalar sc = resolve(n);
    if (sc.kind != ScalarKind::kInt) wrong_type(n, s, path);
    if (sc.int_overflow)
      error(n, path, "out of range: " + printable(sc.text), "out_of_range");
    check_range(n, s, path, static_cast<double>(sc.i), printable(sc.text));
    return json::Value(sc.i);
  }

  json::Value walk_number(const YAML::Node& n, const Schema& s, const std::string& path) {
    if (!n.IsScalar()) wrong_type(n, s, path);
    Scalar sc = resolve(n);
    double v = 0;
    if (sc.kind == ScalarKind::kInt) {
      if (sc.int_overflow) error(n, path, "out of range: " + printable(sc.text), "out_of_range");
      v = static_cast<double>(sc.i);
    } else if (sc.kind == ScalarKind::kFloat) {
      v = sc.d;
    } else {
      wrong_type(n, s, path);
    }
    if (!std::isfinite(v))
      error(n, path, "expected a finite number, got " + printable(sc.text), "out_of_range");
    check_range(n, s, path, v, printable(sc.text));
    return json::Value(v);
  }

  // Keys: scalars only, unique, `<<` merge keys refused.
  std::string key_of(const YAML::Node& key, const std::string& path) {
    if (!key.IsScalar())
      error(key, path, "mapping keys must be strings, got " + describe(key), "wrong_type");
    const std::string& k = key.Scalar();
    if (k == "<<" && key.Tag() == "?")
      error(key, key_segment(path, k), "YAML merge keys (<<) are not supported", "unknown_key");
    if (!json::valid_utf8(k)) error(key, path, "key is not valid UTF-8", "invalid_value");
    return k;
  }

  json::Value walk_object(const YAML::Node& n, const Schema& s, const std::string& path,
                          size_t depth) {
    if (!n.IsMap()) wrong_type(n, s, path);
    json::Object out;
    std::set<std::string> seen;
    for (auto it = n.begin(); it != n.end(); ++it) {
      std::string k = key_of(it->first, path);
      std::string child = key_segment(path, k);
      if (!seen.insert(k).second) error(it->first, child, "duplicate key", "duplicate_key");
      const Schema* prop = nullptr;
      for (const auto& p : s.props) {
        if (p.first == k) {
          prop = p.second.get();
          break;
        }
      }
      if (prop == nullptr) error(it->first, child, "unknown key", "unknown_key");
      out.append_unchecked(k, walk(it->second, *prop, child, depth + 1));
    }
    for (const auto& r : s.required) {
      if (!seen.count(r))
        error(n, key_segment(path, r), "required key is missing", "missing_key");
    }
    return json::Value(std::move(out));
  }

  // Free-form blocks (no published key list): any keys, scalars typed, bounded depth.
  json::Value walk_free(const YAML::Node& n, const std::string& path, size_t depth) {
    if (depth > kMaxFreeDepth + 8) error(n, path, "nesting too deep", "too_large");
    if (n.IsMap()) {
      json::Object out;
      std::set<std::string> seen;
      for (auto it = n.begin(); it != n.end(); ++it) {
        std::string k = key_of(it->first, path);
        std::string child = key_segment(path, k);
        if (!seen.insert(k).second) error(it->first, child, "duplicate key", "duplicate_key");
        count(it->second, child, depth + 1);
        check_tag(it->second, child);
        out.append_unchecked(k, walk_free(it->second, child, depth + 1));
      }
      return json::Value(std::move(out));
    }
    if (n.IsSequence()) {
      json::Array out;
      size_t i = 0;
      for (const auto& item : n) {
        std::string child = index_segment(path, i++);
        count(item, child, depth + 1);
        check_tag(item, child);
        out.push_back(walk_free(item, child, depth + 1));
      }
      return json::Value(std::move(out));
    }
    if (!n.IsScalar()) return json::Value();
    Scalar sc = resolve(n);
    switch (sc.kind) {
      case ScalarKind::kNull: return json::Value();
      case ScalarKind::kBool: return json::Value(sc.b);
      case ScalarKind::kInt:
        if (sc.int_overflow) return json::Value(sc.text);
        return json::Value(sc.i);
      case ScalarKind::kFloat:
        if (!std::isfinite(sc.d)) return json::Value(sc.text);
        return json::Value(sc.d);
      case ScalarKind::kString: break;
    }
    if (!json::valid_utf8(sc.text)) error(n, path, "string is not valid UTF-8", "invalid_value");
    return json::Value(std::move(sc.text));
  }

  size_t nodes_ = 0;
  std::unordered_map<std::string, YAML::Mark> marks_;
};

// ---------------------------------------------------------------------------------------
// Pass 2: typed JSON → NodeConfig

// A position in the typed tree: the value (nullptr when absent) and its path.
struct At {
  const json::Value* v = nullptr;
  std::string path;

  At operator[](std::string_view key) const {
    const json::Value* child = (v != nullptr && v->is_object()) ? v->get(key) : nullptr;
    return At{child, key_segment(path, key)};
  }
  At operator[](size_t i) const {
    const json::Value* child =
        (v != nullptr && v->is_array() && i < v->as_array().size()) ? &v->as_array()[i] : nullptr;
    return At{child, index_segment(path, i)};
  }
  explicit operator bool() const { return v != nullptr; }
  size_t size() const { return v != nullptr && v->is_array() ? v->as_array().size() : 0; }
  bool is_array() const { return v != nullptr && v->is_array(); }
  bool is_object() const { return v != nullptr && v->is_object(); }
  bool is_string() const { return v != nullptr && v->is_string(); }
  bool is_int() const { return v != nullptr && v->is_int(); }

  std::string str(std::string def = {}) const { return v ? v->as_string() : def; }
  double num(double def = 0) const { return v ? v->to_double() : def; }
  std::optional<double> opt_num() const {
    return v ? std::optional<double>(v->to_double()) : std::nullopt;
  }
  bool flag(bool def) const { return v ? v->as_bool() : def; }
  // Integers are range-checked by the schema; these narrow within those ranges.
  uint32_t u32(uint32_t def) const { return v ? static_cast<uint32_t>(v->as_int()) : def; }
  std::optional<uint32_t> opt_u32() const {
    return v ? std::optional<uint32_t>(static_cast<uint32_t>(v->as_int())) : std::nullopt;
  }
  uint64_t u64(uint64_t def) const { return v ? static_cast<uint64_t>(v->as_int()) : def; }
  std::vector<std::string> strs() const {
    std::vector<std::string> out;
    if (v != nullptr && v->is_array())
      for (const auto& e : v->as_array()) out.push_back(e.as_string());
    return out;
  }
};

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

LimitPolicy policy_of(const std::string& s) {
  return s == "clamp" ? LimitPolicy::kClamp : LimitPolicy::kReject;
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
  if (is_one_of(unit, {"s", "sec", "second"})) window = 1;
  else if (is_one_of(unit, {"m", "min", "minute"})) window = 60;
  else if (is_one_of(unit, {"h", "hr", "hour"})) window = 3600;
  else if (is_one_of(unit, {"d", "day"})) window = 86400;
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
    fail(a.path, "expected a duration like \"15min\", \"900s\" or \"1h30m\", got \"" +
                     printable(s) + "\"",
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
    if (is_one_of(unit, {"s", "sec", "secs", "second", "seconds"})) mult = 1;
    else if (is_one_of(unit, {"m", "min", "mins", "minute", "minutes"})) mult = 60;
    else if (is_one_of(unit, {"h", "hr", "hrs", "hour", "hours"})) mult = 3600;
    else if (is_one_of(unit, {"d", "day", "days"})) mult = 86400;
    else bad();
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
           "invalid scope \"" + printable(gate.scope) + "\" (lower-case name like control, nav, admin)",
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
    if (g["action_type"]) gate.action_types.push_back(g["action_type"].str());
    else gate.action_types = g["action_types"].strs();
    gate.require_auth = g["require_auth"].flag(true);
    if (gate.require_auth && gate.action_types.empty())
      fail(g["action_types"].path, "a gate with require_auth needs at least one action type",
           "missing_key");
    for (size_t j = 0; j < gate.action_types.size(); ++j) {
      if (gate.action_types[j].empty())
        fail(g["action_types"][j].path, "empty action type", "invalid_value");
    }
    gate.auth_timeout_ms = g["auth_timeout_ms"].u32(30000);
    gate.on_timeout = g["on_timeout"].str("block") == "allow" ? HitlOnTimeout::kAllow
                                                               : HitlOnTimeout::kBlock;
    gate.notify = g["notify"].strs();
    if (At roles = g["authorized_roles"]) {
      gate.authorized_roles.clear();
      for (size_t j = 0; j < roles.size(); ++j) {
        std::string name = roles[j].str();
        std::optional<Role> r = role_from_name(name);
        if (!r)
          fail(roles[j].path, "unknown role \"" + printable(name) + "\"", "invalid_value");
        if (*r != Role::kOwner && *r != Role::kCreator)
          fail(roles[j].path,
               "HiTL approval needs OWNER or CREATOR (seed §16.4); authorized_roles may only "
               "narrow that set, not add " + std::string(role_name(*r)),
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

// Two spellings of one setting: both present and different → error.
template <typename T>
void same_or_fail(const At& a, const T& va, const At& b, const T& vb) {
  if (a && b && !(va == vb))
    fail(b.path, "conflicts with " + a.path + " (give one of them)", "invalid_value");
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
  if (!c.mqtt.client_id.empty() && !node::valid_topic_segment(c.mqtt.client_id))
    fail(mq["client_id"].path, "expected 1-128 characters of [A-Za-z0-9._-]", "invalid_value");
  c.mqtt.topic_prefix = mq["topic_prefix"].str(c.mqtt.topic_prefix);
  if (!node::valid_topic_prefix(c.mqtt.topic_prefix))
    fail(mq["topic_prefix"].path, "expected '/'-separated segments of [A-Za-z0-9._-] (no wildcards)",
         "invalid_value");
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
    if (at && !node::valid_topic_segment(at.str()))
      fail(at.path, "expected 1-128 characters of [A-Za-z0-9._-], got \"" + printable(at.str()) + "\"",
           "invalid_value");
  };
  auto segments = [&](const At& list) {
    for (size_t i = 0; i < list.size(); ++i) segment(list[i]);
  };
  if (At fl = root["fleet"]) {
    if (!c.mqtt.enabled) fail(fl.path, "a fleet needs the MQTT transport (mqtt.enabled: true)", "invalid_value");
    segment(fl["fleet_id"]);
    segments(fl["robots"]);
    segment(fl["member_id"]);
    c.fleet.fleet_id = fl["fleet_id"].str();
    c.fleet.robots = fl["robots"].strs();
    c.fleet.member_id = fl["member_id"].str(c.ruri_parts.device_id);
    if (std::find(c.fleet.robots.begin(), c.fleet.robots.end(), c.fleet.member_id) == c.fleet.robots.end())
      fail(fl["robots"].path, "must list this robot (\"" + printable(c.fleet.member_id) + "\", fleet.member_id or the RURI device id)",
           "invalid_value");
    c.fleet.access_mode = fl["access_mode"].str(c.fleet.access_mode);
    c.fleet.broadcast = fl["commands"]["broadcast"].flag(true);
    c.fleet.individual = fl["commands"]["individual"].flag(true);
    c.fleet.choreographed = fl["commands"]["choreographed"].flag(true);
  }
  At sw = root["swarm"];
  if (At id = sw["swarm_id"]) {
    if (!c.mqtt.enabled) fail(id.path, "a swarm needs the MQTT transport (mqtt.enabled: true)", "invalid_value");
    segment(id);
    segments(sw["members"]);
    segment(sw["member_id"]);
    segment(sw["leader"]);
    c.swarm.swarm_id = id.str();
    c.swarm.members = sw["members"].strs();
    c.swarm.member_id = sw["member_id"].str(c.fleet.member_id.empty() ? c.ruri_parts.device_id : c.fleet.member_id);
    if (std::find(c.swarm.members.begin(), c.swarm.members.end(), c.swarm.member_id) == c.swarm.members.end())
      c.swarm.members.push_back(c.swarm.member_id);
    std::sort(c.swarm.members.begin(), c.swarm.members.end());
    c.swarm.members.erase(std::unique(c.swarm.members.begin(), c.swarm.members.end()), c.swarm.members.end());
    c.swarm.leader = sw["leader"].str(c.swarm.members.front());
    if (std::find(c.swarm.members.begin(), c.swarm.members.end(), c.swarm.leader) == c.swarm.members.end())
      fail(sw["leader"].path, "the leader must be one of swarm.members", "invalid_value");
    c.swarm.formation = sw["formation"].str(c.swarm.formation);
    c.swarm.join_policy = sw["join_policy"].str(c.swarm.join_policy);
    c.swarm.heartbeat_ms = sw["heartbeat_ms"].u32(c.swarm.heartbeat_ms);
    c.swarm.leader_timeout_ms = sw["leader_timeout_ms"].u32(c.swarm.leader_timeout_ms);
    if (c.swarm.leader_timeout_ms < 2 * c.swarm.heartbeat_ms)
      fail(sw["leader_timeout_ms"].path, "must be at least twice swarm.heartbeat_ms", "out_of_range");
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
    fail(u["enabled"].path, "udp is enabled but both heartbeat and discovery are off", "invalid_value");
  if (c.grpc.enabled && c.grpc.port != 0 && c.grpc.port == c.server.port)
    fail(g["port"].path, "must differ from server.port (" + std::to_string(c.server.port) + ")", "invalid_value");
}

NodeConfig build(const json::Value& root_value, const ConfigOptions& opts) {
  NodeConfig c;
  At root{&root_value, ""};
  const std::string& base = opts.base_dir;

  // --- version and identity
  At ver = root["rcan_version"];
  if (!ver) fail("rcan_version", "required key is missing", "missing_key");
  if (!version_ok(ver.str()))
    fail(ver.path, "expected a version like \"1.2\" or \"1.3.0\", got \"" + printable(ver.str()) + "\"",
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
      fail(id_at.path, "the device id substituted for {device_id} must be 8 lower-case hex "
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

  // --- robot
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
  if (At d = robot["dof"]) c.robot.dof = d.u32(0);
  else if (At pd = root["physics"]["dof"]) c.robot.dof = pd.u32(0);
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

  // --- capabilities
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
    fail(proto_caps.path, "capabilities are given twice (capabilities and rcan_protocol.capabilities)",
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

  // --- node / server
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
  c.server.enable_mdns = server["enable_mdns"] ? server["enable_mdns"].flag(false)
                                                : proto["enable_mdns"].flag(false);
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

  // --- security
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
  if (aud["dir"] && aud["dir"].str().empty()) fail(aud["dir"].path, "must not be empty", "invalid_value");
  if (aud["chain_secret_file"] && aud["chain_secret_file"].str().empty())
    fail(aud["chain_secret_file"].path, "must not be empty", "invalid_value");
  c.security.audit.sync_policy = aud["sync"].str("per_group") == "interval"
                                     ? audit::SyncPolicy::kInterval
                                     : audit::SyncPolicy::kPerGroup;
  c.security.audit.sync_interval_ms = aud["sync_interval_ms"].u32(c.security.audit.sync_interval_ms);
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

  // --- rbac
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

  // --- agent / brain
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
      fail(brain[k].path, std::string("gates are given twice (agent.") + k + " and brain." + k + ")",
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

  // --- safety
  At s = root["safety"];
  if (At lsw = s["local_safety_wins"]; lsw && !lsw.flag(true))
    fail(lsw.path, "must be true: local safety always wins over network commands",
         "invalid_value");
  same_or_fail(s["max_linear_speed_mps"], s["max_linear_speed_mps"].num(), s["max_linear_x"],
               s["max_linear_x"].num());
  same_or_fail(s["max_angular_speed_radps"], s["max_angular_speed_radps"].num(),
               s["max_angular_z"], s["max_angular_z"].num());
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
  if (s["emergency_stop_distance"]) sf.estop_distance_m = s["emergency_stop_distance"].num();
  else if (s["estop_distance_mm"]) sf.estop_distance_m = s["estop_distance_mm"].num() / 1000.0;
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

  // --- driver
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

  // --- v1.5 blocks
  At off = root["offline"];
  c.offline.grace_period_s = off["grace_period_s"].u32(c.offline.grace_period_s);
  c.offline.cross_owner_grace_s = off["cross_owner_grace_s"].u32(c.offline.cross_owner_grace_s);
  c.offline.max_key_ttl_s = off["max_key_ttl_s"].u32(c.offline.max_key_ttl_s);
  c.offline.issuer_url = off["issuer_url"].str();
  c.offline.issuer_poll_ms = off["issuer_poll_ms"].u32(c.offline.issuer_poll_ms);
  c.offline.issuer_timeout_ms = off["issuer_timeout_ms"].u32(c.offline.issuer_timeout_ms);
  if (!c.offline.issuer_url.empty() && !node::parse_http_url(c.offline.issuer_url).ok())
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
  if (!c.control.consent_webhook.empty() && !node::parse_http_url(c.control.consent_webhook).ok())
    fail(ctl["consent_webhook"].path, "must be an http:// URL", "invalid_value");
  At qos = root["qos"];
  c.qos.ack_timeout_ms = qos["ack_timeout_ms"].u32(c.qos.ack_timeout_ms);
  c.qos.max_retries = qos["max_retries"].u32(c.qos.max_retries);
  c.qos.backoff_base_ms = qos["backoff_base_ms"].u32(c.qos.backoff_base_ms);

  parse_fleet_blocks(root, base, c);

  // --- kept blocks
  for (const char* k : {"bridge", "hardware_safety", "messaging", "metadata", "physics", "drivers",
                        "network", "tiered_brain", "reactive", "learner", "camera", "audio",
                        "channels", "agent_roster", "swarm", "connection", "notes", "ros2"}) {
    if (At b = root[k]) c.kept.set(k, *b.v);
  }

  derive_paths(c);
  return c;
}

std::string location(const YAML::Mark& m) {
  if (m.is_null() || m.line < 0) return {};
  return " (line " + std::to_string(m.line + 1) + ", column " + std::to_string(m.column + 1) + ")";
}

Error make_error(const std::string& path, const std::string& msg, const std::string& reason,
                 const std::string& loc) {
  std::string text = path.empty() ? msg : path + ": " + msg;
  return Error(ErrorCode::kSchemaValidationFailed, text + loc, path, reason);
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API

GuestLimits GuestLimitsConfig::to_guest_limits() const {
  auto per_min = [](const RateSpec& r) -> uint32_t {
    if (r.count == 0 || r.window_s == 0) return 0;
    uint64_t v = static_cast<uint64_t>(r.count) * 60 / r.window_s;
    return static_cast<uint32_t>(std::clamp<uint64_t>(v, 1, UINT32_MAX));
  };
  GuestLimits g;
  g.chat_per_minute = per_min(chat_rate);
  g.query_per_minute = per_min(query_rate);
  g.session_seconds = session_duration_s;
  g.concurrent_sessions = concurrent_sessions;
  g.capabilities = capabilities;
  g.blocked = blocked;
  return g;
}

uint32_t RateLimits::for_role(Role r) const {
  switch (r) {
    case Role::kGuest: return guest;
    case Role::kUser: return user;
    case Role::kLeasee: return leasee;
    case Role::kOwner: return owner;
    case Role::kCreator: return creator;
  }
  return guest;
}

const std::vector<std::string>& default_injection_patterns() {
  static const std::vector<std::string> patterns{
      "ignore previous instructions",
      "ignore all previous instructions",
      "ignore the above",
      "disregard all prior",
      "disregard previous instructions",
      "forget your instructions",
      "system prompt",
      "you are now",
      "act as an unrestricted",
      "developer mode",
      "override safety",
      "disable safety",
      "bypass the safety",
      "new instructions:",
      "<|im_start|>",
      "[system]",
  };
  return patterns;
}

std::string_view limit_policy_name(LimitPolicy p) {
  return p == LimitPolicy::kClamp ? "clamp" : "reject";
}
std::string_view gate_on_fail_name(GateOnFail f) {
  switch (f) {
    case GateOnFail::kBlock: return "block";
    case GateOnFail::kEscalate: return "escalate";
    case GateOnFail::kAllow: return "allow";
  }
  return "block";
}
std::string_view hitl_on_timeout_name(HitlOnTimeout t) {
  return t == HitlOnTimeout::kAllow ? "allow" : "block";
}

Result<NodeConfig> parse_config_text(std::string_view yaml, const ConfigOptions& opts) {
  if (yaml.size() > kMaxConfigBytes)
    return make_error("", "config file too large: " + std::to_string(yaml.size()) +
                              " bytes (at most " + std::to_string(kMaxConfigBytes) + ")",
                      "too_large", "");
  if (yaml.find('\0') != std::string_view::npos)
    return make_error("", "config file contains a NUL byte", "malformed_yaml", "");
  Validator v;
  try {
    const std::string text(yaml);
    int ndocs = count_documents(text);
    if (ndocs > 1)
      return make_error("", "unexpected content after the first YAML document (one document only)",
                        "malformed_yaml", "");
    YAML::Node doc = ndocs == 0 ? YAML::Node() : YAML::Load(text);
    if (!doc.IsDefined() || doc.IsNull())
      return make_error("", "the config file is empty", "missing_key", "");
    if (!doc.IsMap())
      return make_error("", "the config file must be a YAML mapping, got " + describe(doc),
                        "wrong_type", location(doc.Mark()));
    json::Value typed = v.run(doc);
    NodeConfig cfg = build(typed, opts);
    cfg.source = opts.source_name;
    return cfg;
  } catch (const ConfigError& e) {
    std::string loc = v.last_mark ? location(*v.last_mark) : std::string();
    if (loc.empty()) {
      // Pass-2 errors: the mark of the path, or of its nearest recorded parent.
      std::string p = e.path;
      while (!p.empty()) {
        if (const YAML::Mark* m = v.mark_of(p)) {
          loc = location(*m);
          break;
        }
        size_t cut = p.find_last_of(".[");
        if (cut == std::string::npos) break;
        p.resize(cut);
      }
    }
    return make_error(e.path, e.message, e.reason, loc);
  } catch (const YAML::DeepRecursion& e) {
    return make_error("", "YAML nesting too deep", "too_large", location(e.mark));
  } catch (const YAML::Exception& e) {
    return make_error("", "malformed YAML: " + printable(e.msg, 200), "malformed_yaml",
                      location(e.mark));
  } catch (const std::bad_alloc&) {
    return make_error("", "config too large (out of memory)", "too_large", "");
  } catch (const std::exception& e) {
    return make_error("", std::string("cannot parse config: ") + e.what(), "malformed_yaml", "");
  }
}

Result<NodeConfig> load_config(const std::string& path, ConfigOptions opts) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    return Error(ErrorCode::kSchemaValidationFailed,
                 "cannot read config file " + path + ": not a regular file", "", "io_error");
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return Error(ErrorCode::kSchemaValidationFailed,
                 "cannot read config file " + path + ": " + std::strerror(errno), "", "io_error");
  std::string text;
  text.resize(kMaxConfigBytes + 1);
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<size_t>(in.gcount()));
  if (in.bad())
    return Error(ErrorCode::kSchemaValidationFailed, "cannot read config file " + path, "",
                 "io_error");
  if (opts.base_dir.empty()) {
    fs::path abs = fs::absolute(fs::path(path), ec);
    opts.base_dir = (ec ? fs::path(path) : abs).parent_path().lexically_normal().string();
  }
  if (opts.source_name == "<text>") opts.source_name = path;
  Result<NodeConfig> r = parse_config_text(text, opts);
  if (!r.ok()) {
    Error e = r.error();
    e.message = path + ": " + e.message;
    return e;
  }
  return r;
}

std::string_view default_config_yaml() {
  // Keep in step with examples/sim-robot.rcan.yaml (config_test checks they load alike).
  static constexpr std::string_view text = R"yaml(rcan_version: "1.2"
ruri: rcan://local.rcan/rcan/sim-rover/{device_id}
robot:
  name: sim-rover
  manufacturer: rcan
  model: sim-rover
  type: mobile_differential_with_arm
  dof: 8
  description: Simulated differential-drive rover with a 6-joint arm
capabilities: [status, chat, teleop, nav, arm]
node:
  log_level: info
server:
  port: 8080
  bind: 127.0.0.1
  io_threads: 2
  enable_mdns: true
  limits:
    max_body_bytes: 65536
    max_header_bytes: 8192
    read_timeout_ms: 10000
    idle_timeout_ms: 60000
    max_connections: 1024
security:
  replay_window_s: 30
  msg_id_cache_size: 10000
  audit:
    sync: per_group
  jwt:
    leeway_s: 60
rbac:
  rate_limits: {guest: 10, user: 100, leasee: 500, owner: 1000, creator: 0}
  guest_limits:
    chat_rate: 10/minute
    query_rate: 30/minute
    session_duration: 15min
    concurrent_sessions: 3
    capabilities: [status_read, chat_text, basic_info]
    blocked: [control, camera_access, location_history]
safety:
  local_safety_wins: true
  max_linear_speed_mps: 0.5
  max_angular_speed_radps: 1.0
  emergency_stop_distance: 0.3
  joint_limits:
    - {name: joint1, min: -3.14, max: 3.14}
    - {name: joint2, min: -3.14, max: 3.14}
    - {name: joint3, min: -3.14, max: 3.14}
    - {name: joint4, min: -3.14, max: 3.14}
    - {name: joint5, min: -3.14, max: 3.14}
    - {name: joint6, min: -3.14, max: 3.14}
  workspace: {x_min: -5.0, x_max: 5.0, y_min: -5.0, y_max: 5.0}
  limit_policy: {speed: clamp, joints: reject, workspace: reject}
  estop_on_startup: false
  heartbeat_timeout_ms: 2000
watchdog:
  enabled: true
  timeout_s: 10
agent:
  provider: none
  confidence_gates: []
  hitl_gates: []
driver:
  type: sim
  sim:
    wheel_base_m: 0.3
    max_accel_mps2: 1.0
    max_angular_accel_radps2: 2.0
    tick_hz: 50
    telemetry_hz: 5
    arm_joints: 6
)yaml";
  return text;
}

Result<NodeConfig> default_config(const std::string& data_dir, std::string_view device_id) {
  if (data_dir.empty())
    return Error(ErrorCode::kSchemaValidationFailed, "node.data_dir: must not be empty",
                 "node.data_dir", "invalid_value");
  std::error_code ec;
  std::filesystem::path abs = std::filesystem::absolute(data_dir, ec);
  std::string dir = (ec ? std::filesystem::path(data_dir) : abs).lexically_normal().string();
  ConfigOptions opts;
  opts.device_id = device_id.empty() ? sha256_hex(dir).substr(0, 8) : std::string(device_id);
  opts.source_name = "<embedded default>";
  opts.default_data_dir = dir;
  std::string_view text = default_config_yaml();
  return parse_config_text(text, opts);
}

Result<std::string> default_data_dir() {
  auto env = [](const char* name) -> std::string {
    const char* v = std::getenv(name);
    return v != nullptr ? std::string(v) : std::string();
  };
  namespace fs = std::filesystem;
  if (std::string d = env("RCAND_DATA_DIR"); !d.empty()) {
    std::error_code ec;
    fs::path abs = fs::absolute(d, ec);
    return (ec ? fs::path(d) : abs).lexically_normal().string();
  }
  if (std::string x = env("XDG_DATA_HOME"); !x.empty() && x[0] == '/')
    return (fs::path(x) / "rcand").lexically_normal().string();
  std::string home = env("HOME");
  if (home.empty() || home[0] != '/') {
    struct passwd pw {};
    struct passwd* result = nullptr;
    std::vector<char> buf(16384);
    if (getpwuid_r(getuid(), &pw, buf.data(), buf.size(), &result) == 0 && result != nullptr &&
        result->pw_dir != nullptr && result->pw_dir[0] == '/')
      home = result->pw_dir;
  }
  if (home.empty() || home[0] != '/')
    return Error(ErrorCode::kSchemaValidationFailed,
                 "no data directory: set RCAND_DATA_DIR or HOME, or pass --data-dir",
                 "node.data_dir", "missing_key");
  return (fs::path(home) / ".local" / "share" / "rcand").lexically_normal().string();
}

Status apply_overrides(NodeConfig& cfg, std::optional<int> port,
                       std::optional<std::string> data_dir) {
  if (port) {
    // 0 asks the kernel for a free port (tests, several nodes on one host); the node logs it.
    if (*port < 0 || *port > 65535)
      return Error(ErrorCode::kSchemaValidationFailed,
                   "--port: out of range: " + std::to_string(*port) + " (must be between 0 and 65535)",
                   "server.port", "out_of_range");
  }
  if (data_dir && data_dir->empty())
    return Error(ErrorCode::kSchemaValidationFailed, "--data-dir: must not be empty",
                 "node.data_dir", "invalid_value");
  if (port) cfg.server.port = static_cast<uint16_t>(*port);
  if (data_dir) {
    std::error_code ec;
    std::filesystem::path abs = std::filesystem::absolute(*data_dir, ec);
    cfg.data_dir = (ec ? std::filesystem::path(*data_dir) : abs).lexically_normal().string();
    derive_paths(cfg);
  }
  return Status::Ok();
}

}  // namespace rcan::config
