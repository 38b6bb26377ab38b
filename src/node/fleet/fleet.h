// Fleet mode on the robot (seed §2.3, §5.1; docs/FLEET.md): the robot's membership and the
// pipeline stage that checks every message that came through a fleet topic or as a
// FLEET_COMMAND.
//
// The fleet stage runs after authentication and before authorisation. For a fleet message it
// requires: this robot is in a fleet; the topic's and the payload's fleet_id are that fleet;
// the token is a fleet JWT (a `fleet` claim, which the JWT verifier has already checked lists
// this robot); the fleet allows the command form (broadcast / individual / choreographed).
// ESTOP and STOP are exempt from all but authentication (PROFILE.md §3): any authenticated
// principal may stop a robot, through any topic. One bound: a fleet ESTOP (on the fleet's
// topics) that the fleet has resumed since — a captured one put back on the estop topic — is
// refused as a replay, and a retained one must be newer than the last fleet RESUME applied
// (estop_ledger.h).
//
// Fleet command vs individual command (seed §5.3 "fleet owner decides the policy"): the
// policy itself belongs to the control-session rules; FleetMembership::conflict is the hook they
// install. It sees every fleet message after the checks above and may refuse it.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "config/fleet_config.h"
#include "node/pipeline/pipeline.h"
#include "rcan/result.h"

namespace rcan::node {

class NodeServices;

struct FleetMembership {
  config::FleetConfig config;
  // Optional: the fleet-vs-individual conflict policy. Returns an error to refuse.
  std::function<std::optional<Error>(const Context& ctx, NodeServices& svc)> conflict;
};

// The stage (node/api/stage_order.cpp runs it after authentication and the freshness look).
std::unique_ptr<Stage> make_fleet_stage(NodeServices& services);

// True when a context arrived through a fleet topic or as a FLEET_COMMAND.
bool fleet_origin(const Context& ctx);

}  // namespace rcan::node
