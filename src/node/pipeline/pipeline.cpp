// The pipeline engine: contexts, refusals, running the stages. See pipeline.h for the contract.
#include "node/pipeline/pipeline.h"

#include <algorithm>
#include <cctype>

#include "base/clock.h"
#include "base/strings.h"
#include "node/pipeline/stages.h"
#include "node/services/node_services.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {}  // namespace

// The SAFETY event a message asks for, if any: a SAFETY message's safety_event / action /
// cmd, or a COMMAND whose action is a stop word. An ESTOP request is honoured in any form.
SafetyAction safety_action_of(const Message& m) {
  std::string word;
  if (m.type == MessageType::kSafety) {
    for (const char* k : {"safety_event", "action", "cmd", "command"}) {
      const json::Value* v = m.payload.find(k);
      if (v && v->is_string()) {
        word = ascii_upper(v->as_string());
        break;
      }
    }
    if (word.empty()) word = "ESTOP";  // a SAFETY message that says nothing more stops the robot
  } else if (m.type == MessageType::kCommand) {
    word = ascii_upper(m.action());
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
    case SafetyAction::kEstop:
      return "ESTOP";
    case SafetyAction::kStop:
      return "STOP";
    case SafetyAction::kResume:
      return "RESUME";
    case SafetyAction::kNone:
      return "NONE";
  }
  return "NONE";
}

const json::Object* wire_of(const Context& ctx) {
  if (ctx.in.body.is_object()) return &ctx.in.body.as_object();  // before decoding; escalated
  return ctx.msg ? &ctx.msg->wire : nullptr;
}

std::string_view token_of(const Context& ctx) {
  if (!ctx.in.bearer.empty()) return ctx.in.bearer;
  const json::Object* wire = wire_of(ctx);
  if (const json::Value* t = wire ? wire->find("auth_token") : nullptr; t && t->is_string())
    return t->as_string();
  return {};
}

namespace {

// A refusal by the robot's safety gates (ESTOP latched, re-arm needed, safe stop, lockdown, a
// limit, prompt injection, the confidence gate, a human's denial): rcan-py's "blocked".
bool blocked_by_safety(const json::Value& payload) {
  const std::string code = json::string_field(payload, "error_code");
  const std::string reason = json::string_field(payload, "reason");
  if (code == "COMMAND_REJECTED")
    return reason == "estop_active" || reason == "rearm_required" || reason == "prompt_injection" ||
           reason == "limit_exceeded";
  return code == "SAFE_STOP" || code == "LOCKDOWN" || code == "CONFIDENCE_GATE_FAIL" ||
         code == "HITL_DENIED";
}

// The answer to an SDK-shaped message (rcan-py / rcan-ts: it has `cmd`) also carries the members
// rcan-py's RCANResponse.from_dict reads: `msg_id` (the message's id — rcan-ts's derived one —
// or the id it sent, when refused before decoding), `status` ("ok", "pending", "error", or
// "blocked" for a safety refusal, with `safety_approved` false and `safety_reason`), `result`
// (the command's result) and `message` for an error. The seed's members are unchanged.
void add_sdk_response_fields(const Context& ctx, json::Value& body) {
  const json::Object* wire = wire_of(ctx);
  if (!wire || !wire->contains("cmd")) return;
  if (!body.is_object()) return;
  json::Object& o = body.as_object();
  const std::string type = json::string_field(body, "type");
  std::string id = ctx.msg ? ctx.msg->message_id : std::string();
  if (!ctx.msg)
    if (const json::Value* v = wire->find("msg_id"); v && v->is_string()) id = v->as_string();
  o.set("msg_id", id.substr(0, 128));
  const json::Value* p = o.find("payload");
  if (type == "ACK") {
    o.set("status", "ok");
    if (const json::Value* r = p ? p->get("result") : nullptr; r && r->is_object())
      o.set("result", *r);
  } else if (type == "ERROR") {
    o.set("status", "error");
    if (p != nullptr) {
      o.set("message", json::string_field(*p, "error"));
      if (blocked_by_safety(*p)) {
        const std::string reason = json::string_field(*p, "reason");
        o.set("status", "blocked");
        o.set("safety_approved", false);
        o.set("safety_reason", reason.empty() ? json::string_field(*p, "error_code") : reason);
      }
    }
  } else if (type == "PENDING_AUTH") {
    o.set("status", "pending");
  }
}

}  // namespace

void Context::finish(Outcome out) {
  if (finished_) return;
  finished_ = true;
  out.authenticated = authenticated;
  add_sdk_response_fields(*this, out.body);
  if (done) done(std::move(out));
}

Stage::Result refuse(NodeServices& svc, const std::shared_ptr<Context>& ctx, const Error& err,
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
  const std::string event = audit_event.empty() ? "COMMAND_REJECTED" : audit_event;
  // Without a verified principal, or refused for its rate: one record per source and kind per
  // window, the rest counted into a summary (refusal_ledger.h) — a flood cannot fill the disk.
  if (!ctx->principal.authenticated || err.code == ErrorCode::kRateLimited) {
    const std::string source = ctx->principal.authenticated
                                   ? ctx->principal.key()
                                   : RefusalLedger::source_of(ctx->in.remote);
    if (!svc.trail.record_refusal(source, event, err.code, ctx->in.route)) {
      ctx->finish(std::move(out));
      return Stage::Result::kAnswered;
    }
  }
  AuditRecord r = message_record(
      svc, *ctx, event,
      err.code == ErrorCode::kAuditUnavailable || err.code == ErrorCode::kInternal ? "error"
                                                                                   : "blocked");
  audit::AuditEntry& e = r.entry();
  e.reason = err.reason.empty() ? std::string(error_name(err.code)) : err.reason;
  bool payload_free =
      err.code == ErrorCode::kReplayDetected || err.code == ErrorCode::kMessageStale ||
      err.code == ErrorCode::kMalformedJson || err.code == ErrorCode::kSchemaValidationFailed;
  if (ctx->action) {
    e.action = ctx->action->name;
  } else if (ctx->msg && !payload_free) {
    std::string action = ctx->msg->action();
    if (!action.empty()) e.action = action.substr(0, 128);
  }
  // §16.2: a refused AI command names its model too (not for replays: those record nothing sent).
  if (ctx->msg && ctx->msg->ai && err.code != ErrorCode::kReplayDetected &&
      err.code != ErrorCode::kMessageStale)
    e.ai = *ctx->msg->ai;
  e.detail = ctx->audit_detail;
  e.detail.set("error_code", std::string(error_name(err.code)));
  if (!err.field.empty()) e.detail.set("field", err.field.substr(0, 128));
  e.detail.set("transport", ctx->in.transport);
  e.detail.set("route", ctx->in.route);
  r.write();
  ctx->finish(std::move(out));
  return Stage::Result::kAnswered;
}

AuditRecord message_record(NodeServices& svc, const Context& ctx, const std::string& event,
                           const std::string& outcome) {
  AuditRecord r = svc.trail.record(event, outcome);
  if (ctx.principal.authenticated) r.by(ctx.principal);
  r.sender(ctx.sender);
  if (ctx.msg) r.message(ctx.msg->message_id);
  return r;
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
  // parse: arrival → here (routing and the JSON parse); total: arrival → answer ready. Timed
  // before the answer is handed over: whoever waits for it may tear the node down at once.
  parse_timer_->observe_us(static_cast<double>(ctx->started_mono_us - ctx->in.received_mono_us));
  ctx->done = [total = total_timer_, arrival = ctx->in.received_mono_us,
               done = std::move(done)](Outcome out) {
    total->observe_us(static_cast<double>(steady_us() - arrival));
    done(std::move(out));
  };
  ctx->pipeline = this;
  run(ctx, 0);
}

void Pipeline::run_from(const std::shared_ptr<Context>& ctx, std::string_view stage) {
  ctx->pipeline = this;
  for (size_t i = 0; i < stages_.size(); ++i)
    if (stage == stages_[i]->name()) return run(ctx, i);
  refuse(svc_, ctx, Error(ErrorCode::kInternal, "no pipeline stage named " + std::string(stage)),
         "INTERNAL_ERROR");
}

void Pipeline::run(const std::shared_ptr<Context>& ctx, size_t first) {
  for (size_t i = first; i < stages_.size(); ++i) {
    int64_t t0 = steady_us();
    Stage::Result r = stages_[i]->run(ctx);
    stage_timers_[i]->observe_us(static_cast<double>(steady_us() - t0));
    if (r != Stage::Result::kContinue) return;
  }
  if (!ctx->finished()) {
    refuse(svc_, ctx, Error(ErrorCode::kInternal, "the pipeline ended without an answer"),
           "INTERNAL_ERROR");
  }
}

}  // namespace rcan::node
