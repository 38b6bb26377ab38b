#include "node/pipeline/guest_limits.h"

#include <algorithm>
#include <cctype>
#include <map>

#include "base/thread_annotations.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"

namespace rcan::node {

std::string guest_capability(const Message& m, const ActionSpec* action) {
  if (m.type == MessageType::kStatus || m.type == MessageType::kHeartbeat) return "status_read";
  return action ? action->guest_class : "control";
}

namespace {

class GuestLimitStage final : public Stage {
 public:
  explicit GuestLimitStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "guest_limits"; }
  Result run(const std::shared_ptr<Context>& ctx) override EXCLUDES(mu_) {
    if (ctx->safety != SafetyAction::kNone || ctx->principal.role != Role::kGuest)
      return Result::kContinue;
    const GuestLimits& g = svc_.settings.guest_limits;
    std::string what = guest_capability(*ctx->msg, ctx->action);
    ctx->audit_detail.set("guest_capability", what);
    bool allowed =
        std::find(g.capabilities.begin(), g.capabilities.end(), what) != g.capabilities.end();
    bool blocked = std::find(g.blocked.begin(), g.blocked.end(), what) != g.blocked.end();
    if (!allowed || blocked) {
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kInsufficientPrivileges,
                "guests may not use " + what + " (guest_limits)", "guest_limits", "guest_blocked"),
          "COMMAND_REJECTED");
    }
    // The guest session: opened by the first request, bounded in length and number.
    int64_t now = svc_.clock.mono_ms();
    int64_t len = int64_t{g.session_seconds} * 1000;
    const std::string key = ctx->principal.key();
    {
      MutexLock lock(mu_);
      for (auto it = sessions_.begin(); it != sessions_.end();)
        it = now - it->second >= 2 * len ? sessions_.erase(it) : std::next(it);
      auto it = sessions_.find(key);
      if (it != sessions_.end() && now - it->second >= len) {
        return refuse(
            svc_, ctx,
            Error(ErrorCode::kSessionExpired,
                  "the guest session ended after " + std::to_string(g.session_seconds) + " s",
                  "guest_limits"),
            "COMMAND_REJECTED");
      }
      if (it == sessions_.end()) {
        size_t live = 0;
        for (const auto& [k, start] : sessions_)
          if (now - start < len) ++live;
        if (live >= g.concurrent_sessions) {
          return refuse(
              svc_, ctx,
              Error(ErrorCode::kRateLimited,
                    "all " + std::to_string(g.concurrent_sessions) + " guest sessions are in use",
                    "guest_limits", "guest_sessions_full"),
              "RATE_LIMITED");
        }
        sessions_[key] = now;
      }
    }
    uint32_t per_minute = what == "chat_text" ? g.chat_per_minute : g.query_per_minute;
    auto d = svc_.rate.take(key + (what == "chat_text" ? "#chat" : "#query"), per_minute, now);
    if (!d.allowed) {
      ctx->audit_detail.set("retry_after_ms", d.retry_after_ms);
      return refuse(svc_, ctx,
                    Error(ErrorCode::kRateLimited,
                          "guest " + std::string(what == "chat_text" ? "chat" : "query") +
                              " rate of " + std::to_string(per_minute) + " per minute reached",
                          "guest_limits"),
                    "RATE_LIMITED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
  Mutex mu_;
  std::map<std::string, int64_t> sessions_ GUARDED_BY(mu_);  // guest principal → start (mono ms)
};

}  // namespace

std::unique_ptr<Stage> make_guest_limit_stage(NodeServices& services) {
  return std::make_unique<GuestLimitStage>(services);
}

}  // namespace rcan::node
