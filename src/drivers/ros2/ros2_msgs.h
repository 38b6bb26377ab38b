// The ROS 2 message types as C structs, generated at build time by Cyclone DDS's idlc from
// idl/*.idl (ROS 2's own field layout and the dds_ module nesting, so the DDS type names are
// ROS 2's: geometry_msgs::msg::dds_::Twist_ and so on).
#pragma once

#include <dds/dds.h>

#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "sensor_msgs.h"
#include "std_msgs.h"
#include "trajectory_msgs.h"
