// The pipeline's own stages (pipeline.h), one factory each, listed in the order the node runs
// them. The fleet stage (node/fleet/fleet.h) and the §16 stages (node/ai/gate_stages.h) come
// from above; node/api/stage_order.cpp assembles the whole list.
#pragma once

#include <memory>
#include <string>

#include "node/pipeline/pipeline.h"

namespace rcan::node {

// message_stages.cpp
std::unique_ptr<Stage> make_shape_stage(NodeServices& services);   // the JSON is a message
std::unique_ptr<Stage> make_token_stage(NodeServices& services);   // a token is present
std::unique_ptr<Stage> make_decode_stage(NodeServices& services);  // decoded; SAFETY recognised
// auth_stages.cpp
std::unique_ptr<Stage> make_auth_stage(NodeServices& services);  // token, signature, §8.5
// Age, ttl and the principal's used ids, remembering nothing (replay.h: peek).
std::unique_ptr<Stage> make_freshness_stage(NodeServices& services);
// authorize_stage.cpp
std::unique_ptr<Stage> make_authorize_stage(NodeServices& services);  // scope, role, session
// guest_limits.cpp (guest_limits.h): seed §6.3
// guard_stages.cpp
std::unique_ptr<Stage> make_rate_limit_stage(NodeServices& services);
// auth_stages.cpp: the message_id remembered in its principal's replay memory (replay.h: check).
std::unique_ptr<Stage> make_replay_stage(NodeServices& services);
// guard_stages.cpp
std::unique_ptr<Stage> make_safety_state_stage(NodeServices& services);  // ESTOP, audit outage
std::unique_ptr<Stage> make_injection_stage(NodeServices& services);
// dispatch_stage.cpp
std::unique_ptr<Stage> make_dispatch_stage(NodeServices& services);  // audit, then act

// The SAFETY event a message asks for, if any: a SAFETY message's safety_event / action /
// cmd, or a COMMAND whose action is a stop word. An ESTOP request is honoured in any form.
SafetyAction safety_action_of(const Message& m);
// "ESTOP", "STOP", "RESUME" or "NONE".
const char* safety_action_name(SafetyAction a);
// The received JSON object: the body, which the decode stage moves into the decoded message's
// wire object (read there from then on), and an AI escalation puts back when it replaces the
// message; null when it is not an object.
const json::Object* wire_of(const Context& ctx);
// The bearer token of a context: the transport's, else the message's auth_token.
std::string_view token_of(const Context& ctx);

}  // namespace rcan::node
