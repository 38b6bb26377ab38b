// The guest-limits stage (seed §6.3, PROFILE.md §5; docs/SESSIONS.md): for GUEST principals,
// after authorisation. A guest's first accepted request opens a guest session that lasts
// `session_duration`; at most `concurrent_sessions` guests have one at a time; chat is held to
// `chat_rate`, status and queries to `query_rate`; what a message asks for is named as a
// guest capability (status_read, chat_text, basic_info, control, camera_access,
// location_history) and must be allowed and not blocked. SAFETY stops are never limited.
#pragma once

#include <memory>
#include <string>

#include "node/pipeline/pipeline.h"

namespace rcan::node {

std::unique_ptr<Stage> make_guest_limit_stage(NodeServices& services);
// The guest capability a message asks for: status_read for STATUS and HEARTBEAT, else the
// guest class of its action in the action table (rcan/actions.h), control without one.
std::string guest_capability(const Message& m, const ActionSpec* action);

}  // namespace rcan::node
