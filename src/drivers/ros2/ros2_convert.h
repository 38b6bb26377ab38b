// Conversions between ROS 2 messages and the driver's view of the robot (no DDS entities, so
// that tests and the fuzz target can call them on any sample). Received samples are
// untrusted: a reading with a non-finite or degenerate value is refused, never applied.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/ros2/ros2_msgs.h"
#include "node/safety/driver.h"
#include "rcan/result.h"

namespace rcan::drivers::ros2 {

// The DDS topic of a ROS 2 topic: "rt" + its fully qualified name. `topic` is relative to
// `ns` unless it starts with '/'. "cmd_vel" in "" → "rt/cmd_vel"; in "/robot1" or "robot1"
// → "rt/robot1/cmd_vel"; "/cmd_vel" in "/robot1" → "rt/cmd_vel". An error for a name ROS 2
// would refuse (empty tokens, characters other than letters, digits and '_').
Result<std::string> dds_topic_name(std::string_view ns, std::string_view topic);

// Yaw (rotation about z, in (-pi, pi]) of a quaternion of any non-zero length.
double yaw_of(double x, double y, double z, double w);

// The base's pose and body velocities from an odometry sample; nullopt when a value is not
// finite or the orientation quaternion is (nearly) zero.
struct OdomReading {
  double x = 0, y = 0, theta = 0;
  double linear_mps = 0, angular_radps = 0;
};
std::optional<OdomReading> read_odometry(const nav_msgs_msg_dds__Odometry_& m);

// Joint positions from a JointState sample into `joints`: by name when `names` (the arm's
// configured joint names, slot order) is not empty — joints the sample does not name keep
// their value; positionally (the first kArmJoints entries) otherwise. A non-finite position
// is skipped; arrays of different lengths are read up to the shorter one. Returns how many
// slots were updated.
int read_joint_state(const sensor_msgs_msg_dds__JointState_& m,
                     const std::vector<std::string>& names, node::JointArray& joints);

// A Twist holding the given body velocities (x forward, z yaw); every other field 0.
geometry_msgs_msg_dds__Twist_ make_twist(double linear_mps, double angular_radps);

}  // namespace rcan::drivers::ros2
