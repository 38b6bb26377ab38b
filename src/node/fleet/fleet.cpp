#include "node/fleet/fleet.h"

#include <algorithm>
#include <atomic>
#include <mutex>

#include "node/fleet/estop_ledger.h"
#include "node/services/node_services.h"
#include "runtime/log.h"

namespace rcan::node {

namespace {

std::string payload_string(const Message& m, const char* key) {
  const json::Value* v = m.payload.find(key);
  return v != nullptr && v->is_string() ? v->as_string() : std::string();
}

class FleetStage final : public Stage {
 public:
  explicit FleetStage(NodeServices& s) : svc_(s) {}
  const char* name() const override { return "fleet"; }
  Result run(const std::shared_ptr<Context>& ctx) override {
    if (!fleet_origin(*ctx)) return Result::kContinue;
    const Message& m = *ctx->msg;
    bool stop = ctx->safety == SafetyAction::kEstop || ctx->safety == SafetyAction::kStop;
    const FleetMembership* fleet = svc_.fleet.get();
    std::string claimed = payload_string(m, "fleet_id");
    if (fleet == nullptr) {
      if (stop) return Result::kContinue;
      return deny(ctx, "this robot is in no fleet", "fleet_id");
    }
    const auto& cfg = fleet->config;
    ctx->audit_detail.set("fleet_id", cfg.fleet_id);
    if (!ctx->in.fleet_mode.empty()) ctx->audit_detail.set("fleet_mode", ctx->in.fleet_mode);
    if (ctx->in.mqtt_qos >= 0) ctx->audit_detail.set("mqtt_qos", ctx->in.mqtt_qos);
    if (const json::Value* step = m.payload.find("step"); step != nullptr && step->is_int())
      ctx->audit_detail.set("fleet_step", step->as_int());
    if (std::string cid = payload_string(m, "choreography_id"); !cid.empty() && cid.size() <= 64)
      ctx->audit_detail.set("choreography_id", cid);
    // The fleet's own ESTOPs and RESUMEs, on its topics: the ledger bounds a standing ESTOP.
    if (ctx->in.fleet_id == cfg.fleet_id &&
        (ctx->safety == SafetyAction::kEstop || ctx->safety == SafetyAction::kResume)) {
      if (Result r = bound_standing_order(ctx, cfg); r != Result::kContinue) return r;
    }
    // An ESTOP/STOP is refused only for failed authentication, or as a replay of one the fleet
    // has resumed since (above).
    if (stop) return Result::kContinue;
    if ((!ctx->in.fleet_id.empty() && ctx->in.fleet_id != cfg.fleet_id) ||
        (!claimed.empty() && claimed != cfg.fleet_id))
      return deny(ctx,
                  "this robot is not in fleet " + (claimed.empty() ? ctx->in.fleet_id : claimed),
                  "fleet_id");
    // A fleet message carries a fleet JWT; its `fleet` claim lists this robot (checked by
    // the verifier against the member id, device id, RURI and RRN).
    if (!ctx->principal.fleet)
      return deny(ctx, "fleet commands need a fleet token (a JWT with a `fleet` claim)",
                  "auth_token");
    if (ctx->in.fleet_mode == "broadcast" && !cfg.broadcast)
      return deny(ctx, "fleet " + cfg.fleet_id + " does not accept broadcast commands",
                  "fleet_mode");
    if (ctx->in.fleet_mode == "individual" && !cfg.individual)
      return deny(ctx, "fleet " + cfg.fleet_id + " does not accept individual commands",
                  "fleet_mode");
    if (m.payload.find("choreography_id") != nullptr && !cfg.choreographed)
      return deny(ctx, "fleet " + cfg.fleet_id + " does not accept choreographed commands",
                  "choreography_id");
    if (fleet->conflict) {
      if (auto err = fleet->conflict(*ctx, svc_)) {
        return refuse(svc_, ctx, *err, "COMMAND_REJECTED");
      }
    }
    return Result::kContinue;
  }

 private:
  std::shared_ptr<FleetEstopLedger> ledger(const config::FleetConfig& cfg) {
    std::call_once(ledger_once_, [&] {
      const std::string& dir = svc_.settings.state_dir;
      ledger_ = std::make_shared<FleetEstopLedger>(dir.empty() ? "" : dir + "/fleet_estops.json",
                                                   cfg.fleet_id, cfg.member_id,
                                                   svc_.clock.wall_ms() / 1000);
      // The counter outlives the stage if /metrics is rendered after the pipeline is gone.
      svc_.metrics.add_counter_fn(
          "rcan_fleet_estop_replays_refused_total",
          "Fleet ESTOPs refused because the fleet had resumed the robot since (a replay)",
          [n = refused_] { return static_cast<double>(n->load()); });
    });
    return ledger_;
  }

  // A fleet ESTOP the fleet has resumed since is refused (a replay: its token and signature are
  // still good); an ESTOP obeyed and a RESUME applied are remembered once the robot has acted
  // on them (the answer is an ACK), never before: a RESUME refused for its role must not
  // supersede anything.
  Result bound_standing_order(const std::shared_ptr<Context>& ctx, const config::FleetConfig& cfg) {
    const Message& m = *ctx->msg;
    auto book = ledger(cfg);
    if (ctx->safety == SafetyAction::kEstop) {
      auto verdict = book->judge(m.message_id, m.timestamp_ms, ctx->in.standing_estop);
      if (verdict != FleetEstopLedger::Verdict::kObey) {
        const char* why = verdict == FleetEstopLedger::Verdict::kSuperseded
                              ? "superseded_by_fleet_resume"
                              : "older_than_fleet_resume";
        ++*refused_;
        ctx->audit_detail.set("fleet_estop_refused", why);
        ctx->audit_detail.set("last_fleet_resume_timestamp_ms", book->last_resume_ms());
        const int64_t now = svc_.clock.mono_ms();
        if (int64_t last = logged_mono_.load(); last == 0 || now - last >= 10'000) {
          logged_mono_.store(now);  // at most every 10 s: each copy is audited anyway
          log(LogLevel::kWarn, "fleet_estop_replay_refused",
              json::Object{{"message_id", m.message_id},
                           {"reason", why},
                           {"standing", ctx->in.standing_estop},
                           {"refused", static_cast<int64_t>(refused_->load())}});
        }
        return refuse(svc_, ctx,
                      Error(ErrorCode::kMessageStale,
                            "this fleet ESTOP was superseded by the fleet's RESUME (a replay)",
                            "message_id", why),
                      "MESSAGE_STALE");
      }
    }
    auto done = std::move(ctx->done);
    ctx->done = [done = std::move(done), book, estop = ctx->safety == SafetyAction::kEstop,
                 id = m.message_id, ts = m.timestamp_ms, exp = ctx->principal.token_exp,
                 clock = &svc_.clock](Outcome out) {
      const bool acted = out.status == 200 && json::string_field(out.body, "type") == "ACK";
      const int64_t now_s = clock->wall_ms() / 1000;
      if (acted && !estop) book->resumed(ts, now_s);  // before the answer: RESUME then ESTOP
      done(std::move(out));
      if (acted && estop) book->honoured(id, ts, exp, now_s);  // after: the stop comes first
    };
    return Result::kContinue;
  }

  Result deny(const std::shared_ptr<Context>& ctx, std::string msg, std::string field) {
    return refuse(svc_, ctx,
                  Error(ErrorCode::kInsufficientPrivileges, std::move(msg), std::move(field)),
                  "COMMAND_REJECTED");
  }
  NodeServices& svc_;
  std::once_flag ledger_once_;
  std::shared_ptr<FleetEstopLedger> ledger_;
  std::shared_ptr<std::atomic<uint64_t>> refused_ = std::make_shared<std::atomic<uint64_t>>(0);
  std::atomic<int64_t> logged_mono_{0};
};

}  // namespace

bool fleet_origin(const Context& ctx) { return ctx.fleet_command || !ctx.in.fleet_id.empty(); }

std::unique_ptr<Stage> make_fleet_stage(NodeServices& services) {
  return std::make_unique<FleetStage>(services);
}

}  // namespace rcan::node
