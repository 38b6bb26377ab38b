// Authorisation: scopes, role, capability, the control session (pipeline.h).
#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

bool iequals(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

class AuthorizeStage final : public Stage {
 public:
  explicit AuthorizeStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "authorize"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    const Message& m = *ctx->msg;
    const Principal& p = ctx->principal;
    auto deny = [&](std::string msg, std::string field) {
      return refuse(svc_, ctx,
                    Error(ErrorCode::kInsufficientPrivileges, std::move(msg), std::move(field)),
                    "COMMAND_REJECTED");
    };
    switch (ctx->safety) {
      case SafetyAction::kEstop:
      case SafetyAction::kStop:
        return Result::kContinue;  // any authenticated principal may stop the robot
      case SafetyAction::kResume:
        // Clearing an ESTOP re-enables motion: the control scope, LEASEE or above, and (checked
        // by the safety core against the latch) a role at least that of whoever latched it.
        if (role_level(p.role) < role_level(Role::kLeasee))
          return deny(std::string(role_name(p.role)) + " may not clear an ESTOP (LEASEE or above)",
                      "role");
        if (!p.has_scope("control"))
          return deny(std::string(role_name(p.role)) +
                          " token lacks scope control, needed to clear an ESTOP",
                      "scope");
        return Result::kContinue;
      case SafetyAction::kNone:
        break;
    }
    // Every scope the message asks for must be held and within the role.
    for (const auto& s : m.scope) {
      auto min = scope_min_role(s);
      if (!min) return deny("unknown scope " + s, "scope");
      if (!p.has_scope(s) && s != "status")
        return deny(std::string(role_name(p.role)) + " token lacks scope " + s, "scope");
      if (role_level(p.role) < role_level(*min))
        return deny(std::string(role_name(p.role)) + " may not use scope " + s, "scope");
    }
    if (m.type == MessageType::kStatus || m.type == MessageType::kHeartbeat)
      return Result::kContinue;
    std::string action = m.action();
    if (action.empty()) {
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kSchemaValidationFailed, "a COMMAND needs payload.action (or command)",
                "payload.action", "missing_field"),
          "MESSAGE_REJECTED");
    }
    // One table says what every action name means (rcan/actions.h); a name it does not hold
    // is refused for every role, never given some default capability.
    const ActionSpec* spec = svc_.actions.find(action);
    if (!spec && ctx->invoke) {  // an INVOKE names a skill: one the robot lacks is not found
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kNotFound, "no skill '" + action.substr(0, 64) + "' on this robot",
                ctx->skill_field, "unknown_skill"),
          "COMMAND_REJECTED");
    }
    if (!spec) {
      return refuse(svc_, ctx,
                    Error(ErrorCode::kCommandRejected,
                          "unknown action '" + action.substr(0, 64) +
                              "': not an action this robot knows (docs/PROTOCOL.md §Actions)",
                          "payload.action", "unknown_action"),
                    "COMMAND_REJECTED");
    }
    ctx->action = spec;
    if (!iequals(action, spec->name)) ctx->audit_detail.set("action_sent", action.substr(0, 128));
    Capability cap = spec->capability;
    ctx->capability = cap;
    Status st = authorize(p.role, p.scopes, cap, svc_.settings.role_policy);
    if (!st.ok()) {
      return refuse(svc_, ctx, st.error(), "COMMAND_REJECTED");
    }
    if (capability_scope(cap) == "control") return hold_control(ctx, p);
    return Result::kContinue;
  }

  // A held control session reserves motion for its holder; a session that expired needs an
  // explicit renewal (a new claim) before its principal drives again.
  Result hold_control(const std::shared_ptr<Context>& ctx, const Principal& p) {
    auto holder = svc_.control.sessions().controller(svc_.clock.mono_ms());
    if (holder && holder->principal_key == p.key()) {
      ctx->session_id = holder->id;
      svc_.act.feed_deadman(holder->id);
    } else if (auto gone = svc_.control.sessions().expired_session_of(p.key())) {
      ctx->audit_detail.set("session_id", *gone);
      return refuse(svc_, ctx,
                    Error(ErrorCode::kSessionExpired,
                          "the control session expired; claim control again", "session"),
                    "COMMAND_REJECTED");
    } else if (holder) {
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kControlConflict,
                "the robot is controlled by another principal; claim it first", "session"),
          "COMMAND_REJECTED");
    } else if (NetMode nm = svc_.control.partition().mode();
               nm == NetMode::kLockdown ||
               (nm == NetMode::kOfflineAutonomous &&
                !svc_.control.partition().cached(p, svc_.clock.wall_ms()))) {
      // Seed §6.1: partitioned, only sessions that already exist (or cached principals) act.
      return refuse(svc_, ctx,
                    Error(ErrorCode::kLockdown,
                          std::string(net_mode_name(nm)) + ": no new control without a session"),
                    "COMMAND_REJECTED");
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

}  // namespace

std::unique_ptr<Stage> make_authorize_stage(NodeServices& services) {
  return std::make_unique<AuthorizeStage>(services);
}

}  // namespace rcan::node
