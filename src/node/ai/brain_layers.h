// Brain layers (§16.3 escalation). A layer is an HTTP endpoint; the node POSTs the
// instruction and its context and gets back a new command, its ai block and a thought.
// The JSON contract (docs/AI.md §Brain layers):
//
//   request  {"layer": "planner", "instruction": "…",
//             "context": {"robot_ruri", "message_id", "from_layer", "scope", "min_confidence",
//                         "command": {…the refused payload…}, "ai": {…}|null, "thought_id"}}
//   response {"command": {"action": "…", …params},
//             "ai": {"provider", "model", "model_version"?, "confidence"?,
//                    "inference_latency_ms"?, "thought_id"?},
//             "thought": {"id"?, "reasoning"?, "instruction"?, "context_snapshot"?}}   (optional)
//
// The node forces ai.layer to the layer it asked and ai.escalated to true, and the thought's
// escalated_from to the refused command's thought (or message) id.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/result.h"
#include "transport/http_api.h"

namespace rcan::node {

// Layer order: reactive (0) < fast (1) < planner (2). -1 for anything else.
int layer_rank(std::string_view layer);
std::string_view layer_name(int rank);

struct LayerReply {
  json::Object command;  // has a non-empty string `action`
  json::Value ai;        // object
  json::Value thought;   // object or null
};

// Parses a layer's answer body (at most 64 KiB, depth 16). Errors name the field
// (kSchemaValidationFailed, kMalformedJson, kBodyTooLarge).
Result<LayerReply> parse_layer_reply(std::string_view body);

// The escalated COMMAND: a copy of `original` whose payload is the layer's command and whose
// ai block is the layer's, with layer = `layer` and escalated = true. The ai block is
// validated as on any COMMAND (§16.2).
Result<Message> escalated_message(const Message& original, const LayerReply& reply,
                                  std::string_view layer, const CodecLimits& limits = {});

// The request body sent to a layer.
json::Value layer_request(const Message& m, std::string_view to_layer,
                          const std::string& robot_ruri, const std::string& scope,
                          double min_confidence);

// The built-in simulated layer (`rcand --sim-layer`): answers every POST with the command it
// was given (or {"action":"status"}), an ai block naming provider "sim", model
// "sim-<layer>" and the configured confidence, and a thought explaining itself.
struct SimLayerOptions {
  std::string layer = "planner";
  double confidence = 0.95;
  int delay_ms = 0;  // answer late (timeout tests)
};

class SimLayer final : public transport::HttpHandler {
 public:
  explicit SimLayer(SimLayerOptions o) : opts_(std::move(o)) {}
  void handle(transport::HttpRequest req, Respond respond) override;
  uint64_t requests() const { return requests_.load(); }

 private:
  SimLayerOptions opts_;
  std::atomic<uint64_t> requests_{0};
};

}  // namespace rcan::node
