// libFuzzer: what the ROS 2 driver does with a received sample (src/drivers/ros2). The first
// byte picks the topic (even: nav_msgs/msg/Odometry, odd: sensor_msgs/msg/JointState); the
// rest is the serialized sample as it comes off the wire (4-byte encapsulation header, CDR).
// Cyclone's own receive path runs on it (normalize: validate and byte-swap; then deserialize
// into the generated struct), then the driver's conversion. Any input must be refused or read
// to finite values: a pose, yaw in (-pi, pi], velocities; joint positions only finite.
#include <dds/ddsi/ddsi_cdrstream.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <numbers>
#include <string>
#include <vector>

#include "drivers/ros2/ros2_convert.h"
#include "drivers/ros2/ros2_msgs.h"

namespace {

// Cyclone's receive path for one serialized sample: false when it would drop it.
bool deserialize(const uint8_t* data, size_t size, const dds_topic_descriptor_t& desc,
                 void* sample) {
  if (size < 4 || size > (1u << 20)) return false;
  bool bswap;
  if (data[0] == 0x00 && data[1] == 0x01)
    bswap = false;  // CDR little-endian (this host)
  else if (data[0] == 0x00 && data[1] == 0x00)
    bswap = true;  // CDR big-endian
  else
    return false;  // not plain CDR: the reader refuses it
  std::vector<char> body(data + 4, data + size);
  if (body.empty()) body.push_back(0);
  uint32_t off = 0;
  const uint32_t n = static_cast<uint32_t>(size - 4);
  if (dds_stream_normalize_data(body.data(), &off, n, bswap, 1, desc.m_ops) == nullptr)
    return false;
  dds_istream_t is;
  dds_istream_init(&is, n, body.data(), 1);
  dds_stream_read(&is, static_cast<char*>(sample), desc.m_ops);
  dds_istream_fini(&is);
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const bool odom = (data[0] & 1) == 0;
  ++data;
  --size;
  if (odom) {
    nav_msgs_msg_dds__Odometry_ m{};
    if (!deserialize(data, size, nav_msgs_msg_dds__Odometry__desc, &m)) return 0;
    if (const auto r = rcan::drivers::ros2::read_odometry(m)) {
      const double v[] = {r->x, r->y, r->theta, r->linear_mps, r->angular_radps};
      for (double d : v)
        if (!std::isfinite(d)) std::abort();
      if (r->theta <= -std::numbers::pi || r->theta > std::numbers::pi) std::abort();
    }
    dds_stream_free_sample(&m, nav_msgs_msg_dds__Odometry__desc.m_ops);
  } else {
    sensor_msgs_msg_dds__JointState_ m{};
    if (!deserialize(data, size, sensor_msgs_msg_dds__JointState__desc, &m)) return 0;
    static const std::vector<std::string> kNames{"j1", "j2", "j3", "j4", "j5", "j6"};
    for (const auto* names : {&kNames, static_cast<const std::vector<std::string>*>(nullptr)}) {
      rcan::node::JointArray j{};
      const int n =
          rcan::drivers::ros2::read_joint_state(m, names ? *names : std::vector<std::string>{}, j);
      if (n < 0 || n > static_cast<int>(m.position._length)) std::abort();
      for (double d : j)
        if (!std::isfinite(d)) std::abort();
    }
    dds_stream_free_sample(&m, sensor_msgs_msg_dds__JointState__desc.m_ops);
  }
  return 0;
}
