// SafetyActuation: the pipeline's Actuation over the SafetyCore. It turns a COMMAND's action
// and parameters into an ActuatorCommand (docs/NODE.md §Commands), asks the core to check it
// (limits, ESTOP, deadline) without applying, and applies it once the audit record is durable.
#include <algorithm>
#include <cmath>

#include "node/safety/actuation_safety.h"
#include "node/safety/sim_robot.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

Error bad_param(std::string field, std::string msg) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), "payload." + field);
}

// A COMMAND's parameters: flat in the payload or under "params"/"parameters", in that order of
// precedence (looked up in place, not merged into a copy).
class Params {
 public:
  explicit Params(const json::Object& payload) : flat_(payload) {
    int i = 0;
    for (const char* k : {"params", "parameters"})
      if (const json::Value* inner = payload.find(k); inner && inner->is_object())
        nested_[i++] = &inner->as_object();
  }
  // The first of the three that has `name` (even as null) decides.
  const json::Value* find(std::string_view name) const {
    if (const json::Value* v = flat_.find(name)) return v;
    for (const json::Object* o : nested_)
      if (o)
        if (const json::Value* v = o->find(name)) return v;
    return nullptr;
  }

 private:
  const json::Object& flat_;
  const json::Object* nested_[2] = {nullptr, nullptr};
};

// First present numeric parameter among `names`; error when present but not a finite number.
Result<std::optional<double>> number(const Params& p, std::initializer_list<const char*> names) {
  for (const char* n : names) {
    const json::Value* v = p.find(n);
    if (!v || v->is_null()) continue;
    if (!v->is_number()) return bad_param(n, std::string(n) + " must be a number");
    double d = v->to_double();
    if (!std::isfinite(d)) return bad_param(n, std::string(n) + " must be finite");
    return std::optional<double>(d);
  }
  return std::optional<double>();
}

}  // namespace

Result<ActuatorCommand> translate_command(const ActionSpec& spec, const Message& msg,
                                          const SafetyLimits& limits) {
  const std::string& action = spec.name;  // canonical: synonyms are folded by the table
  const Params params(msg.payload);
  if (spec.kind == ActionKind::kDrive) {
    auto lin =
        number(params, {"linear", "linear_x", "linear_mps", "speed", "speed_mps", "velocity"});
    if (!lin.ok()) return lin.error();
    auto ang = number(params, {"angular", "angular_z", "angular_radps", "yaw_rate"});
    if (!ang.ok()) return ang.error();
    auto dur_ms = number(params, {"duration_ms"});
    if (!dur_ms.ok()) return dur_ms.error();
    auto dur_s = number(params, {"duration_s", "duration"});
    if (!dur_s.ok()) return dur_s.error();
    auto dist = number(params, {"distance_m", "distance"});
    if (!dist.ok()) return dist.error();
    double linear = lin->value_or(0.0);
    double angular = ang->value_or(0.0);
    if (action == "move_forward" && !*lin) linear = std::min(0.3, limits.max_linear_mps);
    if (action == "move_backward")
      linear = -std::fabs(*lin ? linear : std::min(0.3, limits.max_linear_mps));
    if ((action == "turn_left" || action == "turn_right") && !*ang)
      angular = std::min(0.5, limits.max_angular_radps);
    if (action == "turn_right") angular = -std::fabs(angular);
    int64_t duration = 0;
    if (*dur_ms)
      duration = static_cast<int64_t>(**dur_ms);
    else if (*dur_s)
      duration = static_cast<int64_t>(**dur_s * 1000.0);
    else if (*dist && std::fabs(linear) > 1e-6)
      duration = static_cast<int64_t>(std::fabs(**dist / linear) * 1000.0);
    if (duration < 0) return bad_param("duration_ms", "duration must not be negative");
    if (!*lin && !*ang && action != "move_forward" && action != "move_backward" &&
        action != "turn_left" && action != "turn_right")
      return bad_param("linear", "a drive command needs linear and/or angular");
    return ActuatorCommand::make_drive(linear, angular, duration);
  }
  if (spec.kind == ActionKind::kArm) {
    JointArray targets{};
    if (action == "arm_home") return ActuatorCommand::make_arm(targets);
    const json::Value* j = nullptr;
    for (const char* k : {"joints", "joints_rad", "targets", "positions"}) {
      if ((j = params.find(k))) break;
    }
    if (!j) return bad_param("joints", "an arm command needs joints: 6 target angles in radians");
    if (!j->is_array() || j->as_array().size() != static_cast<size_t>(kArmJoints))
      return bad_param("joints", "joints must be an array of 6 numbers (radians)");
    for (int i = 0; i < kArmJoints; ++i) {
      const json::Value& e = j->as_array()[static_cast<size_t>(i)];
      if (!e.is_number() || !std::isfinite(e.to_double()))
        return bad_param("joints", "joints must be finite numbers");
      targets[static_cast<size_t>(i)] = e.to_double();
    }
    auto speed = number(params, {"max_joint_speed_radps", "joint_speed", "speed"});
    if (!speed.ok()) return speed.error();
    return ActuatorCommand::make_arm(targets, speed->value_or(0.0));
  }
  if (spec.kind == ActionKind::kGripper) {
    ActuatorCommand c;
    c.gripper = action == "gripper_open" ? GripperAction::kOpen : GripperAction::kClose;
    return c;
  }
  // The one skill the simulated robot offers: scan_environment turns it slowly on the spot
  // (duration_ms, default 2 s) so that its sensors sweep the room.
  if (action == "scan_environment") {
    auto dur_ms = number(params, {"duration_ms"});
    if (!dur_ms.ok()) return dur_ms.error();
    double ms = dur_ms->value_or(2000.0);
    if (ms < 0) return bad_param("duration_ms", "duration must not be negative");
    return ActuatorCommand::make_drive(0.0, std::min(0.5, limits.max_angular_radps),
                                       static_cast<int64_t>(ms));
  }
  // A skill (or anything else) the simulated robot has no behaviour for.
  return Error(ErrorCode::kCommandRejected,
               "the robot cannot do '" + action + "' (" + std::string(action_kind_name(spec.kind)) +
                   " it does not offer)",
               "payload.action", "unsupported_action");
}

SafetyActuation::SafetyActuation(SafetyCore& core, std::string robot_name)
    : core_(core), robot_name_(std::move(robot_name)) {}

bool SafetyActuation::estop_active() const { return core_.estop_active(); }
uint64_t SafetyActuation::estop_epoch() const { return core_.estop_epoch(); }

double SafetyActuation::estop(const std::string& source, const std::string& reason, Role by,
                              EstopLatchFn on_latch, bool persist_here) {
  EstopResult r = core_.estop(source, reason, role_level(by), !persist_here);
  // Written here first, the latch is durable before the waiter is registered: answered at once,
  // no timer armed on the control loop.
  if (persist_here) core_.persist_here_if_idle();
  if (on_latch) core_.when_persisted(r.state_seq, std::move(on_latch));
  return static_cast<double>(r.stop_latency_ns) / 1000.0;
}

Status SafetyActuation::resume(Role role, const std::string& source) {
  return core_.resume(role_level(role), source);
}

void SafetyActuation::stop(const std::string& source) {
  (void)source;
  (void)core_.dispatch(ActuatorCommand::make_stop());
}

Result<PreparedCommand> SafetyActuation::prepare(const Message& msg, const ActionSpec& spec,
                                                 int64_t deadline_mono_ms,
                                                 const std::string& session_id,
                                                 std::optional<uint64_t> stream_epoch) {
  PreparedCommand pc;
  pc.deadline_mono_ms = deadline_mono_ms;
  pc.session_id = session_id;
  pc.stream_epoch = stream_epoch;
  pc.action_name = spec.name;
  const std::string& action = pc.action_name;
  if (spec.kind == ActionKind::kInformational) {
    if (action == "chat") {
      for (const char* k : {"text", "message", "question", "instruction", "prompt"}) {
        const json::Value* v = msg.payload.find(k);
        if (v && v->is_string()) {
          pc.question = v->as_string();
          break;
        }
      }
    }
    pc.action = json::Object{{"informational", action}};
    return pc;
  }
  auto cmd = translate_command(spec, msg, core_.limits());
  if (!cmd.ok()) return cmd.error();
  DispatchOptions opts;
  opts.deadline_mono_ms = deadline_mono_ms;
  opts.session_id = session_id;
  opts.stream_epoch = stream_epoch;
  auto checked = core_.check(*cmd, opts);
  if (!checked.ok()) return checked.error();
  pc.clamped = checked->clamped;
  for (const auto& c : checked->clamps) pc.clamp_note += (pc.clamp_note.empty() ? "" : "; ") + c;
  pc.action = checked->applied.to_json();
  pc.command = std::move(*cmd);  // apply() hands this to the core, which checks it again
  return pc;
}

Result<json::Value> SafetyActuation::apply(const PreparedCommand& pc) {
  const std::string& action = pc.action_name;
  if (!pc.command) {
    RobotState st = core_.robot_state();
    if (action == "chat") {
      SafetyStatus s = core_.status();
      ChatContext ctx;
      ctx.estop_active = s.estop_active;
      ctx.estop_reason = s.estop_reason;
      ctx.safe_stop_active = s.safe_stop_active;
      ctx.safe_stop_reason = s.safe_stop_reason;
      ctx.robot_name = robot_name_;
      return json::Value(json::Object{{"reply", chat(pc.question, st, ctx)}});
    }
    return json::Value(st.to_json());
  }
  DispatchOptions opts;
  opts.deadline_mono_ms = pc.deadline_mono_ms;
  opts.session_id = pc.session_id;
  opts.stream_epoch = pc.stream_epoch;
  auto out = core_.dispatch(*pc.command, opts);
  if (!out.ok()) return out.error();
  return json::Value(out->to_json());
}

void SafetyActuation::arm_deadman(const std::string& session_id, int64_t timeout_ms) {
  core_.arm_deadman(session_id, timeout_ms);
  core_.set_deadman_holds_control(session_id, true);
}

void SafetyActuation::feed_deadman(const std::string& session_id) {
  (void)core_.feed_deadman(session_id);
}

void SafetyActuation::disarm_deadman(const std::string& session_id) {
  core_.set_deadman_holds_control(session_id, false);
  core_.disarm_deadman(session_id);
}

Status SafetyActuation::rearm(const std::string& session_id) { return core_.rearm(session_id); }

json::Value SafetyActuation::status() const { return json::Value(core_.status().to_json()); }

json::Value SafetyActuation::telemetry() const {
  return json::Value(core_.robot_state().to_json());
}

}  // namespace rcan::node
