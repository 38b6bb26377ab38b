// The first stages: the message's shape, the presence of a token, decoding (pipeline.h).
#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "rcan/ruri.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

class ShapeStage final : public Stage {
 public:
  explicit ShapeStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "shape"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    Status s = check_shape(ctx->in.body);
    if (!s.ok()) {
      return refuse(svc_, ctx, s.error(), "MESSAGE_REJECTED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

// A missing token is answered before anything else is validated (the live checker's order).
class TokenPresenceStage final : public Stage {
 public:
  explicit TokenPresenceStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "token"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->in.preauthenticated) return Result::kContinue;
    if (token_of(*ctx).empty()) {
      return refuse(svc_, ctx,
                    Error(ErrorCode::kAuthRequired, "a bearer token is required", "auth_token"),
                    "AUTH_FAILED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class DecodeStage final : public Stage {
 public:
  explicit DecodeStage(NodeServices& s) : svc_(s) {
    if (auto self = parse_ruri(s.settings.ruri); self.ok()) self_ = std::move(self).value();
  }
  const char* name() const override { return "decode"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    // The body becomes the message's wire object (no copy); from here on the stages read the
    // received members through wire_of().
    json::Value body = std::move(ctx->in.body);
    ctx->in.body = json::Value();
    auto m = decode_message(std::move(body), svc_.settings.codec);
    if (!m.ok()) {
      ctx->in.body = std::move(body);  // a refused message's members (the SDK answer's msg_id)
      return refuse(svc_, ctx, m.error(), "MESSAGE_REJECTED");
    }
    ctx->msg = std::move(m).value();
    Message& msg = *ctx->msg;
    if (msg.type == MessageType::kFleetCommand) {  // a fleet's command (fleet.cpp checks it)
      msg.type = MessageType::kCommand;
      ctx->fleet_command = true;
    }
    if (msg.type == MessageType::kInvoke) {  // a skill invocation runs as a COMMAND
      // The skill is payload.skill (the §19 page, rcan-py) or payload.skill_id with its
      // arguments in payload.args (the conformance suite's form).
      const char* skill_key = msg.payload.contains("skill") ? "skill" : "skill_id";
      const json::Value* skill = msg.payload.find(skill_key);
      if (skill && !skill->is_string()) {
        const std::string field = std::string("payload.") + skill_key;
        return refuse(svc_, ctx,
                      Error(ErrorCode::kSchemaValidationFailed, field + " must be a string", field),
                      "MESSAGE_REJECTED");
      }
      if (skill && msg.action().empty()) msg.payload.set("action", *skill);
      if (skill) ctx->skill_field = std::string("payload.") + skill_key;
      if (const json::Value* args = msg.payload.find("args"); args && !args->is_null()) {
        if (!args->is_object())
          return refuse(svc_, ctx,
                        Error(ErrorCode::kSchemaValidationFailed, "payload.args must be an object",
                              "payload.args"),
                        "MESSAGE_REJECTED");
        if (!msg.payload.contains("params")) msg.payload.set("params", *args);
      }
      msg.type = MessageType::kCommand;
      ctx->invoke = true;
    }
    ctx->safety = safety_action_of(msg);
    if (msg.priority == Priority::kSafety && ctx->safety == SafetyAction::kNone) {
      return refuse(svc_, ctx,
                    Error(ErrorCode::kSchemaValidationFailed,
                          "priority SAFETY is reserved for SAFETY messages (ESTOP, STOP, RESUME)",
                          "priority"),
                    "MESSAGE_REJECTED");
    }
    if (ctx->safety != SafetyAction::kNone) msg.priority = Priority::kSafety;
    // A message addressed to another robot is refused, whatever its token and signature say:
    // a signed command captured on one robot must not run on another that trusts the same
    // signer (docs/PROTOCOL.md §Addressing). ESTOP and STOP are honoured whatever they name —
    // stopping is always safe, and a mistyped target must not keep a robot moving.
    if (!msg.target_ruri.empty() && msg.target_ruri != "broadcast" &&
        ctx->safety != SafetyAction::kEstop && ctx->safety != SafetyAction::kStop) {
      std::string why = "this robot's identity is not a valid RURI";
      auto target = parse_ruri(msg.target_ruri);
      if (!self_ || !target.ok() || !addresses_robot(*target, *self_, &why)) {
        const char* field = msg.shape == WireShape::kSeed ? "target_ruri" : "target";
        return refuse(svc_, ctx,
                      Error(ErrorCode::kCommandRejected,
                            "the message is addressed to " + msg.target_ruri +
                                ", not this robot (" + svc_.settings.ruri + "): " + why,
                            field, "wrong_target"),
                      "MESSAGE_REJECTED");
      }
    }
    switch (msg.type) {
      case MessageType::kCommand:
      case MessageType::kSafety:
      case MessageType::kStatus:
      case MessageType::kHeartbeat:
        break;
      default:
        return refuse(svc_, ctx,
                      Error(ErrorCode::kSchemaValidationFailed,
                            "message type " + std::string(message_type_name(msg.type)) +
                                " is not accepted on " + ctx->in.route,
                            "type"),
                      "MESSAGE_REJECTED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
  std::optional<Ruri> self_;  // the robot's own identity (settings.ruri)
};

}  // namespace

std::unique_ptr<Stage> make_shape_stage(NodeServices& services) {
  return std::make_unique<ShapeStage>(services);
}
std::unique_ptr<Stage> make_token_stage(NodeServices& services) {
  return std::make_unique<TokenPresenceStage>(services);
}
std::unique_ptr<Stage> make_decode_stage(NodeServices& services) {
  return std::make_unique<DecodeStage>(services);
}

}  // namespace rcan::node
