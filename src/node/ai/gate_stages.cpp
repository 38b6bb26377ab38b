// The §16 pipeline stages in the gate slot (docs/AI.md): the confidence gate (with the
// thought log and escalation to brain layers), the HiTL gate and the watermark.
#include "node/ai/gate_stages.h"

#include <chrono>

#include "base/clock.h"
#include "node/ai/ai_services.h"
#include "node/ai/brain_layers.h"
#include "node/services/node_services.h"
#include "rcan/crypto/watermark.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

bool gated_command(const Context& ctx) {
  return ctx.safety == SafetyAction::kNone && ctx.msg && ctx.msg->type == MessageType::kCommand;
}

class ConfidenceGateStage final : public Stage {
 public:
  explicit ConfidenceGateStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "confidence_gate"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (!gated_command(*ctx)) return Result::kContinue;
    Message& m = *ctx->msg;
    AiServices* ai = svc_.ai.get();
    // §16.5: a COMMAND may carry its thought ({id?, reasoning, instruction, context_snapshot});
    // it goes to the thought log, never to the driver. Escalated commands' thoughts were
    // stored by the escalation itself.
    const json::Value* thought = m.wire.find("thought");
    if (!thought || !thought->is_object()) thought = m.payload.find("thought");
    if (thought && !thought->is_object()) thought = nullptr;
    if (ai && m.ai && !ctx->audit_detail.find("escalation") && (thought || m.ai->thought_id)) {
      Thought t = thought_from_command(m, thought, svc_.clock.wall_ms());
      if (t.id.empty()) t.id = "th_" + new_uuid_v4();
      t.principal = ctx->principal.key();
      const std::string id = t.id;
      if (!ai->thoughts().put(std::move(t))) {
        return refuse(svc_, ctx,
                      Error(ErrorCode::kSchemaValidationFailed,
                            "thought id '" + id.substr(0, 64) + "' holds another sender's thought",
                            "ai.thought_id", "thought_id_taken"),
                      "MESSAGE_REJECTED");
      }
      if (!m.ai->thought_id) m.ai->thought_id = id;
    }
    m.payload.erase("thought");
    if (!ai) return Result::kContinue;
    const config::ConfidenceGate* gate = ai->gate_for(*ctx);
    if (!gate) return Result::kContinue;
    std::optional<double> confidence = m.ai ? m.ai->confidence : std::nullopt;
    if (!confidence) confidence = m.confidence;
    json::Object detail{{"scope", gate->scope},
                        {"min_confidence", gate->min_confidence},
                        {"confidence", confidence ? json::Value(*confidence) : json::Value()}};
    if (confidence && *confidence >= gate->min_confidence) {
      detail.set("result", "pass");
      ctx->audit_detail.set("confidence_gate", detail);
      return Result::kContinue;
    }
    std::string why = confidence ? "confidence " + json::dump(json::Value(*confidence)) +
                                       " is below " + json::dump(json::Value(gate->min_confidence))
                                 : std::string("no confidence was reported");
    switch (gate->on_fail) {
      case config::GateOnFail::kAllow:
        detail.set("result", "bypassed");
        ctx->audit_detail.set("confidence_gate", detail);
        ctx->gate_bypassed = true;
        return Result::kContinue;
      case config::GateOnFail::kBlock:
        detail.set("result", "blocked");
        ctx->audit_detail.set("confidence_gate", detail);
        return refuse(svc_, ctx,
                      Error(ErrorCode::kConfidenceGateFail,
                            why + " for the " + gate->scope + " confidence gate", "ai.confidence",
                            "confidence_below_gate"),
                      "CONFIDENCE_GATE_FAIL");
      case config::GateOnFail::kEscalate:
        break;
    }
    int rank = m.ai && m.ai->layer ? layer_rank(*m.ai->layer) : -1;
    auto above = ai->layer_above(rank);
    if (!above) {
      detail.set("result", "blocked");
      detail.set("escalation", "no higher brain layer is configured");
      ctx->audit_detail.set("confidence_gate", detail);
      return refuse(svc_, ctx,
                    Error(ErrorCode::kConfidenceGateFail,
                          why + " for the " + gate->scope +
                              " confidence gate and no higher brain layer is available",
                          "ai.confidence", "no_higher_layer"),
                    "CONFIDENCE_GATE_FAIL");
    }
    detail.set("result", "escalated");
    ctx->audit_detail.set("confidence_gate", detail);
    ai->escalate(ctx, *gate, above->first, above->second);
    return Result::kParked;
  }

 private:
  NodeServices& svc_;
};

class HitlGateStage final : public Stage {
 public:
  explicit HitlGateStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "hitl_gate"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (!gated_command(*ctx) || !svc_.ai) return Result::kContinue;
    if (!ctx->action) return Result::kContinue;     // only COMMANDs have one (authorize stage)
    const std::string& action = ctx->action->name;  // canonical: a synonym cannot slip past
    const config::HitlGate* gate = svc_.ai->hitl_gate_for(action);
    if (!gate) return Result::kContinue;
    if (!svc_.ai->hold(ctx, *gate, action)) {
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kReplayDetected,
                "a command with this message_id is already held for approval", "message_id"),
          "REPLAY_DETECTED");
    }
    return Result::kParked;
  }

 private:
  NodeServices& svc_;
};

// §16.6: every AI-produced COMMAND that reaches dispatch carries a watermark token in its
// payload and its record. A forwarded command (delegation chain) keeps the token it carries.
class WatermarkStage final : public Stage {
 public:
  explicit WatermarkStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "watermark"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (!gated_command(*ctx) || !svc_.ai || !ctx->msg->ai || !svc_.ai->has_watermark_key())
      return Result::kContinue;
    Message& m = *ctx->msg;
    const json::Value* existing = m.payload.find("watermark_token");
    bool forwarded = m.delegation_chain.is_array() && !m.delegation_chain.as_array().empty();
    if (forwarded && existing && existing->is_string() &&
        watermark::valid_format(existing->as_string())) {
      ctx->watermark_token = existing->as_string();
      ctx->audit_detail.set("watermark", json::Object{{"forwarded", true}});
      return Result::kContinue;
    }
    std::string thought_id = m.ai->thought_id.value_or(m.message_id);
    std::string ts = watermark::format_timestamp(wall_now());
    std::string token = svc_.ai->watermark(thought_id, ts);
    m.payload.set("watermark_token", token);
    ctx->watermark_token = token;
    ctx->audit_detail.set("watermark", json::Object{{"timestamp_iso", ts},
                                                    {"thought_id", thought_id},
                                                    {"rrn", svc_.settings.rrn}});
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

}  // namespace

std::vector<std::unique_ptr<Stage>> ai_stages(NodeServices& services) {
  std::vector<std::unique_ptr<Stage>> v;
  v.push_back(std::make_unique<ConfidenceGateStage>(services));
  v.push_back(std::make_unique<HitlGateStage>(services));
  v.push_back(std::make_unique<WatermarkStage>(services));
  return v;
}

}  // namespace rcan::node
