// ros2_sim_base — the node's simulated robot (SimRobot) as a ROS 2 robot on DDS, for watching
// the whole chain without hardware: rcand (driver.type: ros2) → rt/cmd_vel → this program →
// rt/odom and rt/joint_states → rcand's status and telemetry.
//
//   ros2_sim_base [--domain N] [--namespace NS] [--rate HZ] [--cmd-timeout-ms MS]
//                 [--arm-topic T] [--joints j1,j2,...]
//
// It behaves like a ROS 2 base: it subscribes to cmd_vel (geometry_msgs/msg/Twist, reliable)
// and drives at the last Twist until cmd-timeout-ms (default 500) passes without a new one;
// it publishes nav_msgs/msg/Odometry on odom and sensor_msgs/msg/JointState on joint_states
// at --rate (default 20 Hz). A trajectory_msgs/msg/JointTrajectory on the arm topic (default
// arm_controller/joint_trajectory) moves the arm to its last point; an empty one holds it.
// Joint names default to joint1..joint6. It prints its pose once a second. Cyclone DDS reads
// CYCLONEDDS_URI as usual (docs/DRIVERS.md).
#include <dds/dds.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "drivers/ros2/ros2_convert.h"
#include "drivers/ros2/ros2_msgs.h"
#include "node/safety/sim_robot.h"

namespace {

std::atomic<bool> g_run{true};
void on_signal(int) { g_run = false; }

struct Options {
  uint32_t domain = 0;
  std::string ns;
  int rate_hz = 20;
  int cmd_timeout_ms = 500;
  std::string arm_topic = "arm_controller/joint_trajectory";
  std::vector<std::string> joints{"joint1", "joint2", "joint3", "joint4", "joint5", "joint6"};
};

int usage() {
  std::fprintf(stderr,
               "usage: ros2_sim_base [--domain N] [--namespace NS] [--rate HZ] "
               "[--cmd-timeout-ms MS] [--arm-topic T] [--joints j1,j2,...]\n");
  return 2;
}

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t comma = s.find(',', start);
    out.push_back(s.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

dds_entity_t make(dds_entity_t pp, const dds_topic_descriptor_t* desc, const std::string& name,
                  bool reader) {
  const dds_entity_t t = dds_create_topic(pp, desc, name.c_str(), nullptr, nullptr);
  if (t < 0) return t;
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 10);
  const dds_entity_t e =
      reader ? dds_create_reader(pp, t, q, nullptr) : dds_create_writer(pp, t, q, nullptr);
  dds_delete_qos(q);
  return e;
}

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace rcan;
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return usage();
    const std::string v = argv[++i];
    if (a == "--domain") {
      o.domain = static_cast<uint32_t>(std::atoi(v.c_str()));
    } else if (a == "--namespace") {
      o.ns = v;
    } else if (a == "--rate") {
      o.rate_hz = std::max(1, std::atoi(v.c_str()));
    } else if (a == "--cmd-timeout-ms") {
      o.cmd_timeout_ms = std::max(1, std::atoi(v.c_str()));
    } else if (a == "--arm-topic") {
      o.arm_topic = v;
    } else if (a == "--joints") {
      o.joints = split(v);
    } else {
      return usage();
    }
  }
  if (o.domain > 232 || o.joints.size() > static_cast<size_t>(node::kArmJoints)) return usage();
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  auto name = [&](const char* topic) {
    auto n = drivers::ros2::dds_topic_name(o.ns, topic);
    if (!n.ok()) {
      std::fprintf(stderr, "ros2_sim_base: %s\n", n.error().message.c_str());
      std::exit(2);
    }
    return *n;
  };
  const dds_entity_t pp = dds_create_participant(o.domain, nullptr, nullptr);
  if (pp < 0) {
    std::fprintf(stderr, "ros2_sim_base: cannot join DDS domain %u: %s\n", o.domain,
                 dds_strretcode(pp));
    return 1;
  }
  const dds_entity_t cmd = make(pp, &geometry_msgs_msg_dds__Twist__desc, name("cmd_vel"), true);
  const dds_entity_t arm =
      make(pp, &trajectory_msgs_msg_dds__JointTrajectory__desc, name(o.arm_topic.c_str()), true);
  const dds_entity_t odom = make(pp, &nav_msgs_msg_dds__Odometry__desc, name("odom"), false);
  const dds_entity_t js =
      make(pp, &sensor_msgs_msg_dds__JointState__desc, name("joint_states"), false);
  if (cmd < 0 || arm < 0 || odom < 0 || js < 0) {
    std::fprintf(stderr, "ros2_sim_base: cannot create the DDS topics\n");
    dds_delete(pp);
    return 1;
  }
  std::printf("ros2_sim_base: domain %u, %s in, %s and %s out\n", o.domain, name("cmd_vel").c_str(),
              name("odom").c_str(), name("joint_states").c_str());
  std::fflush(stdout);

  node::SimRobot robot;
  std::vector<char*> joint_ptrs;
  for (auto& j : o.joints) joint_ptrs.push_back(j.data());
  const int64_t pub_every_ms = 1000 / o.rate_hz;
  int64_t last = now_ms(), next_pub = last, next_print = last + 1000;
  while (g_run) {
    // Commands: the latest Twist drives for cmd-timeout-ms (renewed by every new one).
    void* buf[8];
    dds_sample_info_t si[8];
    for (auto& b : buf) b = nullptr;
    dds_return_t n = dds_take(cmd, buf, si, 8, 8);
    for (dds_return_t i = 0; i < n; ++i) {
      if (!si[i].valid_data) continue;
      const auto* t = static_cast<const geometry_msgs_msg_dds__Twist_*>(buf[i]);
      (void)robot.apply(
          node::ActuatorCommand::make_drive(t->linear.x, t->angular.z, o.cmd_timeout_ms));
    }
    if (n > 0) dds_return_loan(cmd, buf, n);
    for (auto& b : buf) b = nullptr;
    n = dds_take(arm, buf, si, 8, 8);
    for (dds_return_t i = 0; i < n; ++i) {
      if (!si[i].valid_data) continue;
      const auto* m = static_cast<const trajectory_msgs_msg_dds__JointTrajectory_*>(buf[i]);
      node::JointArray target = robot.state().joints_rad;  // empty trajectory: hold here
      if (m->points._length > 0) {
        const auto& p = m->points._buffer[m->points._length - 1];
        for (uint32_t k = 0; k < m->joint_names._length && k < p.positions._length; ++k)
          for (size_t s = 0; s < o.joints.size(); ++s)
            if (o.joints[s] == m->joint_names._buffer[k]) target[s] = p.positions._buffer[k];
      }
      (void)robot.apply(node::ActuatorCommand::make_arm(target));
    }
    if (n > 0) dds_return_loan(arm, buf, n);

    const int64_t now = now_ms();
    robot.step(now - last);
    last = now;
    const node::RobotState s = robot.state();
    if (now >= next_pub) {
      next_pub += pub_every_ms;
      if (next_pub < now) next_pub = now + pub_every_ms;
      nav_msgs_msg_dds__Odometry_ od{};
      od.header.stamp.sec = static_cast<int32_t>(s.t_ms / 1000);
      od.header.stamp.nanosec = static_cast<uint32_t>((s.t_ms % 1000) * 1'000'000);
      od.header.frame_id = const_cast<char*>("odom");
      od.child_frame_id = const_cast<char*>("base_link");
      od.pose.pose.position.x = s.x;
      od.pose.pose.position.y = s.y;
      od.pose.pose.orientation.z = std::sin(s.theta / 2);
      od.pose.pose.orientation.w = std::cos(s.theta / 2);
      od.twist.twist.linear.x = s.linear_mps;
      od.twist.twist.angular.z = s.angular_radps;
      dds_write(odom, &od);
      std::vector<double> pos(s.joints_rad.begin(), s.joints_rad.begin() + o.joints.size());
      sensor_msgs_msg_dds__JointState_ j{};
      j.header = od.header;
      j.header.frame_id = const_cast<char*>("");
      j.name._maximum = j.name._length = static_cast<uint32_t>(joint_ptrs.size());
      j.name._buffer = joint_ptrs.data();
      j.position._maximum = j.position._length = static_cast<uint32_t>(pos.size());
      j.position._buffer = pos.data();
      dds_write(js, &j);
    }
    if (now >= next_print) {
      next_print += 1000;
      std::printf("pose x=%.3f y=%.3f theta=%.3f v=%.2f w=%.2f\n", s.x, s.y, s.theta, s.linear_mps,
                  s.angular_radps);
      std::fflush(stdout);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  dds_delete(pp);
  return 0;
}
