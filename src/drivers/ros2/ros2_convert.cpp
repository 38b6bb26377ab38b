#include "drivers/ros2/ros2_convert.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

namespace rcan::drivers::ros2 {
namespace {

// One token of a ROS 2 name: a letter or '_' first, then letters, digits, '_'.
bool token_ok(std::string_view t) {
  if (t.empty()) return false;
  for (size_t i = 0; i < t.size(); ++i) {
    const char c = t[i];
    const bool alpha = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_';
    const bool digit = c >= '0' && c <= '9';
    if (!(alpha || (digit && i > 0))) return false;
  }
  return true;
}

// Appends the '/'-separated tokens of `name` to `out` (each as "/token").
bool append_tokens(std::string_view name, std::string& out) {
  if (!name.empty() && name.front() == '/') name.remove_prefix(1);
  if (name.empty()) return true;
  size_t start = 0;
  while (true) {
    const size_t slash = name.find('/', start);
    const std::string_view tok = name.substr(
        start, slash == std::string_view::npos ? std::string_view::npos : slash - start);
    if (!token_ok(tok)) return false;
    out += '/';
    out += tok;
    if (slash == std::string_view::npos) return true;
    start = slash + 1;
  }
}

}  // namespace

Result<std::string> dds_topic_name(std::string_view ns, std::string_view topic) {
  std::string fq;
  if (topic.empty() || topic == "/")
    return Error(ErrorCode::kSchemaValidationFailed, "empty ROS 2 topic name", "topic");
  if (topic.front() != '/' && !append_tokens(ns, fq))
    return Error(ErrorCode::kSchemaValidationFailed,
                 "not a ROS 2 namespace: \"" + std::string(ns) + "\"", "namespace");
  if (!append_tokens(topic, fq) || fq.empty())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "not a ROS 2 topic name: \"" + std::string(topic) + "\"", "topic");
  return "rt" + fq;
}

double yaw_of(double x, double y, double z, double w) {
  // atan2 of the two terms is independent of the quaternion's length.
  const double siny = 2.0 * (w * z + x * y);
  const double cosy = w * w + x * x - y * y - z * z;
  double a = std::atan2(siny, cosy);
  if (a <= -std::numbers::pi) a = std::numbers::pi;
  return a;
}

std::optional<OdomReading> read_odometry(const nav_msgs_msg_dds__Odometry_& m) {
  const auto& p = m.pose.pose.position;
  const auto& q = m.pose.pose.orientation;
  const auto& v = m.twist.twist.linear;
  const auto& w = m.twist.twist.angular;
  const double vals[] = {p.x, p.y, q.x, q.y, q.z, q.w, v.x, w.z};
  for (double d : vals)
    if (!std::isfinite(d)) return std::nullopt;
  const double n2 = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w;
  if (!std::isfinite(n2) || n2 < 1e-12) return std::nullopt;
  OdomReading r;
  r.x = p.x;
  r.y = p.y;
  r.theta = yaw_of(q.x, q.y, q.z, q.w);
  if (!std::isfinite(r.theta)) return std::nullopt;
  r.linear_mps = v.x;
  r.angular_radps = w.z;
  return r;
}

int read_joint_state(const sensor_msgs_msg_dds__JointState_& m,
                     const std::vector<std::string>& names, node::JointArray& joints) {
  const uint32_t npos = m.position._buffer ? m.position._length : 0;
  int updated = 0;
  if (names.empty()) {
    const uint32_t n = std::min<uint32_t>(npos, node::kArmJoints);
    for (uint32_t i = 0; i < n; ++i) {
      const double v = m.position._buffer[i];
      if (!std::isfinite(v)) continue;
      joints[i] = v;
      ++updated;
    }
    return updated;
  }
  const uint32_t nnames = m.name._buffer ? m.name._length : 0;
  const uint32_t n = std::min(npos, nnames);
  const size_t slots = std::min<size_t>(names.size(), node::kArmJoints);
  for (uint32_t i = 0; i < n; ++i) {
    const char* nm = m.name._buffer[i];
    const double v = m.position._buffer[i];
    if (nm == nullptr || !std::isfinite(v)) continue;
    for (size_t s = 0; s < slots; ++s) {
      if (std::strcmp(names[s].c_str(), nm) == 0) {
        joints[s] = v;
        ++updated;
        break;
      }
    }
  }
  return updated;
}

geometry_msgs_msg_dds__Twist_ make_twist(double linear_mps, double angular_radps) {
  geometry_msgs_msg_dds__Twist_ t{};
  t.linear.x = linear_mps;
  t.angular.z = angular_radps;
  return t;
}

}  // namespace rcan::drivers::ros2
