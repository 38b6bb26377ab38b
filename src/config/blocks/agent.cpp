// §16: `agent` (profile, OpenCastor and seed keys: the confidence and HiTL gates, the
// escalation layers) and the profile style's `brain`, whose gates are aliases of agent's
// (docs/CONFIG.md §agent, docs/AI.md).
#include <algorithm>
#include <regex>
#include <unordered_map>

#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

const Table<ConfidenceGate>& confidence_gate_rows() {
  using G = Rows<ConfidenceGate>;
  static const Table<ConfidenceGate> rows = {
      G::read("scope", Str(64),
              [](const At& a, ConfidenceGate& gate, Ctx&) {
                gate.scope = a.str();
                static const std::regex scope_re(R"(^[a-z][a-z0-9_.:-]*$)");
                if (!std::regex_match(gate.scope, scope_re))
                  fail(a.path,
                       "invalid scope \"" + printable(gate.scope) +
                           "\" (lower-case name like control, nav, admin)",
                       "invalid_value");
              })
          .required(),
      G::field("min_confidence", Num(0.0, 1.0), &ConfidenceGate::min_confidence).required(),
      G::read("on_fail", Enum({"block", "escalate", "allow", "log"}),
              [](const At& a, ConfidenceGate& gate, Ctx&) {
                std::string f = a.str();
                gate.on_fail = f == "block"      ? GateOnFail::kBlock
                               : f == "escalate" ? GateOnFail::kEscalate
                                                 : GateOnFail::kAllow;  // allow | log
              })
          .required(),
  };
  return rows;
}

// Scopes are unique across the list.
std::vector<ConfidenceGate> read_confidence_gates(const At& a, Ctx& x) {
  std::vector<ConfidenceGate> out;
  std::unordered_map<std::string, std::string> scope_at;
  for (size_t i = 0; i < a.size(); ++i) {
    At g = a[i];
    ConfidenceGate gate = element(confidence_gate_rows(), g, x);
    auto [it, inserted] = scope_at.emplace(gate.scope, g.path);
    if (!inserted)
      fail(g["scope"].path,
           "duplicate gate for scope \"" + gate.scope + "\" (also at " + it->second + ")",
           "invalid_value");
    out.push_back(std::move(gate));
  }
  return out;
}

void read_authorized_roles(const At& roles, HitlGate& gate, Ctx&) {
  if (!roles) return;
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

const Table<HitlGate>& hitl_gate_rows() {
  using H = Rows<HitlGate>;
  static const Table<HitlGate> rows = {
      H::check([](const At& g, HitlGate&, Ctx&) {
        if (g["action_types"] && g["action_type"])
          fail(g["action_type"].path, "give either action_types or action_type, not both",
               "invalid_value");
      }),
      H::field("action_types", Arr(Str(128)), &HitlGate::action_types),
      H::read("action_type", Str(128),
              [](const At& a, HitlGate& gate, Ctx&) {
                if (a) gate.action_types = {a.str()};
              }),
      H::field("require_auth", Bool(), &HitlGate::require_auth).required(),
      H::check([](const At& g, HitlGate& gate, Ctx&) {
        if (gate.require_auth && gate.action_types.empty())
          fail(g["action_types"].path, "a gate with require_auth needs at least one action type",
               "missing_key");
        for (size_t j = 0; j < gate.action_types.size(); ++j) {
          if (gate.action_types[j].empty())
            fail(g["action_types"][j].path, "empty action type", "invalid_value");
        }
      }),
      H::field("auth_timeout_ms", Int(1, 86'400'000), &HitlGate::auth_timeout_ms),
      H::read("on_timeout", Enum({"block", "allow", "escalate"}),
              [](const At& a, HitlGate& gate, Ctx&) {
                // escalate is read as block: there is no higher layer to wait for
                if (a)
                  gate.on_timeout =
                      a.str() == "allow" ? HitlOnTimeout::kAllow : HitlOnTimeout::kBlock;
              }),
      H::field("notify", Arr(Str(128)), &HitlGate::notify),
      H::read("authorized_roles", Arr(Str(32)), read_authorized_roles),
  };
  return rows;
}

// A list of gates, agent.<key> or its alias brain.<key> (the check in agent_rows() refuses
// both).
template <typename Gate>
Row<AgentConfig> gates(std::string key, const Table<Gate>& rows,
                       std::vector<Gate> AgentConfig::*member,
                       std::vector<Gate> (*read_list)(const At&, Ctx&)) {
  return Rows<AgentConfig>::read(key, Arr(object_of(rows), 256),
                                 [key, member, read_list](const At& a, AgentConfig& ag, Ctx& x) {
                                   ag.*member = read_list(a ? a : x.root["brain"][key], x);
                                 });
}

std::vector<HitlGate> read_hitl_gates(const At& a, Ctx& x) {
  std::vector<HitlGate> out;
  for (size_t i = 0; i < a.size(); ++i) out.push_back(element(hitl_gate_rows(), a[i], x));
  return out;
}

// agent.layers.{reactive, fast, planner}: escalation targets.
Row<AgentConfig> layer(std::string key, std::optional<AgentLayer> AgentConfig::*member) {
  using L = Rows<AgentLayer>;
  static const Table<AgentLayer> rows = {
      L::read("url", Str(),
              [](const At& a, AgentLayer& l, Ctx&) {
                l.url = a.str();
                if (l.url.rfind("http://", 0) != 0 && l.url.rfind("https://", 0) != 0)
                  fail(a.path, "expected an http:// or https:// URL", "invalid_value");
              })
          .required(),
      L::field("timeout_ms", Int(1, 600'000), &AgentLayer::timeout_ms),
  };
  return Rows<AgentConfig>::read(std::move(key), object_of(rows),
                                 [member](const At& a, AgentConfig& ag, Ctx& x) {
                                   if (a) ag.*member = element(rows, a, x);
                                 });
}

Table<AgentConfig> agent_rows() {
  using A = Rows<AgentConfig>;
  return {
      A::field("provider",
               Enum({"none", "local", "sim", "openai", "anthropic", "google", "mistral", "ollama",
                     "openrouter", "huggingface", "llamacpp", "llama.cpp", "llama-cpp", "mlx",
                     "mlx-lm", "vllm-mlx", "apple", "claude_oauth", "groq"}),
               &AgentConfig::provider),
      A::field("model", Str(256), &AgentConfig::model),
      A::field("latency_budget_ms", Int(0, 600'000), &AgentConfig::latency_budget_ms),
      A::field("safety_stop", Bool(), &AgentConfig::safety_stop),
      A::read("min_obstacle_m", NonNeg(),
              [](const At& a, AgentConfig& ag, Ctx& x) {
                At reactive = x.root["reactive"]["min_obstacle_m"];
                same_or_fail(a, a.num(), reactive, reactive.num());
                ag.min_obstacle_m = a ? a.opt_num() : reactive.opt_num();
              }),
      A::check([](const At& agent, AgentConfig&, Ctx& x) {
        for (const char* k : {"confidence_gates", "hitl_gates"}) {
          if (agent[k] && x.root["brain"][k])
            fail(x.root["brain"][k].path,
                 std::string("gates are given twice (agent.") + k + " and brain." + k + ")",
                 "invalid_value");
        }
      }),
      gates("confidence_gates", confidence_gate_rows(), &AgentConfig::confidence_gates,
            read_confidence_gates),
      gates("hitl_gates", hitl_gate_rows(), &AgentConfig::hitl_gates, read_hitl_gates),
      A::block("layers", Table<AgentConfig>{layer("reactive", &AgentConfig::reactive_layer),
                                            layer("fast", &AgentConfig::fast_layer),
                                            layer("planner", &AgentConfig::planner_layer)}),
      // OpenCastor and v3.2 keys, validated only
      A::schema_only("vision_enabled", Bool()),
      A::schema_only("api_key", Str()),
      A::schema_only("base_url", Str()),
      A::schema_only("agentic_vision", Bool()),
      A::schema_only("tools", StrList()),
      A::schema_only("secondary_models",
                     Arr(Obj({{"provider", Str(128)}, {"model", Str(256)}, {"role", Str(128)}}))),
      A::schema_only("prompt_caching", Bool()),
      A::schema_only("cache_alert_threshold", Num(0.0, 1.0)),
      A::schema_only("runtimes", Arr(Obj({{"id", Str(128)},
                                          {"harness", Str(128)},
                                          {"default", Bool()},
                                          {"models", StrList()}}))),
  };
}

Table<BrainConfig> brain_rows() {
  using B = Rows<BrainConfig>;
  return {
      B::field("provider", Enum({"openai", "anthropic", "google", "mistral", "local", "none"}),
               &BrainConfig::provider),
      B::field("model", Str(256), &BrainConfig::model),
      B::field("fast_brain", Str(256), &BrainConfig::fast_brain),
      B::field("api_key_env", Str(256), &BrainConfig::api_key_env),
      B::field("max_tokens", Int(1, 10'000'000), &BrainConfig::max_tokens),
      B::field("temperature", Num(0.0, 2.0), &BrainConfig::temperature),
      // read by agent.confidence_gates and agent.hitl_gates
      B::schema_only("confidence_gates", Arr(object_of(confidence_gate_rows()), 256)),
      B::schema_only("hitl_gates", Arr(object_of(hitl_gate_rows()), 256)),
  };
}

}  // namespace

Table<NodeConfig> agent_blocks() {
  using R = Rows<NodeConfig>;
  return {
      R::block("agent", agent_rows(), &NodeConfig::agent),
      R::block("brain", brain_rows(), &NodeConfig::brain),
  };
}

}  // namespace rcan::config::internal
