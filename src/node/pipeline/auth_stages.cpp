// Authentication (token, signature, §8.5 sender identity) and the replay window (pipeline.h).
#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "base/log.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

class ReplayStage final : public Stage {
 public:
  explicit ReplayStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "replay"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    const Message& m = *ctx->msg;
    bool safety = ctx->safety == SafetyAction::kEstop || ctx->safety == SafetyAction::kStop;
    int64_t ts = m.timestamp_ms;
    if (ctx->in.standing_estop && ctx->safety == SafetyAction::kEstop) {
      // A retained fleet ESTOP stands until it is cleared: a robot joining later obeys it.
      ctx->audit_detail.set("standing_fleet_estop_timestamp_ms", m.timestamp_ms);
      ts = svc_.clock.wall_ms();
    }
    auto v = svc_.replay.check(m.message_id, ts, safety, svc_.clock.wall_ms());
    if (!v.ok()) {
      // Replay and staleness refusals are audited without the payload.
      return refuse(
          svc_, ctx, v.error(),
          v.error().code == ErrorCode::kReplayDetected ? "REPLAY_DETECTED" : "MESSAGE_STALE");
    }
    if (v->duplicate_safety) ctx->audit_detail.set("duplicate_safety_message", true);
    // TTL: a message past timestamp + ttl is never dispatched.
    if (m.ttl_ms > 0 && svc_.clock.wall_ms() > m.timestamp_ms + m.ttl_ms && !safety) {
      return refuse(svc_, ctx,
                    Error(ErrorCode::kMessageStale, "the message's ttl_ms has expired", "ttl_ms"),
                    "MESSAGE_STALE");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class AuthStage final : public Stage {
 public:
  explicit AuthStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "auth"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->in.preauthenticated) {
      ctx->principal = *ctx->in.preauthenticated;
      int64_t now_s = svc_.clock.wall_ms() / 1000;
      if (ctx->principal.token_exp &&
          *ctx->principal.token_exp + svc_.auth.verify_options().leeway_s < now_s) {
        return refuse(
            svc_, ctx,
            Error(ErrorCode::kSessionExpired, "the stream's token has expired", "auth_token"),
            "AUTH_FAILED");
      }
    } else {
      auto p = svc_.authenticate(token_of(*ctx));
      if (!p.ok()) {
        return refuse(svc_, ctx, p.error(), "AUTH_FAILED");
      }
      ctx->principal = std::move(p).value();
    }
    svc_.ownership.cap(ctx->principal);  // a former owner's token no longer carries ownership
    auto sig = svc_.auth.check_signature(*ctx->msg);
    if (!sig.ok()) {
      return refuse(svc_, ctx, sig.error(), "AUTH_FAILED");
    }
    ctx->sig = *sig;
    if (ctx->sig.verified) {
      ctx->audit_detail.set("sig_alg", ctx->sig.alg);
      ctx->audit_detail.set("sig_kid", ctx->sig.kid);
    }
    auto sender = svc_.auth.sender(*ctx->msg, ctx->principal, ctx->sig);
    if (!sender.ok()) {
      return refuse(svc_, ctx, sender.error(), "AUTH_FAILED");
    }
    ctx->sender = std::move(sender).value();
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

}  // namespace

std::unique_ptr<Stage> make_replay_stage(NodeServices& services) {
  return std::make_unique<ReplayStage>(services);
}
std::unique_ptr<Stage> make_auth_stage(NodeServices& services) {
  return std::make_unique<AuthStage>(services);
}

}  // namespace rcan::node
