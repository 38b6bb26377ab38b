// The blocks of `.rcan.yaml`, one file each: every function returns the top-level rows of its
// file (table.h). blocks/document.cpp puts them in the order build() walks them.
#pragma once

#include "config/table.h"

namespace rcan::config::internal {

Table<NodeConfig> identity_blocks();  // rcan_version, ruri, rrn, registry, robot, metadata,
                                      // capabilities, rcan_protocol
Table<NodeConfig> server_blocks();    // node, server, grpc, udp
Table<NodeConfig> security_blocks();  // security
Table<NodeConfig> rbac_blocks();      // rbac, guest_limits
Table<NodeConfig> agent_blocks();     // agent, brain
Table<NodeConfig> safety_blocks();    // safety, watchdog, hardware_safety
Table<NodeConfig> driver_blocks();    // driver
Table<NodeConfig> control_blocks();   // offline, control, qos
Table<NodeConfig> fleet_blocks();     // mqtt, fleet, swarm
Table<NodeConfig> profile_blocks();   // the kept profile and OpenCastor blocks

}  // namespace rcan::config::internal
