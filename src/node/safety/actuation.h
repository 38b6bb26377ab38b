// Actuation — what the pipeline needs from the safety core, as a narrow interface so the
// pipeline can be tested against a fake and the safety core can change underneath.
// The real implementation (actuation.cpp) translates a COMMAND's action into an actuator
// command and hands it to the SafetyCore, which alone talks to the driver.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "node/safety/driver.h"
#include "rcan/actions.h"
#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/result.h"
#include "rcan/roles.h"

namespace rcan::node {

struct PreparedCommand {
  std::string action_name;  // the COMMAND's canonical action (rcan/actions.h)
  std::optional<ActuatorCommand>
      command;           // as checked by prepare(); none for an informational action
  std::string question;  // chat/ask: the text asked
  json::Value action;    // what will be applied (after clamping), for the audit record
  bool clamped = false;
  std::string clamp_note;        // which limit clamped it
  int64_t deadline_mono_ms = 0;  // 0 = none
  std::string session_id;
  std::optional<uint64_t> stream_epoch;  // see prepare()
};

// How estop() says whether the latch survives a restart (see Actuation::estop).
using EstopLatchFn = std::function<void(bool durable, const std::string& error)>;

class Actuation {
 public:
  virtual ~Actuation() = default;
  virtual bool estop_active() const = 0;
  // How many times ESTOP has latched (SafetyCore::estop_epoch): a channel armed at an older
  // epoch needs a fresh operator action before it moves the robot again.
  virtual uint64_t estop_epoch() const = 0;
  // Latches ESTOP and stops the actuators now. Returns the microseconds from the call to
  // the driver's stop. Then `on_latch` is called exactly once, without blocking anyone (on
  // another thread, or before estop() returns): durable, once the latch is in its state file;
  // or not, with why — the write failed or did not finish in time (the latch holds in memory
  // and the write is retried), or there is no state file.
  // `by` is the role of the principal who asked: only that role or OWNER may clear it.
  // `persist_here`: the calling thread serves one channel and may block for the disk; the
  // latch file is then written on it when no other write is under way (then `on_latch` is
  // called on it, before estop() returns), else on the safety core's own thread.
  virtual double estop(const std::string& source, const std::string& reason, Role by,
                       EstopLatchFn on_latch, bool persist_here) = 0;
  // Clears a latched ESTOP. Errors: INSUFFICIENT_PRIVILEGES below LEASEE, or below the role
  // that latched it (OWNER clears any).
  virtual Status resume(Role role, const std::string& source) = 0;
  // Stops motion without latching (STOP safety event).
  virtual void stop(const std::string& source) = 0;
  // Validates a COMMAND of action `spec` (looked up by the authorize stage) against the state
  // and the local limits, clamping where the policy says so. Errors: COMMAND_REJECTED
  // (estop_active, limit_exceeded, unsupported_action), SCHEMA_VALIDATION_FAILED (parameters).
  // `stream_epoch`: for a command from a stream without a control session, the ESTOP epoch
  // the stream is armed at (Ingress::armed_epoch); the core refuses it (rearm_required) once an
  // ESTOP has latched since, here and again in apply().
  virtual Result<PreparedCommand> prepare(const Message& msg, const ActionSpec& spec,
                                          int64_t deadline_mono_ms, const std::string& session_id,
                                          std::optional<uint64_t> stream_epoch) = 0;
  // Applies a prepared command. Errors: COMMAND_REJECTED estop_active when an ESTOP came in
  // between prepare() and apply(); MESSAGE_STALE past its deadline.
  virtual Result<json::Value> apply(const PreparedCommand& cmd) = 0;
  // Deadman bookkeeping for control sessions.
  virtual void arm_deadman(const std::string& session_id, int64_t timeout_ms) = 0;
  virtual void feed_deadman(const std::string& session_id) = 0;
  virtual void disarm_deadman(const std::string& session_id) = 0;
  // Re-arms a control session after an ESTOP (docs/NODE.md, "Re-arm after ESTOP"): until then
  // its motion commands are refused (COMMAND_REJECTED / rearm_required). Errors: NOT_FOUND.
  virtual Status rearm(const std::string& session_id) = 0;
  // Snapshots for status and telemetry.
  virtual json::Value status() const = 0;
  virtual json::Value telemetry() const = 0;
};

}  // namespace rcan::node
