// SafetyActuation — the Actuation the node runs on: COMMAND → ActuatorCommand → SafetyCore.
#pragma once

#include <string>

#include "node/safety/actuation.h"
#include "node/safety/safety.h"

namespace rcan::node {

// The actuator command a COMMAND of action `spec` asks for (docs/NODE.md §Commands). Errors:
// SCHEMA_VALIDATION_FAILED for bad parameters, COMMAND_REJECTED/unsupported_action for an
// action the simulated robot cannot do (a skill).
Result<ActuatorCommand> translate_command(const ActionSpec& spec, const Message& msg,
                                          const SafetyLimits& limits);

class SafetyActuation final : public Actuation {
 public:
  // `core` must outlive this object.
  SafetyActuation(SafetyCore& core, std::string robot_name);

  bool estop_active() const override;
  uint64_t estop_epoch() const override;
  double estop(const std::string& source, const std::string& reason, Role by, EstopLatchFn on_latch,
               bool persist_here) override;
  Status resume(Role role, const std::string& source) override;
  void stop(const std::string& source) override;
  Result<PreparedCommand> prepare(const Message& msg, const ActionSpec& spec,
                                  int64_t deadline_mono_ms, const std::string& session_id,
                                  std::optional<uint64_t> stream_epoch) override;
  Result<json::Value> apply(const PreparedCommand& cmd) override;
  void arm_deadman(const std::string& session_id, int64_t timeout_ms) override;
  void feed_deadman(const std::string& session_id) override;
  void disarm_deadman(const std::string& session_id) override;
  Status rearm(const std::string& session_id) override;
  json::Value status() const override;
  json::Value telemetry() const override;

 private:
  SafetyCore& core_;
  std::string robot_name_;
};

}  // namespace rcan::node
