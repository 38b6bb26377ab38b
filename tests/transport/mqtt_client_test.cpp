// MqttClient against a real Mosquitto: a robot process with many open descriptors (WebSocket
// clients, audit segments, a driver's sockets) must keep its fleet channel. libmosquitto's own
// loop (mosquitto_loop) uses select(), which cannot watch a descriptor numbered 1024 or more.
#include "transport/mqtt_client.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "test_support.h"

namespace rcan::transport {
namespace {

template <typename F>
bool eventually(F f, int timeout_ms = 10000) {
  for (int waited = 0; waited < timeout_ms; waited += 10) {
    if (f()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return f();
}

class Mosquitto {
 public:
  explicit Mosquitto(const std::string& dir) : port_(test::free_port()) {
    std::ofstream(dir + "/mosquitto.conf")
        << "listener " << port_ << " 127.0.0.1\nallow_anonymous true\npersistence false\n";
    EXPECT_TRUE(proc_.start({"/usr/sbin/mosquitto", "-c", dir + "/mosquitto.conf"}));
    EXPECT_TRUE(proc_.wait_for_line("running", 10000).has_value());
  }
  std::string url() const { return "mqtt://127.0.0.1:" + std::to_string(port_); }

 private:
  uint16_t port_;
  test::Process proc_;
};

// Holds `n` descriptors open (so that the next ones are numbered above them).
class ManyDescriptors {
 public:
  explicit ManyDescriptors(int n) {
    rlimit rl{};
    getrlimit(RLIMIT_NOFILE, &rl);
    const rlim_t want = static_cast<rlim_t>(n) + 256;
    if (rl.rlim_cur < want && rl.rlim_max >= want) {
      rl.rlim_cur = want;
      setrlimit(RLIMIT_NOFILE, &rl);
    }
    for (int i = 0; i < n; ++i) {
      int fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
      if (fd < 0) break;
      fds_.push_back(fd);
    }
  }
  ~ManyDescriptors() {
    for (int fd : fds_) ::close(fd);
  }
  size_t size() const { return fds_.size(); }

 private:
  std::vector<int> fds_;
};

TEST(MqttClient, KeepsItsChannelWhenTheProcessHoldsMoreThan1024Descriptors) {
  test::TempDir tmp;
  Mosquitto broker(tmp.path());
  ManyDescriptors held(1100);
  if (held.size() < 1100) GTEST_SKIP() << "cannot open 1100 descriptors here (RLIMIT_NOFILE)";

  MqttOptions o;
  o.url = broker.url();
  MqttClient client(o);
  std::mutex mu;
  std::vector<std::string> got;
  client.subscribe("rcan/test/many-fds", 1);
  client.on_message([&](const MqttMessage& m) {
    std::lock_guard<std::mutex> lk(mu);
    got.push_back(m.payload);
  });
  ASSERT_TRUE(client.start().ok());
  ASSERT_TRUE(eventually([&] { return client.connected() && client.all_subscribed(); }))
      << "no MQTT session with the broker while the process holds " << held.size()
      << " descriptors";
  // Publishes from another thread are sent at once, and what the broker delivers arrives.
  for (int i = 0; i < 20; ++i)
    ASSERT_TRUE(client.publish("rcan/test/many-fds", "m" + std::to_string(i), 1, false).ok());
  EXPECT_TRUE(eventually([&] {
    std::lock_guard<std::mutex> lk(mu);
    return got.size() == 20;
  }));
  // The broker's acknowledgement reaches the publisher (what a fleet ESTOP waits for).
  EXPECT_TRUE(client.publish_confirmed("rcan/test/many-fds", "confirmed", 1, false, 5000).ok());
  client.stop();
}

// The same client with few descriptors: connects, round-trips at QoS 0 and 1, stops.
TEST(MqttClient, RoundTripAndCleanStop) {
  test::TempDir tmp;
  Mosquitto broker(tmp.path());
  MqttOptions o;
  o.url = broker.url();
  MqttClient client(o);
  std::atomic<int> got{0};
  client.subscribe("rcan/test/rt", 1);
  client.on_message([&](const MqttMessage&) { got.fetch_add(1); });
  ASSERT_TRUE(client.start().ok());
  ASSERT_TRUE(eventually([&] { return client.connected() && client.all_subscribed(); }));
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(client.publish("rcan/test/rt", "x", i % 2, false).ok());
  EXPECT_TRUE(eventually([&] { return got.load() == 100; })) << got.load();
  client.stop();
  EXPECT_FALSE(client.connected());
}

}  // namespace
}  // namespace rcan::transport
