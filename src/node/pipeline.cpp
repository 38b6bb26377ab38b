// The pipeline and its standard stages. See pipeline.h for the contract.
#include "node/pipeline.h"

#include <algorithm>
#include <cctype>
#include <chrono>

#include "node/fleet.h"
#include "node/guest_limits.h"
#include "node/http_api.h"
#include "node/log.h"
#include "node/services.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

std::string upper(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

// The SAFETY event a message asks for, if any: a SAFETY message's safety_event / action /
// cmd, or a COMMAND whose action is a stop word. An ESTOP request is honoured in any form.
SafetyAction safety_action_of(const Message& m) {
  std::string word;
  if (m.type == MessageType::kSafety) {
    for (const char* k : {"safety_event", "action", "cmd", "command"}) {
      const json::Value* v = m.payload.find(k);
      if (v && v->is_string()) {
        word = upper(v->as_string());
        break;
      }
    }
    if (word.empty()) word = "ESTOP";  // a SAFETY message that says nothing more stops the robot
  } else if (m.type == MessageType::kCommand) {
    word = upper(m.action());
  } else {
    return SafetyAction::kNone;
  }
  if (word == "ESTOP" || word == "E_STOP" || word == "EMERGENCY_STOP") return SafetyAction::kEstop;
  if (word == "STOP" || word == "SAFE_STOP") return SafetyAction::kStop;
  if (word == "RESUME" || word == "ESTOP_CLEAR") return SafetyAction::kResume;
  if (m.type == MessageType::kSafety) return SafetyAction::kEstop;  // unknown safety word: stop
  return SafetyAction::kNone;
}

const char* safety_action_name(SafetyAction e) {
  switch (e) {
    case SafetyAction::kEstop: return "ESTOP";
    case SafetyAction::kStop: return "STOP";
    case SafetyAction::kResume: return "RESUME";
    case SafetyAction::kNone: return "NONE";
  }
  return "NONE";
}

std::string token_of(const Context& ctx) {
  if (!ctx.in.bearer.empty()) return ctx.in.bearer;
  if (const json::Value* t = ctx.in.body.get("auth_token"); t && t->is_string()) return t->as_string();
  return {};
}

// ----------------------------------------------------------------------------------------

class ShapeStage final : public Stage {
 public:
  explicit ShapeStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "shape"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    Status s = check_shape(ctx->in.body);
    if (!s.ok()) {
      refuse(svc_, ctx, s.error(), "MESSAGE_REJECTED");
      return Result::kAnswered;
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
      refuse(svc_, ctx, Error(ErrorCode::kAuthRequired, "a bearer token is required", "auth_token"),
             "AUTH_FAILED");
      return Result::kAnswered;
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class DecodeStage final : public Stage {
 public:
  explicit DecodeStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "decode"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    auto m = decode_message(ctx->in.body, svc_.settings.codec);
    if (!m.ok()) {
      refuse(svc_, ctx, m.error(), "MESSAGE_REJECTED");
      return Result::kAnswered;
    }
    ctx->msg = std::move(m).value();
    Message& msg = *ctx->msg;
    if (msg.type == MessageType::kFleetCommand) {  // a fleet's command (fleet.cpp checks it)
      msg.type = MessageType::kCommand;
      ctx->fleet_command = true;
    }
    ctx->safety = safety_action_of(msg);
    if (msg.priority == Priority::kSafety && ctx->safety == SafetyAction::kNone) {
      refuse(svc_, ctx,
             Error(ErrorCode::kSchemaValidationFailed,
                   "priority SAFETY is reserved for SAFETY messages (ESTOP, STOP, RESUME)", "priority"),
             "MESSAGE_REJECTED");
      return Result::kAnswered;
    }
    if (ctx->safety != SafetyAction::kNone) msg.priority = Priority::kSafety;
    switch (msg.type) {
      case MessageType::kCommand:
      case MessageType::kSafety:
      case MessageType::kStatus:
      case MessageType::kHeartbeat: break;
      default:
        refuse(svc_, ctx,
               Error(ErrorCode::kSchemaValidationFailed,
                     "message type " + std::string(message_type_name(msg.type)) + " is not accepted on " +
                         ctx->in.route,
                     "type"),
               "MESSAGE_REJECTED");
        return Result::kAnswered;
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

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
      refuse(svc_, ctx, v.error(), v.error().code == ErrorCode::kReplayDetected ? "REPLAY_DETECTED" : "MESSAGE_STALE");
      return Result::kAnswered;
    }
    if (v->duplicate_safety) ctx->audit_detail.set("duplicate_safety_message", true);
    // TTL: a message past timestamp + ttl is never dispatched.
    if (m.ttl_ms > 0 && svc_.clock.wall_ms() > m.timestamp_ms + m.ttl_ms && !safety) {
      refuse(svc_, ctx, Error(ErrorCode::kMessageStale, "the message's ttl_ms has expired", "ttl_ms"),
             "MESSAGE_STALE");
      return Result::kAnswered;
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
      if (ctx->principal.token_exp && *ctx->principal.token_exp + svc_.auth.verify_options().leeway_s < now_s) {
        refuse(svc_, ctx, Error(ErrorCode::kSessionExpired, "the stream's token has expired", "auth_token"),
               "AUTH_FAILED");
        return Result::kAnswered;
      }
    } else {
      auto p = svc_.authenticate(token_of(*ctx));
      if (!p.ok()) {
        refuse(svc_, ctx, p.error(), "AUTH_FAILED");
        return Result::kAnswered;
      }
      ctx->principal = std::move(p).value();
    }
    svc_.ownership.cap(ctx->principal);  // a former owner's token no longer carries ownership
    auto sig = svc_.auth.check_signature(*ctx->msg);
    if (!sig.ok()) {
      refuse(svc_, ctx, sig.error(), "AUTH_FAILED");
      return Result::kAnswered;
    }
    ctx->sig = *sig;
    if (ctx->sig.verified) {
      ctx->audit_detail.set("sig_alg", ctx->sig.alg);
      ctx->audit_detail.set("sig_kid", ctx->sig.kid);
    }
    auto sender = svc_.auth.sender(*ctx->msg, ctx->principal, ctx->sig);
    if (!sender.ok()) {
      refuse(svc_, ctx, sender.error(), "AUTH_FAILED");
      return Result::kAnswered;
    }
    ctx->sender = std::move(sender).value();
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class AuthorizeStage final : public Stage {
 public:
  explicit AuthorizeStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "authorize"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    const Message& m = *ctx->msg;
    const Principal& p = ctx->principal;
    auto deny = [&](std::string msg, std::string field) {
      refuse(svc_, ctx, Error(ErrorCode::kInsufficientPrivileges, std::move(msg), std::move(field)),
             "COMMAND_REJECTED");
      return Result::kAnswered;
    };
    switch (ctx->safety) {
      case SafetyAction::kEstop:
      case SafetyAction::kStop:
        return Result::kContinue;  // any authenticated principal may stop the robot
      case SafetyAction::kResume:
        if (role_level(p.role) < role_level(Role::kLeasee))
          return deny(std::string(role_name(p.role)) + " may not clear an ESTOP (LEASEE or above)", "role");
        return Result::kContinue;
      case SafetyAction::kNone: break;
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
    if (m.type == MessageType::kStatus || m.type == MessageType::kHeartbeat) return Result::kContinue;
    std::string action = m.action();
    if (action.empty()) {
      refuse(svc_, ctx,
             Error(ErrorCode::kSchemaValidationFailed, "a COMMAND needs payload.action (or command)",
                   "payload.action", "missing_field"),
             "MESSAGE_REJECTED");
      return Result::kAnswered;
    }
    Capability cap = capability_for_action(action);
    ctx->capability = cap;
    Status st = authorize(p.role, p.scopes, cap, svc_.settings.role_policy);
    if (!st.ok()) {
      refuse(svc_, ctx, st.error(), "COMMAND_REJECTED");
      return Result::kAnswered;
    }
    // A held control session reserves motion for its holder; a session that expired needs an
    // explicit renewal (a new claim) before its principal drives again.
    if (capability_scope(cap) == "control") {
      auto holder = svc_.sessions.controller(svc_.clock.mono_ms());
      if (holder && holder->principal_key == p.key()) {
        ctx->session_id = holder->id;
        svc_.act.session_heartbeat(holder->id);
      } else if (auto gone = svc_.sessions.expired_session_of(p.key())) {
        ctx->audit_detail.set("session_id", *gone);
        refuse(svc_, ctx, Error(ErrorCode::kSessionExpired, "the control session expired; claim control again", "session"),
               "COMMAND_REJECTED");
        return Result::kAnswered;
      } else if (holder) {
        refuse(svc_, ctx,
               Error(ErrorCode::kControlConflict,
                     "the robot is controlled by another principal; claim it first", "session"),
               "COMMAND_REJECTED");
        return Result::kAnswered;
      } else if (NetMode nm = svc_.partition.mode();
                 nm == NetMode::kLockdown ||
                 (nm == NetMode::kOfflineAutonomous && !svc_.partition.cached(p, svc_.clock.wall_ms()))) {
        // Seed §6.1: partitioned, only sessions that already exist (or cached principals) act.
        refuse(svc_, ctx,
               Error(ErrorCode::kLockdown, std::string(net_mode_name(nm)) + ": no new control without a session"),
               "COMMAND_REJECTED");
        return Result::kAnswered;
      }
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

class RateLimitStage final : public Stage {
 public:
  explicit RateLimitStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "rate_limit"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (ctx->safety != SafetyAction::kNone) return Result::kContinue;  // SAFETY is never rate-limited
    auto d = svc_.rate.take(ctx->principal.key(), svc_.rate_limit(ctx->principal.role), svc_.clock.mono_ms());
    if (!d.allowed) {
      Error e(ErrorCode::kRateLimited,
              std::string(role_name(ctx->principal.role)) + " rate limit of " +
                  std::to_string(svc_.rate_limit(ctx->principal.role)) + " per minute reached");
      ctx->audit_detail.set("retry_after_ms", d.retry_after_ms);
      refuse(svc_, ctx, e, "RATE_LIMITED");
      return Result::kAnswered;
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
    bool moves = ctx->capability && capability_scope(*ctx->capability) != "status" &&
                 *ctx->capability != Capability::kChat;
    if (moves && svc_.act.estop_active()) {
      refuse(svc_, ctx,
             Error(ErrorCode::kCommandRejected, "ESTOP is active; RESUME (LEASEE or above) clears it", "",
                   "estop_active"),
             "COMMAND_REJECTED");
      return Result::kAnswered;
    }
    if (!svc_.audit.available()) {
      refuse(svc_, ctx,
             Error(ErrorCode::kAuditUnavailable,
                   "the audit log cannot record; commands are refused until it can (ESTOP still works)"),
             "COMMAND_REJECTED");
      return Result::kAnswered;
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
    if (ctx->safety != SafetyAction::kNone || ctx->msg->type != MessageType::kCommand) return Result::kContinue;
    if (auto hit = svc_.injection.scan(json::Value(ctx->msg->payload))) {
      ctx->audit_detail.set("pattern", *hit);
      refuse(svc_, ctx,
             Error(ErrorCode::kCommandRejected, "the command text matches a prompt-injection pattern", "payload",
                   "prompt_injection"),
             "INJECTION_BLOCKED");
      return Result::kAnswered;
    }
    return Result::kContinue;
  }

 private:
  NodeServices& svc_;
};

// Audit, then dispatch. SAFETY stops act first and record after; everything else is recorded
// durably before it reaches the safety core.
class DispatchStage final : public Stage {
 public:
  explicit DispatchStage(NodeServices& s)
      : svc_(s), audit_timer_(s.metrics.stage("audit")), apply_timer_(s.metrics.stage("apply")) {}
  const char* name() const override { return "dispatch"; }

  Result run(const std::shared_ptr<Context>& ctx) override {
    const Message& m = *ctx->msg;
    switch (ctx->safety) {
      case SafetyAction::kEstop:
      case SafetyAction::kStop: return stop(ctx);
      case SafetyAction::kResume: return resume(ctx);
      case SafetyAction::kNone: break;
    }
    if (m.type == MessageType::kStatus) {
      json::Object payload = svc_.status(true).as_object();
      auto e = accepted_entry(*ctx, "STATUS");
      svc_.write_audit(std::move(e));
      ctx->finish(Outcome{200, svc_.envelope(MessageType::kStatus, std::move(payload), m.message_id), {}});
      return Result::kAnswered;
    }
    if (m.type == MessageType::kHeartbeat) {
      // Keeps the sender's control session alive (deadman). Only its holder can feed it.
      auto holder = svc_.sessions.controller(svc_.clock.mono_ms());
      bool fed = false;
      if (holder && holder->principal_key == ctx->principal.key()) {
        svc_.act.session_heartbeat(holder->id);
        fed = true;
      }
      auto e = accepted_entry(*ctx, "HEARTBEAT");
      svc_.write_audit(std::move(e));
      json::Object payload{{"ok", true}, {"session_alive", fed}};
      if (fed) payload.set("session_id", holder->id);
      ctx->finish(Outcome{200, svc_.envelope(MessageType::kAck, payload, m.message_id), {}});
      return Result::kAnswered;
    }
    return command(ctx);
  }

 private:
  audit::AuditEntry accepted_entry(const Context& ctx, const std::string& event) {
    const Message& m = *ctx.msg;
    auto e = svc_.entry(ctx.principal.display(), m.message_id, event, "ok");
    e.sender_type = std::string(sender_type_name(ctx.sender.sender_type));
    if (!ctx.sender.sub.empty()) e.sub = ctx.sender.sub;
    if (!ctx.sender.cloud_provider.empty()) e.cloud_provider = ctx.sender.cloud_provider;
    if (!ctx.sender.function_name.empty()) e.function_name = ctx.sender.function_name;
    std::string action = m.action();
    if (!action.empty()) e.action = action;
    if (m.ai) e.ai = *m.ai;
    e.gate_bypassed = ctx.gate_bypassed;
    e.hitl_timeout_bypass = ctx.hitl_timeout_bypass;
    if (!ctx.watermark_token.empty()) e.watermark_token = ctx.watermark_token;
    e.detail = ctx.audit_detail;
    e.detail.set("transport", ctx.in.transport);
    e.detail.set("route", ctx.in.route);
    if (!m.delegation_chain.is_null()) e.detail.set("delegation_chain", m.delegation_chain);
    return e;
  }

  Result stop(const std::shared_ptr<Context>& ctx) {
    bool estop = ctx->safety == SafetyAction::kEstop;
    std::string source = ctx->principal.display() + " via " + ctx->in.transport;
    std::string reason;
    if (const json::Value* r = ctx->msg->payload.find("reason"); r && r->is_string()) reason = r->as_string().substr(0, 512);
    double us = 0;
    const int64_t t_call = steady_us();
    if (estop) {
      us = svc_.act.estop(source, reason);
    } else {
      svc_.act.stop(source);
      us = static_cast<double>(steady_us() - t_call);
    }
    // From the request's arrival (the transport's read) to Driver::stop() returning.
    const double arrival_us = static_cast<double>(t_call - ctx->in.received_mono_us) + us;
    svc_.metrics.stage("estop_to_driver").observe_us(us);
    svc_.metrics.stage(ctx->in.transport == "ws" ? "stop_arrival_to_driver_ws" : "stop_arrival_to_driver_http")
        .observe_us(arrival_us);
    log(LogLevel::kInfo, estop ? "estop.latency" : "stop.latency",
        {{"transport", ctx->in.transport},
         {"route", ctx->in.route},
         {"arrival_to_driver_us", arrival_us},
         {"call_to_driver_us", us}});
    json::Object ev{{"type", "EVENT"},
                    {"event", estop ? "ESTOP" : "STOP"},
                    {"source", ctx->principal.display()},
                    {"timestamp_ms", svc_.clock.wall_ms()}};
    svc_.events.publish(json::Value(ev));
    // Seed §5.3 safety conflict: a stop from someone other than the holder. The stop always
    // wins (it already happened); every session is alerted.
    auto holder = svc_.sessions.controller(svc_.clock.mono_ms());
    if (holder && holder->principal_key != ctx->principal.key()) {
      svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                                   {"event", "SAFETY_CONFLICT"},
                                                   {"stopped_by", ctx->principal.display()},
                                                   {"holder_session", holder->id},
                                                   {"timestamp_ms", svc_.clock.wall_ms()}}));
      ctx->audit_detail.set("safety_conflict", true);
      ctx->audit_detail.set("holder_session", holder->id);
    }
    auto e = accepted_entry(*ctx, estop ? "ESTOP" : "STOP");
    if (!reason.empty()) e.reason = reason;
    std::string id = ctx->msg->message_id;
    json::Object payload{{"command", safety_action_name(ctx->safety)},
                         {"result", estop ? "estop_latched" : "stopped"},
                         {"estop_active", svc_.act.estop_active()}};
    // The stop already happened; the answer waits for the record (or its failure).
    svc_.write_audit(std::move(e), [this, ctx, id, payload](rcan::Result<audit::Receipt> r) mutable {
      if (!r.ok()) payload.set("audit", "unavailable");
      ctx->finish(Outcome{200, svc_.envelope(MessageType::kAck, payload, id), {}});
    });
    return Result::kParked;
  }

  Result resume(const std::shared_ptr<Context>& ctx) {
    if (!svc_.audit.available()) {  // RESUME re-enables motion: not without its record
      refuse(svc_, ctx,
             Error(ErrorCode::kAuditUnavailable,
                   "the audit log cannot record; RESUME is refused until it can (ESTOP still works)"),
             "COMMAND_REJECTED");
      return Result::kAnswered;
    }
    Status st = svc_.act.resume(ctx->principal.role, ctx->principal.display());
    if (!st.ok()) {
      refuse(svc_, ctx, st.error(), "COMMAND_REJECTED");
      return Result::kAnswered;
    }
    svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                                 {"event", "RESUME"},
                                                 {"source", ctx->principal.display()},
                                                 {"timestamp_ms", svc_.clock.wall_ms()}}));
    auto e = accepted_entry(*ctx, "RESUME");
    std::string id = ctx->msg->message_id;
    svc_.write_audit(std::move(e), [this, ctx, id](rcan::Result<audit::Receipt>) {
      ctx->finish(Outcome{200,
                          svc_.envelope(MessageType::kAck,
                                        json::Object{{"command", "RESUME"}, {"result", "estop_cleared"}}, id),
                          {}});
    });
    return Result::kParked;
  }

  Result command(const std::shared_ptr<Context>& ctx) {
    const Message& m = *ctx->msg;
    int64_t deadline = 0;
    int64_t ttl = m.ttl_ms > 0 ? m.ttl_ms : svc_.settings.default_ttl_ms;
    if (ttl > 0) {
      int64_t remaining = m.timestamp_ms + ttl - svc_.clock.wall_ms();
      deadline = svc_.clock.mono_ms() + std::max<int64_t>(remaining, 0);
    }
    auto prepared = svc_.act.prepare(m, deadline, ctx->session_id);
    if (!prepared.ok()) {
      refuse(svc_, ctx, prepared.error(), "COMMAND_REJECTED");
      return Result::kAnswered;
    }
    auto e = accepted_entry(*ctx, "COMMAND");
    if (prepared->clamped) {
      e.detail.set("clamped", prepared->clamp_note);
    }
    e.detail.set("applied", prepared->action);
    auto cmd = std::make_shared<PreparedCommand>(std::move(prepared).value());
    int64_t audit_start = steady_us();
    svc_.write_audit(std::move(e), [this, ctx, cmd, audit_start](rcan::Result<audit::Receipt> r) {
      audit_timer_.observe_us(static_cast<double>(steady_us() - audit_start));
      const std::string& id = ctx->msg->message_id;
      if (!r.ok()) {
        // Nothing is dispatched without its record.
        Error err(ErrorCode::kAuditUnavailable, "the command could not be recorded and was not dispatched");
        ctx->finish(Outcome{http_status(err.code), svc_.error(err, id), {}});
        return;
      }
      int64_t t0 = steady_us();
      std::optional<rcan::Result<json::Value>> result;
      auto apply = [&] { result = svc_.act.apply(*cmd); };
      if (ctx->session_id.empty()) {
        apply();
      } else if (!svc_.sessions.run_if_live(ctx->session_id, svc_.clock.mono_ms(), apply)) {
        // Its control session ended (pre-empted, expired, revoked) while it was in flight.
        auto drop = svc_.entry(ctx->principal.display(), id, "COMMAND_DROPPED", "blocked");
        drop.sender_type = std::string(sender_type_name(ctx->sender.sender_type));
        drop.sub = ctx->principal.sub;
        drop.reason = "session_ended";
        drop.detail.set("session_id", ctx->session_id);
        svc_.write_audit(std::move(drop));
        Error err(ErrorCode::kControlConflict, "the control session ended before the command reached the robot",
                  "session", "session_ended");
        ctx->finish(Outcome{http_status(err.code), svc_.error(err, id), {}});
        return;
      }
      auto& applied = *result;
      apply_timer_.observe_us(static_cast<double>(steady_us() - t0));
      if (!applied.ok()) {
        // An ESTOP overtook this command between its record and the driver: say so in a
        // record of its own and refuse.
        auto drop = svc_.entry(ctx->principal.display(), id, "COMMAND_DROPPED", "blocked");
        drop.sender_type = std::string(sender_type_name(ctx->sender.sender_type));
        drop.reason = applied.error().reason.empty() ? std::string(error_name(applied.error().code))
                                                     : applied.error().reason;
        svc_.write_audit(std::move(drop));
        ctx->finish(Outcome{http_status(applied.error().code, applied.error().reason),
                            svc_.error(applied.error(), id),
                            {}});
        return;
      }
      json::Object payload{{"command", ctx->msg->action()}, {"result", *applied}};
      if (cmd->clamped) payload.set("clamped", cmd->clamp_note);
      if (!ctx->watermark_token.empty()) payload.set("watermark_token", ctx->watermark_token);
      ctx->finish(Outcome{200, svc_.envelope(MessageType::kAck, payload, id), {}});
    });
    return Result::kParked;
  }

  NodeServices& svc_;
  Histogram& audit_timer_;  // per command: looked up once
  Histogram& apply_timer_;
};

}  // namespace

void Context::finish(Outcome out) {
  if (finished_) return;
  finished_ = true;
  if (done) done(std::move(out));
}

void refuse(NodeServices& svc, const std::shared_ptr<Context>& ctx, const Error& err,
            const std::string& audit_event) {
  std::string reply_to;
  if (ctx->msg) reply_to = ctx->msg->message_id;
  Outcome out;
  out.status = http_status(err.code, err.reason);
  out.body = svc.error(err, reply_to);
  if (err.code == ErrorCode::kRateLimited) {
    const json::Value* ra = ctx->audit_detail.find("retry_after_ms");
    int64_t secs = ra && ra->is_int() ? (ra->as_int() + 999) / 1000 : 1;
    out.headers.emplace_back("Retry-After", std::to_string(std::max<int64_t>(secs, 1)));
  }
  auto e = svc.entry(ctx->principal.display(), reply_to, audit_event.empty() ? "COMMAND_REJECTED" : audit_event,
                     err.code == ErrorCode::kAuditUnavailable || err.code == ErrorCode::kInternal ? "error" : "blocked");
  e.sender_type = std::string(sender_type_name(ctx->sender.sender_type));
  if (ctx->principal.authenticated) e.sub = ctx->principal.sub;
  if (!ctx->sender.cloud_provider.empty()) e.cloud_provider = ctx->sender.cloud_provider;
  if (!ctx->sender.function_name.empty()) e.function_name = ctx->sender.function_name;
  e.reason = err.reason.empty() ? std::string(error_name(err.code)) : err.reason;
  bool payload_free = err.code == ErrorCode::kReplayDetected || err.code == ErrorCode::kMessageStale ||
                      err.code == ErrorCode::kMalformedJson || err.code == ErrorCode::kSchemaValidationFailed;
  if (ctx->msg && !payload_free) {
    std::string action = ctx->msg->action();
    if (!action.empty()) e.action = action.substr(0, 128);
  }
  // §16.2: a refused AI command names its model too (not for replays: those record nothing sent).
  if (ctx->msg && ctx->msg->ai && err.code != ErrorCode::kReplayDetected && err.code != ErrorCode::kMessageStale)
    e.ai = *ctx->msg->ai;
  e.detail = ctx->audit_detail;
  e.detail.set("error_code", std::string(error_name(err.code)));
  if (!err.field.empty()) e.detail.set("field", err.field.substr(0, 128));
  e.detail.set("transport", ctx->in.transport);
  e.detail.set("route", ctx->in.route);
  svc.write_audit(std::move(e));
  ctx->finish(std::move(out));
}

Pipeline::Pipeline(NodeServices& services, std::vector<std::unique_ptr<Stage>> stages)
    : svc_(services), stages_(std::move(stages)) {
  for (const auto& s : stages_) stage_timers_.push_back(&svc_.metrics.stage(s->name()));
  parse_timer_ = &svc_.metrics.stage("parse");
  total_timer_ = &svc_.metrics.stage("total");
}

void Pipeline::submit(Ingress in, std::function<void(Outcome)> done) {
  auto ctx = std::make_shared<Context>();
  ctx->in = std::move(in);
  ctx->started_mono_us = steady_us();
  if (ctx->in.received_mono_us == 0) ctx->in.received_mono_us = ctx->started_mono_us;
  // parse: arrival → here (routing and the JSON parse); total: arrival → answer handed over.
  parse_timer_->observe_us(static_cast<double>(ctx->started_mono_us - ctx->in.received_mono_us));
  ctx->done = [total = total_timer_, arrival = ctx->in.received_mono_us, done = std::move(done)](Outcome out) {
    done(std::move(out));
    total->observe_us(static_cast<double>(steady_us() - arrival));
  };
  ctx->pipeline = this;
  run(ctx, 0);
}

void Pipeline::run_from(const std::shared_ptr<Context>& ctx, std::string_view stage) {
  ctx->pipeline = this;
  for (size_t i = 0; i < stages_.size(); ++i)
    if (stage == stages_[i]->name()) return run(ctx, i);
  refuse(svc_, ctx, Error(ErrorCode::kInternal, "no pipeline stage named " + std::string(stage)), "INTERNAL_ERROR");
}

void Pipeline::run(const std::shared_ptr<Context>& ctx, size_t first) {
  for (size_t i = first; i < stages_.size(); ++i) {
    int64_t t0 = steady_us();
    Stage::Result r = stages_[i]->run(ctx);
    stage_timers_[i]->observe_us(static_cast<double>(steady_us() - t0));
    if (r != Stage::Result::kContinue) return;
  }
  if (!ctx->finished()) {
    refuse(svc_, ctx, Error(ErrorCode::kInternal, "the pipeline ended without an answer"), "INTERNAL_ERROR");
  }
}

std::vector<std::unique_ptr<Stage>> Pipeline::standard_stages(NodeServices& s) {
  std::vector<std::unique_ptr<Stage>> v;
  v.push_back(std::make_unique<ShapeStage>(s));
  v.push_back(std::make_unique<TokenPresenceStage>(s));
  v.push_back(std::make_unique<DecodeStage>(s));
  // Authentication before the replay memory: a message whose token does not verify must not
  // use up its message_id or a place in the bounded memory (docs/SECURITY.md).
  v.push_back(std::make_unique<AuthStage>(s));
  v.push_back(std::make_unique<ReplayStage>(s));
  v.push_back(make_fleet_stage(s));  // fleet.cpp
  v.push_back(std::make_unique<AuthorizeStage>(s));
  v.push_back(make_guest_limit_stage(s));
  v.push_back(std::make_unique<RateLimitStage>(s));
  v.push_back(std::make_unique<SafetyStateStage>(s));
  v.push_back(std::make_unique<InjectionStage>(s));
  for (auto& g : ai_stages(s)) v.push_back(std::move(g));  // §16: confidence, HiTL, watermark
  v.push_back(std::make_unique<DispatchStage>(s));
  return v;
}

}  // namespace rcan::node
