#include "node/ai/brain_layers.h"

#include <chrono>
#include <thread>

#include "base/clock.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

Error schema(const std::string& field, const std::string& msg) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field);
}

}  // namespace

int layer_rank(std::string_view layer) {
  if (layer == "reactive") return 0;
  if (layer == "fast") return 1;
  if (layer == "planner") return 2;
  return -1;
}

std::string_view layer_name(int rank) {
  switch (rank) {
    case 0:
      return "reactive";
    case 1:
      return "fast";
    case 2:
      return "planner";
    default:
      return "";
  }
}

Result<LayerReply> parse_layer_reply(std::string_view body) {
  auto v = json::parse(body, {.max_depth = 16, .max_bytes = 64 * 1024});
  if (!v.ok()) return v.error();
  if (!v->is_object()) return schema("", "a layer answer must be a JSON object");
  LayerReply r;
  const json::Value* cmd = v->get("command");
  if (!cmd || !cmd->is_object()) return schema("command", "command must be an object");
  const json::Value* action = cmd->get("action");
  if (!action || !action->is_string() || action->as_string().empty() ||
      action->as_string().size() > 128)
    return schema("command.action",
                  "command.action must be a non-empty string (at most 128 characters)");
  if (cmd->get("ai") || cmd->get("watermark_token"))
    return schema("command", "command may not carry ai or watermark_token");
  r.command = cmd->as_object();
  const json::Value* ai = v->get("ai");
  if (!ai || !ai->is_object()) return schema("ai", "ai must be an object");
  r.ai = *ai;
  if (const json::Value* t = v->get("thought"); t && !t->is_null()) {
    if (!t->is_object()) return schema("thought", "thought must be an object");
    r.thought = *t;
  }
  return r;
}

Result<Message> escalated_message(const Message& original, const LayerReply& reply,
                                  std::string_view layer, const CodecLimits& limits) {
  json::Object ai = reply.ai.as_object();
  ai.set("layer", std::string(layer));
  ai.set("escalated", true);
  json::Object m{{"version", "1.0.0"},       {"message_id", original.message_id},
                 {"type", "COMMAND"},        {"timestamp_ms", original.timestamp_ms},
                 {"payload", reply.command}, {"ai", ai}};
  if (original.ttl_ms > 0) m.set("ttl_ms", original.ttl_ms);
  auto decoded = decode_message(json::Value(m), limits);
  if (!decoded.ok()) return decoded.error();
  Message out = std::move(decoded).value();
  // Who sent it does not change: the escalation acts for the original sender.
  out.source_ruri = original.source_ruri;
  out.target_ruri = original.target_ruri;
  out.scope = original.scope;
  out.sender_type = original.sender_type;
  out.sender_type_explicit = original.sender_type_explicit;
  out.cloud_provider = original.cloud_provider;
  out.function_name = original.function_name;
  out.function_region = original.function_region;
  out.delegation_chain = original.delegation_chain;
  out.priority = original.priority;
  return out;
}

json::Value layer_request(const Message& m, std::string_view to_layer,
                          const std::string& robot_ruri, const std::string& scope,
                          double min_confidence) {
  std::string instruction;
  if (const json::Value* i = m.payload.find("instruction"); i && i->is_string())
    instruction = i->as_string();
  if (instruction.empty()) instruction = m.action();
  json::Object payload = m.payload;
  payload.erase("thought");
  json::Object ctx{
      {"robot_ruri", robot_ruri},
      {"message_id", m.message_id},
      {"from_layer", m.ai && m.ai->layer ? json::Value(*m.ai->layer) : json::Value()},
      {"scope", scope},
      {"min_confidence", min_confidence},
      {"command", payload},
      {"ai", m.ai ? m.ai->to_json() : json::Value()},
      {"thought_id", m.ai && m.ai->thought_id ? json::Value(*m.ai->thought_id) : json::Value()}};
  return json::Object{
      {"layer", std::string(to_layer)}, {"instruction", instruction}, {"context", ctx}};
}

void SimLayer::handle(transport::HttpRequest req, Respond respond) {
  requests_.fetch_add(1);
  transport::HttpResponse r;
  if (req.method != "POST") {
    r.status = 405;
    r.body = R"({"error":"POST a layer request"})";
    return respond(std::move(r));
  }
  auto v = json::parse(req.body, {.max_depth = 32, .max_bytes = 256 * 1024});
  if (!v.ok() || !v->is_object()) {
    r.status = 400;
    r.body = R"({"error":"the body must be a JSON object"})";
    return respond(std::move(r));
  }
  std::string instruction;
  if (const json::Value* i = v->get("instruction"); i && i->is_string())
    instruction = i->as_string().substr(0, 1024);
  json::Object command{{"action", "status"}};
  json::Value context = json::Object{};
  if (const json::Value* c = v->get("context"); c && c->is_object()) {
    context = *c;
    if (const json::Value* cmd = c->get("command"); cmd && cmd->is_object()) {
      const json::Value* a = cmd->get("action");
      if (a && a->is_string() && !a->as_string().empty()) {
        command = cmd->as_object();
        command.erase("ai");
        command.erase("watermark_token");
        command.erase("thought");
      }
    }
  }
  log(LogLevel::kInfo, "layer_request",
      json::Object{{"layer", opts_.layer}, {"instruction", instruction}});
  std::string action =
      command.find("action")->is_string() ? command.find("action")->as_string() : "status";
  std::string thought_id = "th_" + new_uuid_v4();
  json::Object ai{{"provider", "sim"},
                  {"model", "sim-" + opts_.layer},
                  {"model_version", "1"},
                  {"layer", opts_.layer},
                  {"confidence", opts_.confidence},
                  {"inference_latency_ms", opts_.delay_ms},
                  {"thought_id", thought_id}};
  json::Object thought{{"id", thought_id},
                       {"instruction", instruction},
                       {"reasoning", "the " + opts_.layer + " layer re-examined '" + instruction +
                                         "' with the full context and confirms action " + action},
                       {"context_snapshot", context}};
  json::Object out{{"command", command},
                   {"ai", ai},
                   {"thought", thought},
                   {"timestamp_ms", Clock::system().wall_ms()}};
  r.body = json::dump(json::Value(out));
  if (opts_.delay_ms > 0) {
    // Answer late without holding a transport thread.
    int delay = opts_.delay_ms;
    std::thread([respond, r, delay]() mutable {
      std::this_thread::sleep_for(std::chrono::milliseconds(delay));
      respond(std::move(r));
    }).detach();
    return;
  }
  respond(std::move(r));
}

}  // namespace rcan::node
