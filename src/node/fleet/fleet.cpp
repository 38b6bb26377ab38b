#include "node/fleet/fleet.h"

#include <algorithm>

#include "node/services/node_services.h"

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
    if (stop) return Result::kContinue;  // an ESTOP/STOP is refused only for failed authentication
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
  Result deny(const std::shared_ptr<Context>& ctx, std::string msg, std::string field) {
    return refuse(svc_, ctx,
                  Error(ErrorCode::kInsufficientPrivileges, std::move(msg), std::move(field)),
                  "COMMAND_REJECTED");
  }
  NodeServices& svc_;
};

}  // namespace

bool fleet_origin(const Context& ctx) { return ctx.fleet_command || !ctx.in.fleet_id.empty(); }

std::unique_ptr<Stage> make_fleet_stage(NodeServices& services) {
  return std::make_unique<FleetStage>(services);
}

}  // namespace rcan::node
