// A ROS 2 robot as the tests see it: a DDS participant (Cyclone DDS) on the ROS 2 topic and
// type names — rt/<ns>/cmd_vel of geometry_msgs::msg::dds_::Twist_ in, rt/<ns>/odom and
// rt/<ns>/joint_states out. The Twists it receives are decoded from their CDR bytes by the
// code below (not by the driver's generated code), so a layout the driver got wrong shows.
// Header-only; programs that include it link rcan_ros2 (the generated types and Cyclone).
#pragma once

#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "drivers/ros2/ros2_msgs.h"

namespace rcan::test {

// A Cyclone configuration that keeps every DDS packet on the loopback interface: no
// multicast, discovery by unicast to 127.0.0.1. For CYCLONEDDS_URI (which takes XML inline).
inline std::string loopback_dds_config() {
  return "<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface name=\"lo\"/>"
         "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
         "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30"
         "</MaxAutoParticipantIndex><Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>"
         "</Domain></CycloneDDS>";
}

// Sets CYCLONEDDS_URI for this process (before its first participant) and returns the
// environment entry for a child process.
inline std::string use_loopback_dds() {
  const std::string cfg = loopback_dds_config();
  ::setenv("CYCLONEDDS_URI", cfg.c_str(), 1);
  return "CYCLONEDDS_URI=" + cfg;
}

// A domain id of its own per test process (1-230), so that tests running in parallel do not
// see each other's traffic.
inline uint32_t random_domain_id() {
  const uint64_t t =
      static_cast<uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
  return 1 + static_cast<uint32_t>((t ^ (static_cast<uint64_t>(::getpid()) * 2654435761u)) % 230);
}

inline int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// ---- CDR, by hand (XCDR1, as ROS 2 writes it) ------------------------------------------------
// A serialized sample is a 4-byte encapsulation header (00 01 = CDR little-endian, 00 00
// options) and the body, where every primitive sits at a multiple of its size counted from
// the body's start; a string is a uint32 length (with the NUL) and the bytes with the NUL; a
// sequence is a uint32 count and the elements.

struct CdrWriter {
  std::vector<uint8_t> b{0x00, 0x01, 0x00, 0x00};
  void align(size_t n) {
    while ((b.size() - 4) % n) b.push_back(0);
  }
  template <typename T>
  void put(T v) {
    align(sizeof(T));
    uint8_t raw[sizeof(T)];
    std::memcpy(raw, &v, sizeof(T));
    b.insert(b.end(), raw, raw + sizeof(T));
  }
  void str(const std::string& s) {
    put<uint32_t>(static_cast<uint32_t>(s.size() + 1));
    b.insert(b.end(), s.begin(), s.end());
    b.push_back(0);
  }
};

struct CdrReader {
  const uint8_t* p;
  size_t n;
  size_t off = 4;
  bool ok = true;
  template <typename T>
  T get() {
    while ((off - 4) % sizeof(T)) ++off;
    T v{};
    if (off + sizeof(T) > n) {
      ok = false;
      return v;
    }
    std::memcpy(&v, p + off, sizeof(T));
    off += sizeof(T);
    return v;
  }
};

struct WireTwist {
  double lx = 0, ly = 0, lz = 0, ax = 0, ay = 0, az = 0;
  int64_t t_ns = 0;  // steady clock, when this process got it
  bool zero() const { return lx == 0 && ly == 0 && lz == 0 && ax == 0 && ay == 0 && az == 0; }
};

// geometry_msgs/msg/Twist: linear {x,y,z}, angular {x,y,z}, six float64 — 52 bytes in all.
inline std::optional<WireTwist> decode_twist(const uint8_t* p, size_t n) {
  if (n != 4 + 6 * 8 || p[0] != 0x00 || p[1] != 0x01) return std::nullopt;
  CdrReader r{p, n};
  WireTwist t;
  t.lx = r.get<double>();
  t.ly = r.get<double>();
  t.lz = r.get<double>();
  t.ax = r.get<double>();
  t.ay = r.get<double>();
  t.az = r.get<double>();
  if (!r.ok) return std::nullopt;
  return t;
}

// nav_msgs/msg/Odometry written out field by field.
inline std::vector<uint8_t> encode_odometry(int32_t sec, uint32_t nsec, const std::string& frame,
                                            const std::string& child, double x, double y, double qz,
                                            double qw, double v, double w) {
  CdrWriter c;
  c.put<int32_t>(sec);
  c.put<uint32_t>(nsec);
  c.str(frame);
  c.str(child);
  for (double d : {x, y, 0.0, 0.0, 0.0, qz, qw}) c.put<double>(d);  // pose.pose
  for (int i = 0; i < 36; ++i) c.put<double>(0.0);                  // pose.covariance
  for (double d : {v, 0.0, 0.0, 0.0, 0.0, w}) c.put<double>(d);     // twist.twist
  for (int i = 0; i < 36; ++i) c.put<double>(0.0);                  // twist.covariance
  return c.b;
}

// The serialized bytes of a DDS sample as Cyclone put them on the wire (dds_takecdr).
inline std::vector<uint8_t> serdata_bytes(struct ddsi_serdata* d) {
  std::vector<uint8_t> out(ddsi_serdata_size(d));
  ddsi_serdata_to_ser(d, 0, out.size(), out.data());
  return out;
}

// ---- the peer --------------------------------------------------------------------------------

class Ros2Peer {
 public:
  // ns: the ROS namespace ("" or "/robot1").
  explicit Ros2Peer(uint32_t domain, const std::string& ns = "") {
    const std::string pre =
        "rt" + (ns.empty() || ns == "/" ? std::string() : (ns[0] == '/' ? ns : "/" + ns));
    pp_ = dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr);
    if (pp_ < 0) return;
    // cmd_vel as a ROS 2 base subscribes: reliable, keep-last 10.
    dds_qos_t* rq = dds_create_qos();
    dds_qset_reliability(rq, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(rq, DDS_HISTORY_KEEP_LAST, 10);
    const dds_entity_t tw = dds_create_topic(pp_, &geometry_msgs_msg_dds__Twist__desc,
                                             (pre + "/cmd_vel").c_str(), nullptr, nullptr);
    dds_listener_t* l = dds_create_listener(this);
    dds_lset_data_available(l, &Ros2Peer::on_twist);
    twist_reader_ = dds_create_reader(pp_, tw, rq, l);
    dds_delete_listener(l);
    const dds_entity_t tj =
        dds_create_topic(pp_, &trajectory_msgs_msg_dds__JointTrajectory__desc,
                         (pre + "/arm_controller/joint_trajectory").c_str(), nullptr, nullptr);
    traj_reader_ = dds_create_reader(pp_, tj, rq, nullptr);
    dds_delete_qos(rq);
    // odom and joint_states as a typical driver publishes them: reliable, keep-last 10.
    dds_qos_t* wq = dds_create_qos();
    dds_qset_reliability(wq, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(wq, DDS_HISTORY_KEEP_LAST, 10);
    const dds_entity_t to = dds_create_topic(pp_, &nav_msgs_msg_dds__Odometry__desc,
                                             (pre + "/odom").c_str(), nullptr, nullptr);
    odom_writer_ = dds_create_writer(pp_, to, wq, nullptr);
    const dds_entity_t tjs = dds_create_topic(pp_, &sensor_msgs_msg_dds__JointState__desc,
                                              (pre + "/joint_states").c_str(), nullptr, nullptr);
    joint_writer_ = dds_create_writer(pp_, tjs, wq, nullptr);
    dds_delete_qos(wq);
  }
  ~Ros2Peer() {
    if (pp_ > 0) dds_delete(pp_);
  }
  Ros2Peer(const Ros2Peer&) = delete;
  Ros2Peer& operator=(const Ros2Peer&) = delete;

  bool ok() const { return pp_ > 0 && twist_reader_ > 0 && odom_writer_ > 0; }

  // Waits until the driver's cmd_vel writer and odom reader are matched with ours.
  bool wait_matched(int timeout_ms) {
    const int64_t end = steady_ns() + int64_t{timeout_ms} * 1'000'000;
    while (steady_ns() < end) {
      dds_subscription_matched_status_t s{};
      dds_publication_matched_status_t p{};
      dds_get_subscription_matched_status(twist_reader_, &s);
      dds_get_publication_matched_status(odom_writer_, &p);
      if (s.current_count > 0 && p.current_count > 0) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }

  void publish_odom(double x, double y, double theta, double v, double w) {
    nav_msgs_msg_dds__Odometry_ m{};
    m.header.frame_id = const_cast<char*>("odom");
    m.child_frame_id = const_cast<char*>("base_link");
    m.pose.pose.position.x = x;
    m.pose.pose.position.y = y;
    m.pose.pose.orientation.z = std::sin(theta / 2);
    m.pose.pose.orientation.w = std::cos(theta / 2);
    m.twist.twist.linear.x = v;
    m.twist.twist.angular.z = w;
    dds_write(odom_writer_, &m);
  }
  void publish_odom_raw(const nav_msgs_msg_dds__Odometry_& m) { dds_write(odom_writer_, &m); }

  void publish_joints(const std::vector<std::string>& names, std::vector<double> pos) {
    std::vector<char*> np;
    for (const auto& n : names) np.push_back(const_cast<char*>(n.c_str()));
    sensor_msgs_msg_dds__JointState_ m{};
    m.header.frame_id = const_cast<char*>("");
    m.name._maximum = m.name._length = static_cast<uint32_t>(np.size());
    m.name._buffer = np.data();
    m.position._maximum = m.position._length = static_cast<uint32_t>(pos.size());
    m.position._buffer = pos.data();
    dds_write(joint_writer_, &m);
  }

  std::vector<WireTwist> twists() {
    std::lock_guard<std::mutex> lock(mu_);
    return twists_;
  }
  size_t bad_twists() {
    std::lock_guard<std::mutex> lock(mu_);
    return bad_;
  }
  void clear() {
    std::lock_guard<std::mutex> lock(mu_);
    twists_.clear();
  }
  // Takes what has arrived (waiting up to timeout_ms for something): O(1) under the lock, so
  // that a busy consumer never holds up the listener and its timestamps.
  std::vector<WireTwist> drain(int timeout_ms) {
    std::vector<WireTwist> out;
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [&] { return !twists_.empty(); });
    out.swap(twists_);
    return out;
  }
  // Waits until `pred(twists)` holds; false on timeout.
  template <typename Pred>
  bool wait(Pred pred, int timeout_ms) {
    std::unique_lock<std::mutex> lock(mu_);
    return cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [&] { return pred(twists_); });
  }
  // The next JointTrajectory received (generated types: the arm path's own check).
  std::optional<std::vector<uint8_t>> take_trajectory_bytes(int timeout_ms) {
    const int64_t end = steady_ns() + int64_t{timeout_ms} * 1'000'000;
    while (steady_ns() < end) {
      struct ddsi_serdata* d = nullptr;
      dds_sample_info_t si;
      if (dds_takecdr(traj_reader_, &d, 1, &si, DDS_ANY_STATE) == 1) {
        auto b = serdata_bytes(d);
        ddsi_serdata_unref(d);
        if (si.valid_data) return b;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return std::nullopt;
  }

 private:
  static void on_twist(dds_entity_t rd, void* arg) {
    auto* self = static_cast<Ros2Peer*>(arg);
    struct ddsi_serdata* d[16];
    dds_sample_info_t si[16];
    while (true) {
      const dds_return_t n = dds_takecdr(rd, d, 16, si, DDS_ANY_STATE);
      if (n <= 0) break;
      const int64_t t = steady_ns();
      std::lock_guard<std::mutex> lock(self->mu_);
      for (dds_return_t i = 0; i < n; ++i) {
        if (si[i].valid_data) {
          const auto b = serdata_bytes(d[i]);
          auto tw = decode_twist(b.data(), b.size());
          if (tw) {
            tw->t_ns = t;
            self->twists_.push_back(*tw);
          } else {
            ++self->bad_;
          }
        }
        ddsi_serdata_unref(d[i]);
      }
      self->cv_.notify_all();
    }
  }

  dds_entity_t pp_ = 0, twist_reader_ = 0, traj_reader_ = 0, odom_writer_ = 0, joint_writer_ = 0;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<WireTwist> twists_;
  size_t bad_ = 0;
};

}  // namespace rcan::test
