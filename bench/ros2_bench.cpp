// The ROS 2 driver's latencies, end to end (docs/DRIVERS.md §Numbers): rcand with
// `driver.type: ros2` on loopback DDS, and this program as the robot — a DDS reader on
// rt/cmd_vel (geometry_msgs::msg::dds_::Twist_) that timestamps every Twist as it arrives.
//   * COMMAND arrival → Twist on the wire: HTTP clients post COMMAND move over keep-alive
//     connections; each command's speeds are unique, and its first Twist is matched to it.
//     p50/p99 at 1 and at 16 clients.
//   * ESTOP arrival → zero Twist on the wire: POST /api/stop while a drive runs (the last
//     Twist written is a moving one), until the first zero Twist; idle and under 16 clients.
// Times are from just before the request is written to the socket until the DDS listener runs
// (both in this process, one steady clock). Not a test: it prints numbers.
//
//   ros2_bench [--rcand PATH] [--commands 2000] [--stops 50]
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bench_support.h"
#include "drivers/ros2/ros2_driver.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "ros2_peer.h"

using namespace rcan;
namespace fs = std::filesystem;

namespace {

class Conn {
 public:
  explicit Conn(uint16_t port) {
    fd_ = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
      close(fd_);
      fd_ = -1;
    }
    int one = 1;
    if (fd_ >= 0) setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  }
  ~Conn() {
    if (fd_ >= 0) close(fd_);
  }
  // Sends; `on_send(t)` runs with the steady time just before the write (the Twist may come
  // back before the answer). Returns the HTTP status (0: failed).
  template <typename F>
  int post(const std::string& path, const std::string& body, const std::string& token, F on_send) {
    if (fd_ < 0) return 0;
    const std::string req =
        "POST " + path + " HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + token +
        "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
        "\r\n\r\n" + body;
    on_send(test::steady_ns());
    if (send(fd_, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size()))
      return 0;
    return read_response();
  }
  int post(const std::string& path, const std::string& body, const std::string& token) {
    return post(path, body, token, [](int64_t) {});
  }
  int get(const std::string& path, std::string* out) {
    const std::string req = "GET " + path + " HTTP/1.1\r\nHost: x\r\n\r\n";
    if (fd_ < 0 ||
        send(fd_, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size()))
      return 0;
    const int st = read_response();
    if (out) *out = last_body_;
    return st;
  }

 private:
  int read_response() {
    while (true) {
      const size_t end = buf_.find("\r\n\r\n");
      if (end != std::string::npos) {
        size_t cl = 0;
        const size_t p = buf_.find("Content-Length: ");
        if (p != std::string::npos && p < end)
          cl = std::strtoul(buf_.c_str() + p + 16, nullptr, 10);
        if (buf_.size() >= end + 4 + cl) {
          const int status = std::atoi(buf_.c_str() + 9);
          last_body_ = buf_.substr(end + 4, cl);
          buf_.erase(0, end + 4 + cl);
          return status;
        }
      }
      pollfd pf{fd_, POLLIN, 0};
      if (poll(&pf, 1, 10000) <= 0) return 0;
      char tmp[65536];
      const ssize_t k = recv(fd_, tmp, sizeof tmp, 0);
      if (k <= 0) return 0;
      buf_.append(tmp, static_cast<size_t>(k));
    }
  }
  int fd_ = -1;
  std::string buf_;
  std::string last_body_;
};

std::string message(const char* type, json::Object payload) {
  return json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                             {"message_id", new_uuid_v4()},
                                             {"type", type},
                                             {"timestamp_ms", bench::wall_ms()},
                                             {"payload", std::move(payload)}}));
}
std::string move(double linear, double angular, int64_t ms) {
  return message(
      "COMMAND",
      json::Object{
          {"action", "move"}, {"linear", linear}, {"angular", angular}, {"duration_ms", ms}});
}
std::string resume() { return message("SAFETY", json::Object{{"safety_event", "RESUME"}}); }

// Speeds that name a command for the whole run: linear 1e-6·(seq+1) (seq < 100000, so at
// most 0.1 m/s), angular 0.01·(client+1).
int64_t key_of(double lx, double az) {
  const int64_t seq = std::llround(lx * 1e6) - 1;
  const int64_t client = std::llround(az * 100.0) - 1;
  return client * 1'000'000 + seq;
}

// Pending commands (key → send time) and what their first Twist took.
struct Matcher {
  std::mutex mu;
  std::map<int64_t, int64_t> pending;
  std::vector<double> lat_us;
  void sent(int64_t key, int64_t t) {
    std::lock_guard<std::mutex> l(mu);
    pending[key] = t;
  }
  void got(const test::WireTwist& t) {
    if (t.zero()) return;
    std::lock_guard<std::mutex> l(mu);
    auto it = pending.find(key_of(t.lx, t.az));
    if (it == pending.end()) return;
    lat_us.push_back(static_cast<double>(t.t_ns - it->second) / 1000.0);
    pending.erase(it);
  }
};

void print(const char* what, std::vector<double> v) {
  std::sort(v.begin(), v.end());
  std::printf("%-44s n=%-6zu p50 %8.1f us   p99 %8.1f us   max %8.1f us\n", what, v.size(),
              bench::pct(v, 0.50), bench::pct(v, 0.99), v.empty() ? 0.0 : v.back());
}

// A configured robot (`rcand init` in `dir`), made a ROS 2 robot on `domain`.
bool init_robot(const std::string& rcand, const std::string& dir, uint32_t domain) {
  const std::string cmd = rcand + " init --dir " + dir + " --yes --name ros2-bench >/dev/null";
  if (std::system(cmd.c_str()) != 0) {
    std::fprintf(stderr, "rcand init failed\n");
    return false;
  }
  std::ifstream in(dir + "/robot.rcan.yaml");
  std::string yaml, line;
  while (std::getline(in, line)) yaml += line + "\n";
  yaml = yaml.substr(0, yaml.rfind("driver:\n")) + "driver:\n  type: ros2\n  ros2:\n" +
         "    domain_id: " + std::to_string(domain) +
         "\n    cmd_rate_hz: 20\n    odom_timeout_ms: 0\n";
  std::ofstream(dir + "/robot.rcan.yaml", std::ios::trunc) << yaml;
  return true;
}

// rcand, the robot (a DDS reader on rt/cmd_vel) and what the robot has seen.
struct Bench {
  explicit Bench(uint32_t domain) : robot(domain) {}

  test::Ros2Peer robot;
  bench::Node node;
  std::string issuer_seed;
  Matcher m;
  std::atomic<int64_t> estop_sent{0}, estop_zero{0};
  std::atomic<bool> measuring_estop{false};
  std::atomic<int64_t> last_moving{0};  // arrival of the last moving Twist
  std::atomic<bool> done{false};
  std::thread feeder;
  int seq_counter[16] = {};

  std::string token(const std::string& sub) const {
    return bench::token_for(issuer_seed, "rcand-local", node.ruri, sub);
  }

  // The peer collects Twists in order; this thread takes them to the matcher as they come.
  void start_feeder() {
    feeder = std::thread([this] {
      while (!done) {
        for (const auto& t : robot.drain(50)) {
          m.got(t);
          if (!t.zero()) last_moving = t.t_ns;
          if (measuring_estop && t.zero() && t.t_ns >= estop_sent.load() && estop_zero.load() == 0)
            estop_zero = t.t_ns;
        }
      }
    });
  }
  void stop_feeder() {
    done = true;
    if (feeder.joinable()) feeder.join();
  }

  // COMMAND → Twist: `clients` keep-alive connections, `per_client` commands each.
  void command_phase(int clients, int per_client, const char* label) {
    {
      std::lock_guard<std::mutex> l(m.mu);
      m.lat_us.clear();
      m.pending.clear();
    }
    std::atomic<int> failures{0};
    std::vector<std::thread> th;
    for (int c = 0; c < clients; ++c) {
      th.emplace_back([&, c] {
        int* next_seq = &seq_counter[c];
        Conn conn(node.port);
        const std::string tok = token("bench-" + std::to_string(c));
        for (int i = 0; i < per_client; ++i) {
          const int seq = (*next_seq)++;
          const double lx = 1e-6 * (seq + 1), az = 0.01 * (c + 1);
          const std::string body = move(lx, az, 200);
          const int st = conn.post("/rcan/v1/command", body, tok,
                                   [&](int64_t t) { m.sent(key_of(lx, az), t); });
          if (st != 200) ++failures;
        }
      });
    }
    for (auto& t : th) t.join();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    std::vector<double> lat;
    {
      std::lock_guard<std::mutex> l(m.mu);
      lat = m.lat_us;
    }
    print(label, lat);
    if (failures) std::printf("  (%d commands not answered 200)\n", failures.load());
  }

  // One ESTOP while the robot moves: its latency to the first zero Twist, -1 when none came,
  // -2 when the robot was not moving (not measured: a zero Twist was already on the wire).
  double one_estop(const std::string& admin, const std::string& driver,
                   std::map<int, int>& drive_answers) {
    Conn c(node.port);
    c.post("/rcan/v1/command", resume(), admin);
    // A drive, so that the last Twist on the wire is a moving one.
    ++drive_answers[c.post("/rcan/v1/command", move(0.3, 0.0, 5000), driver)];
    Conn s(node.port);  // connected before the clock starts
    std::this_thread::sleep_for(std::chrono::milliseconds(60));
    // Only while the robot is moving (a moving Twist in the last 30 ms).
    int k = 0;
    for (; k < 500 && test::steady_ns() - last_moving.load() > 30'000'000; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (k == 500) return -2;
    estop_zero = 0;
    int64_t t = 0;
    s.post("/api/stop", "{\"reason\":\"bench\"}", admin, [&](int64_t at) {
      t = at;
      estop_sent = at;
      measuring_estop = true;
    });
    for (int w = 0; w < 200 && estop_zero.load() == 0; ++w)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    measuring_estop = false;
    const int64_t z = estop_zero.load();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    return z != 0 ? static_cast<double>(z - t) / 1000.0 : -1.0;
  }

  // ESTOP → zero Twist, `stops` times; with `load`, 16 clients keep commanding meanwhile.
  void estop_phase(bool load, int stops, const char* label) {
    std::atomic<bool> stop_load{false};
    std::vector<std::thread> th;
    for (int c = 0; load && c < 16; ++c) {
      th.emplace_back([&, c] {
        Conn conn(node.port);
        const std::string tok = token("load-" + std::to_string(c));
        // 50 commands a second each (800/s in all): a load the node answers, not one that
        // fills its replay memory and has the robot's own commands refused.
        while (!stop_load) {
          if (conn.post("/rcan/v1/command", move(0.2, 0.0, 100), tok) == 0) break;
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
      });
    }
    const std::string admin = token("bench-operator");
    const std::string driver = token("bench-driver");
    (void)node.child->take_kept();  // estop.latency lines: only this phase's
    std::vector<double> lat;
    std::map<int, int> drive_answers;
    int not_moving = 0;
    for (int i = 0; i < stops; ++i) {
      const double us = one_estop(admin, driver, drive_answers);
      if (us >= 0) lat.push_back(us);
      if (us == -2) ++not_moving;
    }
    stop_load = true;
    for (auto& t : th) t.join();
    Conn c(node.port);
    c.post("/rcan/v1/command", resume(), admin);
    print(label, lat);
    // rcand's own figure for the same ESTOPs: from the request's read to Driver::stop()
    // returning — the zero Twist has been handed to the socket by then (dds_write sends in
    // the caller's thread), so this is ESTOP arrival -> zero Twist on the wire.
    std::vector<double> node_us;
    for (auto& line : node.child->take_kept()) {
      auto v = json::parse(line);
      const json::Value* us = v.ok() ? v->get("arrival_to_driver_us") : nullptr;
      if (us && us->is_number()) node_us.push_back(us->to_double());
    }
    print("  in rcand: ESTOP read -> zero Twist written", node_us);
    if (not_moving > 0) {
      std::printf(
          "  (%d of %d ESTOPs not measured: the robot was not moving; the drive before "
          "each ESTOP was answered",
          not_moving, stops);
      for (const auto& [status, n] : drive_answers) std::printf(" %d x%d", status, n);
      std::printf(")\n");
    }
    if (lat.size() + not_moving < static_cast<size_t>(stops))
      std::printf("  (%zu of %d ESTOPs without a zero Twist within 200 ms)\n",
                  stops - not_moving - lat.size(), stops);
  }
};

// The driver alone, in this process (no HTTP, no safety core, no network: Cyclone delivers to
// a reader in the same process directly): Driver::apply() and Driver::stop() to the Twist at
// the DDS listener — the driver's own share of the figures above.
bool driver_alone() {
  config::Ros2DriverConfig cfg;
  cfg.domain_id = test::random_domain_id();
  cfg.odom_timeout_ms = 0;
  auto d = drivers::ros2::Ros2Driver::create(cfg);
  test::Ros2Peer peer(cfg.domain_id);
  if (!d.ok() || !peer.ok() || !peer.wait_matched(10000)) {
    std::fprintf(stderr, "in-process driver: no DDS match\n");
    return false;
  }
  std::vector<double> apply_us, stop_us;
  auto first = [&](int64_t t0, bool zero, std::vector<double>& out) {
    peer.wait([](const std::vector<test::WireTwist>& v) { return !v.empty(); }, 1000);
    const auto v = peer.twists();
    if (!v.empty() && v[0].zero() == zero)
      out.push_back(static_cast<double>(v[0].t_ns - t0) / 1000.0);
    peer.clear();
  };
  for (int i = 0; i < 200; ++i) {
    peer.clear();
    const int64_t t0 = test::steady_ns();
    (void)(*d)->apply(node::ActuatorCommand::make_drive(0.2, 0.0, 5000));
    first(t0, false, apply_us);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    peer.clear();
    const int64_t t1 = test::steady_ns();
    (*d)->stop();
    first(t1, true, stop_us);
  }
  print("Driver::apply() -> Twist (in-process reader)", apply_us);
  print("Driver::stop() -> zero Twist (in-process reader)", stop_us);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string rcand = (fs::path(argv[0]).parent_path() / ".." / "bin" / "rcand").string();
  int commands = 2000, stops = 50;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--rcand") rcand = argv[i + 1];
    if (a == "--commands") commands = std::atoi(argv[i + 1]);
    if (a == "--stops") stops = std::atoi(argv[i + 1]);
  }
  test::use_loopback_dds();  // rcand inherits it
  const uint32_t domain = test::random_domain_id();
  char tmpl[] = "/tmp/rcan-ros2-bench-XXXXXX";
  const std::string root = mkdtemp(tmpl);
  const std::string dir = root + "/robot";
  if (!init_robot(rcand, dir, domain)) return 1;
  int rc = 0;
  {
    Bench b(domain);
    b.node.dir = dir;
    b.issuer_seed = dir + "/issuer/ed25519.seed";
    if (!b.robot.ok() ||
        !bench::start_node(b.node, rcand, {"--config", dir + "/robot.rcan.yaml"})) {
      rc = 1;
    } else if (!b.robot.wait_matched(15000)) {
      std::fprintf(stderr, "no DDS match with rcand\n");
      rc = 1;
    } else {
      b.start_feeder();
      bench::settle(b.node.child->pid());
      std::printf(
          "ros2_bench: rcand (driver.type ros2, DDS domain %u, loopback) — COMMAND and ESTOP "
          "to the DDS wire\n",
          domain);
      b.command_phase(1, commands, "COMMAND -> Twist on rt/cmd_vel, 1 client");
      b.command_phase(16, std::max(1, commands / 8), "COMMAND -> Twist on rt/cmd_vel, 16 clients");
      b.estop_phase(false, stops, "ESTOP -> zero Twist on rt/cmd_vel, idle");
      b.estop_phase(true, stops, "ESTOP -> zero Twist on rt/cmd_vel, 16 clients");
      b.stop_feeder();
    }
    if (b.node.child) b.node.child->stop();
  }
  fs::remove_all(root);
  if (rc == 0 && !driver_alone()) rc = 1;
  return rc;
}
