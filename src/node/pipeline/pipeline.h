// The one dispatch pipeline. Every route and transport turns its input into an Ingress and
// calls Pipeline::submit(); nothing else authorises, audits or dispatches.
//
// A pipeline is an ordered list of Stages (in the spirit of Envoy's filters). Each stage
// receives the Context and returns:
//   kContinue — pass it to the next stage;
//   kAnswered — the stage refused (`return refuse(...)`) or answered the message itself;
//   kParked   — the stage took ownership and will finish the context later (audit
//               durability, a HiTL decision); it must eventually call ctx.finish().
// Whatever happens, the context is finished exactly once and writes exactly one audit record
// (refusals: the record is written by refuse(); acceptances: by the dispatch stage).
//
// The stages themselves are in stages.h (and, for fleets and §16, in node/fleet and node/ai);
// the node's order is node/api/stage_order.cpp (docs/NODE.md).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "node/admission/authenticator.h"
#include "node/vocabulary/audit_record.h"
#include "rcan/actions.h"
#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/roles.h"

namespace rcan {
class Histogram;
}

namespace rcan::node {

class NodeServices;
class Pipeline;

// What a transport hands to the pipeline.
struct Ingress {
  json::Value body;       // parsed JSON (the transport parsed it with its limits)
  std::string bearer;     // token from the Authorization header or the stream's CONNECT
  std::string transport;  // "http", "ws"
  std::string route;      // e.g. "/rcan/v1/command"
  std::string remote;     // peer address, for logs
  std::optional<Principal> preauthenticated;  // a stream authenticated at CONNECT
  std::string fleet_id;         // MQTT: the fleet topic it came in on (empty: not a fleet topic)
  std::string fleet_mode;       // MQTT: "broadcast", "individual" or "estop" (docs/FLEET.md)
  bool standing_estop = false;  // MQTT: the retained fleet ESTOP, obeyed whatever its age
  int mqtt_qos = -1;            // MQTT: the QoS the broker delivered it at (-1: not MQTT)
  // A shared channel (MQTT): the token must be bound to a key (cnf) and the message signed by
  // it, or a reader of the channel could send messages of their own with a copied token.
  bool require_bound_key = false;
  // A stream (WebSocket, gRPC): the ESTOP epoch it is armed at, set at CONNECT. A motion command
  // on it without a control session is refused (rearm_required) once an ESTOP has latched since,
  // until one carries "rearm": true (docs/NODE.md, "Re-arm after ESTOP"). Null: HTTP, MQTT.
  std::shared_ptr<std::atomic<uint64_t>> armed_epoch;
  int64_t received_mono_us = 0;  // steady clock at arrival (transport read done); 0: at submit
  // The transport's thread serves this one connection and may block for the disk: an ESTOP's
  // latch file is then written on it, and the record of a stop (which has already happened)
  // committed on it, when nothing else is writing them (audit::Commit::kHereIfIdle,
  // SafetyCore::persist_here_if_idle), and the answer goes out from it.
  bool may_commit_audit = false;
};

// What the pipeline answers.
struct Outcome {
  int status = 200;
  json::Value body;
  std::vector<std::pair<std::string, std::string>> headers;
  bool authenticated = false;  // the message's token verified (the auth stage passed)
};

enum class SafetyAction { kNone, kEstop, kStop, kResume };

struct Context {
  Ingress in;
  std::optional<Message> msg;
  Principal principal;
  SignatureCheck sig;
  SenderIdentity sender;
  SafetyAction safety = SafetyAction::kNone;
  // The COMMAND's action from the action table (rcan/actions.h), set by the authorize stage:
  // every later stage, the audit record and the driver use its canonical name.
  const ActionSpec* action = nullptr;
  std::optional<Capability> capability;
  std::string event = "COMMAND";  // audit event for acceptance
  json::Object audit_detail;
  std::string session_id;      // control session the command runs under
  bool fleet_command = false;  // arrived as FLEET_COMMAND (decoded as a COMMAND)
  bool invoke = false;         // arrived as INVOKE (decoded as a COMMAND naming a skill)
  std::string skill_field = "payload.skill";  // where an INVOKE named its skill
  // The replay stage remembered the message's id: when a §16 escalation runs the layer's
  // command (the same message_id) through the stages again, it is not a replay.
  bool replay_remembered = false;
  bool authenticated = false;  // the auth stage verified the token (Outcome::authenticated)
  // §16 (src/node/ai/gate_stages.cpp): written into the acceptance record by the dispatch stage.
  bool gate_bypassed = false;        // a confidence gate missed with on_fail allow
  bool hitl_timeout_bypass = false;  // a HiTL gate timed out with on_timeout allow
  std::string watermark_token;       // §16.6 token of an AI-produced command
  Pipeline* pipeline = nullptr;      // set by submit(), for stages that park and resume
  int64_t started_mono_us = 0;
  std::function<void(Outcome)> done;

  // Finishes with `out` (once; later calls are ignored).
  void finish(Outcome out);
  bool finished() const { return finished_; }

 private:
  bool finished_ = false;
};

class Stage {
 public:
  enum class Result { kContinue, kAnswered, kParked };
  virtual ~Stage() = default;
  virtual const char* name() const = 0;
  virtual Result run(const std::shared_ptr<Context>& ctx) = 0;
};

class Pipeline {
 public:
  Pipeline(NodeServices& services, std::vector<std::unique_ptr<Stage>> stages);
  // Runs the stages; `done` is called exactly once, possibly on another thread.
  void submit(Ingress in, std::function<void(Outcome)> done);

  // Runs the stages from the one named `stage` (inclusive) on a context that a stage parked
  // (a §16 gate resuming after escalation or a HiTL decision). An unknown name finishes the
  // context with an internal error.
  void run_from(const std::shared_ptr<Context>& ctx, std::string_view stage);

 private:
  NodeServices& svc_;
  void run(const std::shared_ptr<Context>& ctx, size_t first);
  std::vector<std::unique_ptr<Stage>> stages_;
  std::vector<Histogram*> stage_timers_;  // one per stage (metrics lookups off the hot path)
  Histogram* parse_timer_ = nullptr;
  Histogram* total_timer_ = nullptr;
};

// Refuses a context: answers the error body with its HTTP status and writes the audit
// record (event, outcome "blocked"/"error"). The one way a stage refuses:
//   if (!ok) return refuse(svc_, ctx, Error(ErrorCode::kRateLimited, "…"), "RATE_LIMITED");
// Returns Stage::Result::kAnswered.
Stage::Result refuse(NodeServices& svc, const std::shared_ptr<Context>& ctx, const Error& err,
                     const std::string& audit_event = {});

// An audit record of `event` about the context's message: its id, the principal (when
// authenticated) and the §8.5 sender identity. The caller adds the rest and writes it.
AuditRecord message_record(NodeServices& svc, const Context& ctx, const std::string& event,
                           const std::string& outcome);

}  // namespace rcan::node
