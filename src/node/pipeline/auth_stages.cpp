// Authentication (token, signature, §8.5 sender identity) and the replay window: the freshness
// look right after authentication, the replay memory after the rate limit (pipeline.h).
#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "node/vocabulary/refusal_ledger.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

bool is_stop(const Context& ctx) {
  return ctx.safety == SafetyAction::kEstop || ctx.safety == SafetyAction::kStop;
}

// The timestamp the replay window judges: the message's, except for a retained fleet ESTOP,
// which stands until it is cleared (a robot joining later obeys it), whatever its age.
int64_t replay_timestamp(NodeServices& svc, const std::shared_ptr<Context>& ctx) {
  if (ctx->in.standing_estop && ctx->safety == SafetyAction::kEstop) {
    ctx->audit_detail.set("standing_fleet_estop_timestamp_ms", ctx->msg->timestamp_ms);
    return svc.clock.wall_ms();
  }
  return ctx->msg->timestamp_ms;
}

Stage::Result refuse_replay(NodeServices& svc, const std::shared_ptr<Context>& ctx,
                            const Error& e) {
  // Replay and staleness refusals are audited without the payload.
  return refuse(svc, ctx, e,
                e.code == ErrorCode::kReplayDetected ? "REPLAY_DETECTED" : "MESSAGE_STALE");
}

// Right after authentication: a stale message, or one whose id its principal already used, is
// refused before anything else looks at it (a copy neither feeds a deadman nor spends its
// principal's rate budget). Nothing is remembered here.
class FreshnessStage final : public Stage {
 public:
  explicit FreshnessStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "freshness"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    const Message& m = *ctx->msg;
    bool safety = is_stop(*ctx);
    auto v = svc_.replay.peek(ctx->principal.key(), m.message_id, replay_timestamp(svc_, ctx),
                              safety, svc_.clock.wall_ms());
    if (!v.ok()) return refuse_replay(svc_, ctx, v.error());
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

// After authorisation, the guest limits and the rate limit: the message_id is remembered in its
// principal's memory (replay.h), so a message refused before here used up nothing. The check is
// made again, atomically with remembering (a copy may have come in meanwhile).
class ReplayStage final : public Stage {
 public:
  explicit ReplayStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "replay"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->replay_remembered) return Result::kContinue;  // an escalation's second pass
    const Message& m = *ctx->msg;
    const int64_t now = svc_.clock.wall_ms();
    auto v = svc_.replay.check(ctx->principal.key(), m.message_id, replay_timestamp(svc_, ctx),
                               is_stop(*ctx), now);
    if (!v.ok()) {
      if (v.error().code != ErrorCode::kRateLimited) return refuse_replay(svc_, ctx, v.error());
      ctx->audit_detail.set("retry_after_ms", svc_.replay.retry_after_ms(now));
      return refuse(svc_, ctx, v.error(), "RATE_LIMITED");
    }
    if (v->duplicate_safety) ctx->audit_detail.set("duplicate_safety_message", true);
    if (v->unremembered) ctx->audit_detail.set("replay_memory_full", true);
    ctx->replay_remembered = true;
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
      // Revoked since CONNECT: the stream is being closed too (Node, GrpcServer).
      if (Status s = svc_.check_revoked(ctx->principal); !s.ok())
        return refuse(svc_, ctx, s.error(), "AUTH_FAILED");
    } else {
      // The peer's address pays for tokens that fail verification (NodeServices::authenticate);
      // a stop never waits on that budget, and MQTT has no peer address (the broker's clients
      // authenticated to the broker).
      const bool unlimited = is_stop(*ctx) || ctx->in.transport == "mqtt";
      auto p = svc_.authenticate(
          token_of(*ctx), unlimited ? std::string() : RefusalLedger::source_of(ctx->in.remote));
      if (!p.ok()) {
        return refuse(svc_, ctx, p.error(), "AUTH_FAILED");
      }
      ctx->principal = std::move(p).value();
    }
    ctx->authenticated = true;
    svc_.control.ownership().cap(
        ctx->principal);  // a former owner's token no longer carries ownership
    auto sig = svc_.auth.check_signature(*ctx->msg, ctx->principal, ctx->in.require_bound_key);
    if (!sig.ok()) {
      return refuse(svc_, ctx, sig.error(), "AUTH_FAILED");
    }
    ctx->sig = *sig;
    if (ctx->sig.verified) {
      ctx->audit_detail.set("sig_alg", ctx->sig.alg);
      ctx->audit_detail.set("sig_kid", ctx->sig.kid);
      if (ctx->sig.bound_key) ctx->audit_detail.set("sig_bound_to_token", true);
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

std::unique_ptr<Stage> make_freshness_stage(NodeServices& services) {
  return std::make_unique<FreshnessStage>(services);
}
std::unique_ptr<Stage> make_replay_stage(NodeServices& services) {
  return std::make_unique<ReplayStage>(services);
}
std::unique_ptr<Stage> make_auth_stage(NodeServices& services) {
  return std::make_unique<AuthStage>(services);
}

}  // namespace rcan::node
