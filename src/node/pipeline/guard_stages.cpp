// The guards before dispatch: rate limits, the safety state, the injection screen (pipeline.h).
#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

class RateLimitStage final : public Stage {
 public:
  explicit RateLimitStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "rate_limit"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->safety != SafetyAction::kNone)
      return Result::kContinue;  // SAFETY is never rate-limited
    auto d = svc_.rate.take(ctx->principal.key(), svc_.rate_limit(ctx->principal.role),
                            svc_.clock.mono_ms());
    if (!d.allowed) {
      Error e(ErrorCode::kRateLimited,
              std::string(role_name(ctx->principal.role)) + " rate limit of " +
                  std::to_string(svc_.rate_limit(ctx->principal.role)) + " per minute reached");
      ctx->audit_detail.set("retry_after_ms", d.retry_after_ms);
      return refuse(svc_, ctx, e, "RATE_LIMITED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class SafetyStateStage final : public Stage {
 public:
  explicit SafetyStateStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "safety_state"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->safety != SafetyAction::kNone) return Result::kContinue;
    const Message& m = *ctx->msg;
    if (m.type != MessageType::kCommand) return Result::kContinue;
    bool moves = ctx->action && ctx->action->kind != ActionKind::kInformational;
    if (moves && svc_.act.estop_active()) {
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kCommandRejected, "ESTOP is active; RESUME (LEASEE or above) clears it",
                "", "estop_active"),
          "COMMAND_REJECTED");
    }
    if (!svc_.audit.available()) {
      return refuse(
          svc_, ctx,
          Error(
              ErrorCode::kAuditUnavailable,
              "the audit log cannot record; commands are refused until it can (ESTOP still works)"),
          "COMMAND_REJECTED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class InjectionStage final : public Stage {
 public:
  explicit InjectionStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "injection"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->safety != SafetyAction::kNone || ctx->msg->type != MessageType::kCommand)
      return Result::kContinue;
    if (auto hit = svc_.injection.scan(json::Value(ctx->msg->payload))) {
      ctx->audit_detail.set("pattern", *hit);
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kCommandRejected, "the command text matches a prompt-injection pattern",
                "payload", "prompt_injection"),
          "INJECTION_BLOCKED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

}  // namespace

std::unique_ptr<Stage> make_rate_limit_stage(NodeServices& services) {
  return std::make_unique<RateLimitStage>(services);
}
std::unique_ptr<Stage> make_safety_state_stage(NodeServices& services) {
  return std::make_unique<SafetyStateStage>(services);
}
std::unique_ptr<Stage> make_injection_stage(NodeServices& services) {
  return std::make_unique<InjectionStage>(services);
}

}  // namespace rcan::node
