// AiServices: confidence-gate escalation, the HiTL queue, notifications, the watermark.
#include "node/ai/ai_services.h"

#include <pthread.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "base/strings.h"
#include "node/ai/brain_layers.h"
#include "node/pipeline/pipeline.h"
#include "node/services/node_services.h"
#include "rcan/crypto/watermark.h"
#include "rcan/errors.h"
#include "runtime/http_client.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

bool is_stream_channel(const std::string& n) {
  std::string l = ascii_lower(n);
  return l == "ws" || l == "websocket" || l == "stream" || l == "app";
}

}  // namespace

AiOptions ai_options(const config::NodeConfig& cfg) {
  AiOptions o;
  o.confidence_gates = cfg.agent.confidence_gates;
  o.hitl_gates = cfg.agent.hitl_gates;
  o.layers = {cfg.agent.reactive_layer, cfg.agent.fast_layer, cfg.agent.planner_layer};
  o.pending_file = cfg.data_dir + "/hitl-pending.json";
  o.thought_file = cfg.data_dir + "/thoughts.jsonl";
  return o;
}

AiServices::AiServices(NodeServices& svc, AiOptions opts)
    : svc_(svc), opts_(std::move(opts)), thoughts_(opts_.thought_capacity, opts_.thought_file) {}

AiServices::~AiServices() { shutdown(); }

Status AiServices::start(Pipeline& pipeline) {
  pipeline_ = &pipeline;
  auto thoughts = thoughts_.open();
  if (!thoughts.ok()) return thoughts.error();
  if (*thoughts > 0)
    log(LogLevel::kWarn, "thought_log_lines_skipped",
        json::Object{{"file", opts_.thought_file}, {"lines", static_cast<int64_t>(*thoughts)}});
  size_t skipped = 0;
  auto items = load_pending(opts_.pending_file, &skipped);
  if (!items.ok()) {
    // An unreadable file is kept aside for inspection; the node starts with nothing held.
    std::string aside = opts_.pending_file + ".unreadable-" + std::to_string(svc_.clock.wall_ms());
    if (std::rename(opts_.pending_file.c_str(), aside.c_str()) != 0)
      return Error(ErrorCode::kInternal, items.error().message + " (and it cannot be moved aside)");
    log(LogLevel::kError, "hitl_pending_unreadable",
        json::Object{{"error", items.error().message}, {"moved_to", aside}});
    svc_.trail.record("HITL_PENDING_LOST", "error")
        .by_system()
        .reason(items.error().message.substr(0, 256))
        .detail("moved_to", aside)
        .write();
    items = std::vector<PendingItem>{};
  }
  {
    MutexLock lock(mu_);
    for (auto& i : *items) pending_[i.message_id] = std::move(i);
  }
  if (!items->empty() || skipped)
    log(LogLevel::kInfo, "hitl_pending_restored",
        json::Object{{"pending", static_cast<int64_t>(items->size())},
                     {"skipped", static_cast<int64_t>(skipped)}});
  timer_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "hitl-timer");
    timer_loop();
  });
  return Status::Ok();
}

void AiServices::shutdown() {
  {
    MutexLock lock(mu_);
    if (quit_) return;
    quit_ = true;
  }
  cv_.notify_all();
  if (timer_.joinable()) timer_.join();
  net_.shutdown();
  disk_.shutdown();
}

// ------------------------------------------------------------------------------------------
// Confidence gates

const config::ConfidenceGate* AiServices::gate_for(const Context& ctx) const {
  if (opts_.confidence_gates.empty() || !ctx.msg) return nullptr;
  std::vector<std::string> scopes = ctx.msg->scope;
  if (ctx.capability) {
    scopes.emplace_back(capability_scope(*ctx.capability));
    std::string name(capability_name(*ctx.capability));
    scopes.push_back(name);
    if (*ctx.capability == Capability::kNavigation) scopes.emplace_back("nav");
  }
  for (const auto& g : opts_.confidence_gates)
    if (std::find(scopes.begin(), scopes.end(), g.scope) != scopes.end()) return &g;
  return nullptr;
}

std::optional<std::pair<int, config::AgentLayer>> AiServices::layer_above(int rank) const {
  for (int r = std::max(rank + 1, 0); r < 3; ++r)
    if (opts_.layers[static_cast<size_t>(r)])
      return std::make_pair(r, *opts_.layers[static_cast<size_t>(r)]);
  return std::nullopt;
}

void AiServices::escalate(const std::shared_ptr<Context>& ctx, const config::ConfidenceGate& gate,
                          int to_rank, const config::AgentLayer& layer) {
  const Message& m = *ctx->msg;
  std::string to(layer_name(to_rank));
  std::string from = m.ai && m.ai->layer ? *m.ai->layer : "";
  std::string from_thought = m.ai && m.ai->thought_id ? *m.ai->thought_id : m.message_id;
  // The refused command is recorded with its own ai block before the layer is asked.
  AuditRecord r = message_record(svc_, *ctx, "CONFIDENCE_GATE_ESCALATED", "blocked");
  if (m.ai) r.entry().ai = *m.ai;
  r.entry().detail = ctx->audit_detail;
  r.action(m.action())
      .reason("confidence_below_gate_escalate")
      .detail("to_layer", to)
      .detail("layer_url", layer.url)
      .write();
  config::ConfidenceGate g = gate;
  bool posted = net_.post([this, ctx, g, to, from, from_thought, layer] {
    const Message& orig = *ctx->msg;
    json::Value req = layer_request(orig, to, svc_.settings.ruri, g.scope, g.min_confidence);
    std::string problem;
    std::optional<Message> next;
    LayerReply reply;
    auto url = parse_http_url(layer.url);
    if (!url.ok()) {
      problem = url.error().message;
    } else {
      auto ans = http_post_json(*url, json::dump(req), static_cast<int>(layer.timeout_ms));
      if (!ans.ok()) {
        problem = ans.error().message;
      } else if (ans->status != 200) {
        problem = "the layer answered HTTP " + std::to_string(ans->status);
      } else {
        auto parsed = parse_layer_reply(ans->body);
        if (!parsed.ok()) {
          problem = "the layer's answer is invalid: " + parsed.error().message;
        } else {
          reply = std::move(parsed).value();
          auto msg = escalated_message(orig, reply, to, svc_.settings.codec);
          if (!msg.ok())
            problem = "the layer's command is invalid: " + msg.error().message;
          else
            next = std::move(msg).value();
        }
      }
    }
    json::Object esc{{"from_layer", from.empty() ? json::Value() : json::Value(from)},
                     {"to_layer", to},
                     {"escalated_from", from_thought}};
    if (orig.ai && orig.ai->confidence) esc.set("from_confidence", *orig.ai->confidence);
    if (!next) {
      esc.set("error", problem.substr(0, 512));
      ctx->audit_detail.set("escalation", esc);
      refuse(svc_, ctx,
             Error(ErrorCode::kConfidenceGateFail,
                   "confidence below the " + g.scope + " gate and escalation to the " + to +
                       " layer failed: " + problem.substr(0, 256),
                   "ai.confidence", "escalation_failed"),
             "CONFIDENCE_GATE_FAIL");
      return;
    }
    // The layer's thought, naming what it escalated from.
    Thought t = thought_from_command(*next, reply.thought.is_object() ? &reply.thought : nullptr,
                                     svc_.clock.wall_ms());
    if (t.id.empty()) t.id = "th_" + new_uuid_v4();
    t.layer = to;
    t.escalated_from = from_thought;
    t.principal = ctx->principal.key();
    if (!thoughts_.put(t)) {  // the layer named an id someone else's thought holds: a new one
      t.id = "th_" + new_uuid_v4();
      (void)thoughts_.put(t);
    }
    next->ai->thought_id = t.id;
    esc.set("thought_id", t.id);
    ctx->audit_detail.erase("confidence_gate");
    ctx->audit_detail.set("escalation", esc);
    // What was received stays what the answer and the later stages read (wire_of): an SDK
    // message's msg_id and shape, its rearm flag.
    if (!ctx->in.body.is_object()) ctx->in.body = json::Value(std::move(ctx->msg->wire));
    ctx->msg = std::move(next);
    ctx->capability.reset();
    ctx->action = nullptr;
    // The new command is authorised, screened and gated again like any other.
    if (ctx->pipeline) ctx->pipeline->run_from(ctx, "authorize");
  });
  if (!posted)
    refuse(svc_, ctx,
           Error(ErrorCode::kSafeStop, "the node is busy; escalation could not be queued"),
           "CONFIDENCE_GATE_FAIL");
}

// ------------------------------------------------------------------------------------------
// HiTL

const config::HitlGate* AiServices::hitl_gate_for(const std::string& action) const {
  if (action.empty()) return nullptr;
  // Both sides canonical: a gate on `arm_move` holds `set_joints` too, and a gate naming a
  // synonym holds the action it names. A gate naming no known action matches that name only.
  auto canonical = [&](const std::string& name) {
    const ActionSpec* s = svc_.actions.find(name);
    return s ? s->name : ascii_lower(name);
  };
  std::string a = canonical(action);
  for (const auto& g : opts_.hitl_gates) {
    if (!g.require_auth) continue;
    for (const auto& t : g.action_types)
      if (canonical(t) == a) return &g;
  }
  return nullptr;
}

void AiServices::persist_locked() {
  std::vector<PendingItem> items;
  for (const auto& [id, i] : pending_) items.push_back(i);
  if (Status s = save_pending(opts_.pending_file, items); !s.ok())
    log(LogLevel::kError, "hitl_pending_write_failed", json::Object{{"error", s.error().message}});
}

bool AiServices::hold(const std::shared_ptr<Context>& ctx, const config::HitlGate& gate,
                      const std::string& action_type) {
  const Message& m = *ctx->msg;
  int64_t now = svc_.clock.wall_ms();
  PendingItem it;
  it.message_id = m.message_id;
  it.action_type = action_type;
  it.description = ctx->principal.display() + " asks for " + action_type +
                   (m.ai ? " (AI-produced by " + m.ai->provider + "/" + m.ai->model + ")" : "") +
                   "; it needs OWNER or CREATOR approval";
  it.auth_timeout_ms = gate.auth_timeout_ms;
  it.created_ms = now;
  it.expires_at_ms = now + gate.auth_timeout_ms;
  it.allow_on_timeout = gate.on_timeout == config::HitlOnTimeout::kAllow;
  it.authorized_roles = gate.authorized_roles;
  it.notify = gate.notify;
  EncodeOptions eo;
  eo.include_auth_token = false;
  it.message = encode_message(m, eo);
  it.issuer = ctx->principal.issuer;
  it.sub = ctx->principal.sub;
  it.role = ctx->principal.role;
  it.scopes = ctx->principal.scopes;
  it.sender = ctx->sender;
  it.transport = ctx->in.transport;
  it.route = ctx->in.route;
  it.audit_detail = ctx->audit_detail;
  it.gate_bypassed = ctx->gate_bypassed;
  if (m.ai) {
    it.thought_id = m.ai->thought_id.value_or("");
    it.confidence = m.ai->confidence;
    it.model = m.ai->model;
  }
  {
    MutexLock lock(mu_);
    if (absorb_wall_step_locked(svc_.clock.mono_ms(), now)) persist_locked();
    // Message ids are unique per principal only (replay.h): another principal's command with
    // the id of a held one must not take its place (an approval names the id).
    if (!pending_.emplace(it.message_id, it).second) return false;
  }
  cv_.notify_all();
  audit::AuditEntry e = std::move(message_record(svc_, *ctx, "HITL_PENDING", "blocked").entry());
  if (m.ai) e.ai = *m.ai;
  e.action = action_type;
  e.reason = "hitl_authorization_required";
  e.gate_bypassed = ctx->gate_bypassed;
  e.detail = ctx->audit_detail;
  e.detail.set("auth_timeout_ms", static_cast<int64_t>(gate.auth_timeout_ms));
  e.detail.set("expires_at_ms", it.expires_at_ms);
  e.detail.set("on_timeout", it.allow_on_timeout ? "allow" : "block");
  json::Array notify;
  for (const auto& n : gate.notify) notify.emplace_back(n);
  e.detail.set("notify", notify);
  e.detail.set("transport", ctx->in.transport);
  e.detail.set("route", ctx->in.route);
  json::Value event = svc_.envelope(MessageType::kPendingAuth, it.public_view(now), m.message_id);
  // The pending file is written off the transport thread; the sender hears 202 once it holds
  // the command.
  auto job = [this, ctx, it, event, e = std::move(e)]() mutable {
    {
      MutexLock lock(mu_);
      persist_locked();
    }
    svc_.trail.write(std::move(e));
    notify_owners(event);
    post_webhooks(it, event);
    ctx->finish(Outcome{202, event, {}});
  };
  auto shared = std::make_shared<decltype(job)>(std::move(job));
  if (!disk_.post([shared] { (*shared)(); })) (*shared)();
  return true;
}

void AiServices::post_webhooks(const PendingItem& item, const json::Value& event) {
  for (const auto& n : item.notify) {
    if (is_stream_channel(n)) continue;
    if (n.rfind("http://", 0) != 0) {
      log(LogLevel::kWarn, "hitl_notify_unsupported",
          json::Object{{"channel", n.substr(0, 128)}, {"message_id", item.message_id}});
      continue;
    }
    std::string body = json::dump(event);
    std::string url = n;
    std::string id = item.message_id;
    int timeout = opts_.webhook_timeout_ms;
    net_.post([url, body, id, timeout] {
      auto u = parse_http_url(url);
      auto r = u.ok() ? http_post_json(*u, body, timeout) : Result<HttpAnswer>(u.error());
      if (!r.ok() || r->status / 100 != 2)
        log(LogLevel::kWarn, "hitl_webhook_failed",
            json::Object{
                {"url", url.substr(0, 256)},
                {"message_id", id},
                {"error", r.ok() ? "HTTP " + std::to_string(r->status) : r.error().message}});
    });
  }
}

void AiServices::notify_owners(json::Value event) {
  svc_.events.publish(std::move(event), Audience::at_least(Role::kOwner));
}

void AiServices::notify_principal(const std::string& principal_key, json::Value event) {
  svc_.events.publish(std::move(event), Audience::principal(principal_key));
}

json::Value AiServices::pending_list() const {
  int64_t now = svc_.clock.wall_ms();
  json::Array arr;
  MutexLock lock(mu_);
  for (const auto& [id, i] : pending_) arr.push_back(i.public_view(now));
  return json::Object{{"pending", arr}, {"count", static_cast<int64_t>(arr.size())}};
}

size_t AiServices::pending_count() const {
  MutexLock lock(mu_);
  return pending_.size();
}

std::shared_ptr<Context> AiServices::rebuild(const PendingItem& item, Error& err) {
  auto ctx = std::make_shared<Context>();
  ctx->in.body = item.message;
  ctx->in.transport = item.transport;
  ctx->in.route = item.route;
  ctx->principal.authenticated = true;
  ctx->principal.issuer = item.issuer;
  ctx->principal.sub = item.sub;
  ctx->principal.role = item.role;
  ctx->principal.scopes = item.scopes;
  ctx->sender = item.sender;
  ctx->audit_detail = item.audit_detail;
  ctx->gate_bypassed = item.gate_bypassed;
  ctx->pipeline = pipeline_;
  auto m = decode_message(item.message, svc_.settings.codec);
  if (!m.ok()) {
    err = m.error();
    return ctx;
  }
  ctx->msg = std::move(m).value();
  ctx->action = svc_.actions.find(ctx->msg->action());
  if (!ctx->action) {  // held before the table changed under it: refuse, never default
    err =
        Error(ErrorCode::kCommandRejected, "the held command's action is not one this robot knows",
              "payload.action", "unknown_action");
    return ctx;
  }
  ctx->capability = ctx->action->capability;
  if (capability_scope(*ctx->capability) == "control") {
    auto holder = svc_.control.sessions().controller(svc_.clock.mono_ms());
    if (holder) {
      if (holder->principal_key != ctx->principal.key()) {
        err = Error(ErrorCode::kControlConflict,
                    "another principal holds control now; the approved command was not dispatched",
                    "session");
        return ctx;
      }
      ctx->session_id = holder->id;
    }
  }
  err = Error(ErrorCode::kInternal, "");  // marks success: message empty
  return ctx;
}

void AiServices::dispatch_held(const PendingItem& item, json::Object extra_detail,
                               bool timeout_bypass, std::function<void(Outcome)> done) {
  Error err(ErrorCode::kInternal, "");
  auto ctx = rebuild(item, err);
  ctx->audit_detail.set("hitl", extra_detail);
  ctx->hitl_timeout_bypass = timeout_bypass;
  ctx->done = std::move(done);
  if (!err.message.empty() || !ctx->msg || !pipeline_) {
    if (err.message.empty())
      err = Error(ErrorCode::kInternal, "the held command could not be restored");
    refuse(svc_, ctx, err, "COMMAND_REJECTED");
    return;
  }
  pipeline_->run_from(ctx, "watermark");
}

void AiServices::authorize(const Principal& p, const json::Value& body,
                           const std::string& transport, const std::string& route,
                           std::function<void(int, json::Value)> done) {
  auto parsed = parse_authorize(body);
  if (!parsed.ok()) return done(http_status(parsed.error().code), svc_.error(parsed.error()));
  // The decision changes the pending file: it runs on the disk worker, in order.
  bool posted = disk_.post([this, p, req = std::move(parsed).value(), transport, route, done] {
    decide(p, req, transport, route, done);
  });
  if (!posted) done(503, svc_.error(Error(ErrorCode::kSafeStop, "the node is busy; try again")));
}

void AiServices::decide(const Principal& p, const AuthorizeRequest& request,
                        const std::string& transport, const std::string& route,
                        const std::function<void(int, json::Value)>& done) {
  const AuthorizeRequest* req = &request;
  std::optional<PendingItem> item;
  {
    MutexLock lock(mu_);
    auto it = pending_.find(req->target);
    if (it == pending_.end())
      for (auto i = pending_.begin(); i != pending_.end(); ++i)
        if (!i->second.thought_id.empty() && i->second.thought_id == req->target) it = i;
    if (it != pending_.end()) item = it->second;
  }
  std::string original = item ? item->message_id : req->target;
  bool allowed = item ? std::find(item->authorized_roles.begin(), item->authorized_roles.end(),
                                  p.role) != item->authorized_roles.end()
                      : role_level(p.role) >= role_level(Role::kOwner);
  auto record = [&](const std::string& event, const std::string& outcome) {
    audit::AuditEntry e =
        std::move(svc_.trail.record(event, outcome).by(p).message(original).entry());
    if (item) e.action = item->action_type;
    e.detail.set("authorize_message_id", req->authorize_id);
    e.detail.set("decision", req->approve ? "approve" : "deny");
    e.detail.set("authorizer_role", std::string(role_name(p.role)));
    if (!req->reason.empty()) e.reason = req->reason;
    if (item) e.detail.set("requested_by", item->sub);
    e.detail.set("transport", transport);
    e.detail.set("route", route);
    return e;
  };
  if (!allowed) {
    auto e = record("HITL_AUTHORIZE_REFUSED", "blocked");
    e.reason = "INSUFFICIENT_PRIVILEGES";
    svc_.trail.write(std::move(e));
    Error err(
        ErrorCode::kInsufficientPrivileges,
        std::string(role_name(p.role)) + " may not authorize held commands (OWNER or CREATOR only)",
        "role");
    return done(http_status(err.code), svc_.error(err, req->authorize_id));
  }
  if (!item) {
    Error err(ErrorCode::kNotFound,
              "no command is waiting for authorization under " + req->target.substr(0, 64),
              "payload.message_id");
    return done(404, svc_.error(err, req->authorize_id));
  }
  {
    MutexLock lock(mu_);
    if (!pending_.erase(item->message_id)) {
      Error err(ErrorCode::kNotFound, "the command was decided meanwhile", "payload.message_id");
      return done(404, svc_.error(err, req->authorize_id));
    }
    persist_locked();
  }
  std::string originator = item->principal_key();
  if (req->approve) {
    svc_.trail.write(record("HITL_APPROVED", "ok"));
    json::Object hitl{{"decision", "approve"},
                      {"authorized_by", p.display()},
                      {"authorize_message_id", req->authorize_id}};
    dispatch_held(*item, hitl, false, [this, done, originator](Outcome out) {
      notify_principal(originator, out.body);
      done(out.status, out.body);
    });
    return;
  }
  svc_.trail.write(record("HITL_DENIED", "blocked"));
  Error denied(ErrorCode::kHitlDenied,
               "the held " + item->action_type + " command was denied by " + p.display() +
                   (req->reason.empty() ? "" : ": " + req->reason),
               "", "hitl_denied");
  notify_principal(originator, svc_.error(denied, item->message_id));
  done(200, svc_.envelope(
                MessageType::kAck,
                json::Object{
                    {"message_id", item->message_id}, {"decision", "deny"}, {"dispatched", false}},
                req->authorize_id));
}

bool AiServices::absorb_wall_step_locked(int64_t now_mono_ms, int64_t now_wall_ms) {
  bool moved = false;
  if (anchor_mono_ms_ >= 0) {
    int64_t step = (now_wall_ms - anchor_wall_ms_) - (now_mono_ms - anchor_mono_ms_);
    if (step > 2000 || step < -2000) {
      for (auto& [id, i] : pending_) {
        i.created_ms += step;
        i.expires_at_ms += step;
        moved = true;
      }
    }
  }
  anchor_mono_ms_ = now_mono_ms;
  anchor_wall_ms_ = now_wall_ms;
  return moved;
}

void AiServices::timer_loop() {
  ReleasableMutexLock lock(mu_);
  while (!quit_) {
    int64_t now = svc_.clock.wall_ms();
    if (absorb_wall_step_locked(svc_.clock.mono_ms(), now)) persist_locked();
    std::vector<PendingItem> expired;
    int64_t next = now + 200;
    for (auto it = pending_.begin(); it != pending_.end();) {
      if (it->second.expires_at_ms <= now) {
        expired.push_back(std::move(it->second));
        it = pending_.erase(it);
      } else {
        next = std::min(next, it->second.expires_at_ms);
        ++it;
      }
    }
    if (!expired.empty()) {
      persist_locked();
      lock.unlock();
      for (auto& i : expired) settle_timeout(std::move(i));
      lock.lock();
      continue;
    }
    cv_.wait_for(mu_, std::chrono::milliseconds(std::clamp<int64_t>(next - now, 1, 200)));
  }
}

void AiServices::settle_timeout(PendingItem item) {
  std::string originator = item.principal_key();
  AuditRecord r = svc_.trail.record("HITL_TIMEOUT", item.allow_on_timeout ? "ok" : "blocked");
  r.by_subject(item.sub).sender(item.sender).message(item.message_id);
  r.entry().hitl_timeout_bypass = item.allow_on_timeout;
  r.action(item.action_type)
      .reason(item.allow_on_timeout ? "hitl_timeout_allow" : "hitl_timeout")
      .detail("auth_timeout_ms", static_cast<int64_t>(item.auth_timeout_ms))
      .detail("on_timeout", item.allow_on_timeout ? "allow" : "block")
      .write();
  if (!item.allow_on_timeout) {
    Error err(ErrorCode::kHitlTimeout,
              "no OWNER or CREATOR authorized the held " + item.action_type + " command within " +
                  std::to_string(item.auth_timeout_ms) + " ms",
              "", "hitl_timeout");
    notify_principal(originator, svc_.error(err, item.message_id));
    return;
  }
  json::Object hitl{{"decision", "timeout"}, {"on_timeout", "allow"}};
  dispatch_held(item, hitl, true,
                [this, originator](Outcome out) { notify_principal(originator, out.body); });
}

// ------------------------------------------------------------------------------------------

std::string AiServices::watermark(const std::string& thought_id,
                                  const std::string& timestamp_iso) const {
  return watermark::compute(opts_.watermark_key.span(), svc_.settings.rrn, thought_id,
                            timestamp_iso);
}

}  // namespace rcan::node
