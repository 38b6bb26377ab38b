// The last stage: audit, then dispatch to the safety core (pipeline.h).
#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

// An ESTOP or STOP answer waits for its audit record and, for an ESTOP, for its latch file;
// whichever of them comes last (the stage, the audit writer or the safety core's persister)
// sends it. Nothing here blocks a thread.
class StopAnswer {
 public:
  StopAnswer(NodeServices& svc, std::shared_ptr<Context> ctx, bool latch)
      : svc_(svc), ctx_(std::move(ctx)), pending_(latch ? 3 : 2) {}

  // The stage's own part: the answer's payload.
  void ready(json::Object payload) EXCLUDES(mu_) {
    {
      MutexLock lock(mu_);
      payload_ = std::move(payload);
    }
    arrive();
  }
  void audited(bool ok) EXCLUDES(mu_) {
    if (!ok) {
      MutexLock lock(mu_);
      extra_.set("audit", "unavailable");
    }
    arrive();
  }
  // The latch survives a restart ("durable"), or the answer says it may not and why.
  void latched(bool durable, const std::string& error) EXCLUDES(mu_) {
    {
      MutexLock lock(mu_);
      extra_.set("latch", durable ? "durable" : "not_durable");
      if (!durable) extra_.set("latch_error", error);
    }
    arrive();
  }

 private:
  void arrive() EXCLUDES(mu_) {
    json::Object payload;
    {
      MutexLock lock(mu_);
      if (--pending_ > 0) return;
      payload = std::move(payload_);
      for (const auto& [k, v] : extra_) payload.set(k, v);
    }
    ctx_->finish(Outcome{
        200, svc_.envelope(MessageType::kAck, std::move(payload), ctx_->msg->message_id), {}});
  }

  NodeServices& svc_;
  const std::shared_ptr<Context> ctx_;
  Mutex mu_;
  int pending_ GUARDED_BY(mu_);
  json::Object payload_ GUARDED_BY(mu_);
  json::Object extra_ GUARDED_BY(mu_);
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
      case SafetyAction::kStop:
        return stop(ctx);
      case SafetyAction::kResume:
        return resume(ctx);
      case SafetyAction::kNone:
        break;
    }
    if (m.type == MessageType::kStatus) {
      json::Object payload = svc_.status(true).as_object();
      auto e = accepted_entry(*ctx, "STATUS");
      svc_.trail.write(std::move(e));
      ctx->finish(
          Outcome{200, svc_.envelope(MessageType::kStatus, std::move(payload), m.message_id), {}});
      return Result::kAnswered;
    }
    if (m.type == MessageType::kHeartbeat) {
      // Keeps the sender's control session alive (deadman). Only its holder can feed it.
      auto holder = svc_.control.sessions().controller(svc_.clock.mono_ms());
      bool fed = false;
      if (holder && holder->principal_key == ctx->principal.key()) {
        svc_.act.feed_deadman(holder->id);
        fed = true;
      }
      auto e = accepted_entry(*ctx, "HEARTBEAT");
      svc_.trail.write(std::move(e));
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
    AuditRecord r = message_record(svc_, ctx, event, "ok");
    r.action(ctx.action ? ctx.action->name : m.action());
    audit::AuditEntry e = std::move(r.entry());
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
    if (const json::Value* r = ctx->msg->payload.find("reason"); r && r->is_string())
      reason = r->as_string().substr(0, 512);
    double us = 0;
    auto answer = std::make_shared<StopAnswer>(svc_, ctx, estop);
    const int64_t t_call = steady_us();
    if (estop) {
      // The ACK waits for the latch file too: an acknowledged ESTOP survives a restart, or
      // its answer says that it may not (latch: not_durable, with why). A transport thread
      // that may wait for the disk writes it itself (as the record below).
      us = svc_.act.estop(
          source, reason, ctx->principal.role,
          [answer](bool durable, const std::string& error) { answer->latched(durable, error); },
          ctx->in.may_commit_audit);
    } else {
      svc_.act.stop(source);
      us = static_cast<double>(steady_us() - t_call);
    }
    // From the request's arrival (the transport's read) to Driver::stop() returning.
    const double arrival_us = static_cast<double>(t_call - ctx->in.received_mono_us) + us;
    svc_.metrics.stage("estop_to_driver").observe_us(us);
    svc_.metrics
        .stage(ctx->in.transport == "ws" ? "stop_arrival_to_driver_ws"
                                         : "stop_arrival_to_driver_http")
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
    auto holder = svc_.control.sessions().controller(svc_.clock.mono_ms());
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
    // The stop already happened; the answer waits for the record (or its failure). A transport
    // thread that may wait for the disk commits it itself: a message after a stop waits one
    // fdatasync at most, and the robot is stopped meanwhile.
    svc_.trail.write(
        std::move(e), [answer](rcan::Result<audit::Receipt> r) { answer->audited(r.ok()); },
        ctx->in.may_commit_audit ? audit::Commit::kHereIfIdle : audit::Commit::kWriter);
    answer->ready(json::Object{{"command", safety_action_name(ctx->safety)},
                               {"result", estop ? "estop_latched" : "stopped"},
                               {"estop_active", svc_.act.estop_active()}});
    return Result::kParked;
  }

  Result resume(const std::shared_ptr<Context>& ctx) {
    if (!svc_.audit.available()) {  // RESUME re-enables motion: not without its record
      return refuse(
          svc_, ctx,
          Error(ErrorCode::kAuditUnavailable,
                "the audit log cannot record; RESUME is refused until it can (ESTOP still works)"),
          "COMMAND_REJECTED");
    }
    Status st = svc_.act.resume(ctx->principal.role, ctx->principal.display());
    if (!st.ok()) {
      return refuse(svc_, ctx, st.error(), "COMMAND_REJECTED");
    }
    svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                                 {"event", "RESUME"},
                                                 {"source", ctx->principal.display()},
                                                 {"timestamp_ms", svc_.clock.wall_ms()}}));
    auto e = accepted_entry(*ctx, "RESUME");
    std::string id = ctx->msg->message_id;
    svc_.trail.write(std::move(e), [this, ctx, id](rcan::Result<audit::Receipt>) {
      ctx->finish(Outcome{
          200,
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
    if (!ctx->action) {  // the authorize stage looks every COMMAND's action up
      return refuse(svc_, ctx, Error(ErrorCode::kInternal, "a command reached dispatch unchecked"),
                    "INTERNAL_ERROR");
    }
    // A stream without a control session is held by the ESTOP epoch it is armed at (the safety
    // core refuses its motion once an ESTOP has latched since); a command that says
    // "rearm": true is the client's fresh operator action and arms it at the current epoch.
    // docs/NODE.md, "Re-arm after ESTOP".
    std::optional<uint64_t> stream_epoch;
    bool rearmed = false;
    if (ctx->session_id.empty() && ctx->in.armed_epoch) {
      const json::Object* wire = wire_of(*ctx);
      const json::Value* rearm = wire ? wire->find("rearm") : nullptr;
      if (rearm && rearm->is_bool() && rearm->as_bool()) {
        const uint64_t now = svc_.act.estop_epoch();
        rearmed = ctx->in.armed_epoch->exchange(now) < now;
      }
      stream_epoch = ctx->in.armed_epoch->load();
    }
    auto prepared = svc_.act.prepare(m, *ctx->action, deadline, ctx->session_id, stream_epoch);
    if (!prepared.ok()) {
      Error err = prepared.error();
      if (ctx->invoke && err.reason == "unsupported_action")  // a skill this robot does not have
        err = Error(ErrorCode::kNotFound,
                    "this robot does not offer the skill '" + std::string(ctx->action->name) + "'",
                    ctx->skill_field, "unknown_skill");
      return refuse(svc_, ctx, err, "COMMAND_REJECTED");
    }
    auto e = accepted_entry(*ctx, "COMMAND");
    if (rearmed) e.detail.set("rearmed", true);
    if (prepared->clamped) {
      e.detail.set("clamped", prepared->clamp_note);
    }
    e.detail.set("applied", prepared->action);
    auto cmd = std::make_shared<PreparedCommand>(std::move(prepared).value());
    int64_t audit_start = steady_us();
    svc_.trail.write(std::move(e), [this, ctx, cmd, audit_start](rcan::Result<audit::Receipt> r) {
      audit_timer_.observe_us(static_cast<double>(steady_us() - audit_start));
      const std::string& id = ctx->msg->message_id;
      if (!r.ok()) {
        // Nothing is dispatched without its record.
        Error err(ErrorCode::kAuditUnavailable,
                  "the command could not be recorded and was not dispatched");
        ctx->finish(Outcome{http_status(err.code), svc_.error(err, id), {}});
        return;
      }
      int64_t t0 = steady_us();
      std::optional<rcan::Result<json::Value>> result;
      auto apply = [&] { result = svc_.act.apply(*cmd); };
      if (ctx->session_id.empty()) {
        apply();
      } else if (!svc_.control.sessions().run_if_live(ctx->session_id, svc_.clock.mono_ms(),
                                                      apply)) {
        // Its control session ended (pre-empted, expired, revoked) while it was in flight.
        message_record(svc_, *ctx, "COMMAND_DROPPED", "blocked")
            .reason("session_ended")
            .detail("session_id", ctx->session_id)
            .write();
        Error err(ErrorCode::kControlConflict,
                  "the control session ended before the command reached the robot", "session",
                  "session_ended");
        ctx->finish(Outcome{http_status(err.code), svc_.error(err, id), {}});
        return;
      }
      auto& applied = *result;
      apply_timer_.observe_us(static_cast<double>(steady_us() - t0));
      if (!applied.ok()) {
        // An ESTOP overtook this command between its record and the driver: say so in a
        // record of its own and refuse.
        message_record(svc_, *ctx, "COMMAND_DROPPED", "blocked")
            .reason(applied.error().reason.empty() ? std::string(error_name(applied.error().code))
                                                   : applied.error().reason)
            .write();
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

std::unique_ptr<Stage> make_dispatch_stage(NodeServices& services) {
  return std::make_unique<DispatchStage>(services);
}

}  // namespace rcan::node
