// The driver the configuration names (driver.type): the simulator, a ROS 2 robot over DDS, or a
// driver process.
#pragma once

#include <memory>

#include "config/config.h"
#include "node/safety/driver.h"
#include "node/safety/sim_robot.h"
#include "rcan/result.h"

namespace rcan::rcand {

// A started driver, ready for the SafetyCore. `sim` configures the simulator.
Result<std::unique_ptr<node::Driver>> make_driver(const config::NodeConfig& cfg,
                                                  const node::SimRobotConfig& sim);

}  // namespace rcan::rcand
