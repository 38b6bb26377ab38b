// Driver-process benchmark (plain main, prints numbers; not a test). docs/DRIVERS.md quotes it.
//
// The benchmark plays the driver process itself: it listens on a Unix socket, and a
// SafetyCore over a ProcessDriver (driver.process.socket) connects to it. The peer answers
// describe and heartbeats like any driver and timestamps every frame as it reads it.
//
// 1. COMMAND → apply frame: 1 and 16 client threads call SafetyCore::dispatch() (what the
//    node's pipeline calls once a COMMAND is admitted and audited) with drive commands of
//    unique speeds; the time from the call to the peer reading the matching apply frame,
//    p50 / p99 / max. Each client waits for its command to arrive before it sends the next
//    (as an HTTP client waits for its ACK); the open-loop line sends back to back, which
//    outruns the reading peer and shows the driver refusing what its full queue cannot take.
// 2. ESTOP → stop frame: SafetyCore::estop() called while a drive is active, idle and with 16
//    threads hammering dispatch(); the time from the call to the peer reading the stop frame.
//
// 3. With --rcand PATH, the same through a real rcand (driver.type process, driver.process.socket
//    = the peer): a move COMMAND POSTed to /rcan/v1/command (HTTP, token, replay guard, audit
//    record, safety core) → the apply frame, 1 and 16 clients (each waits for its ACK); a SAFETY
//    ESTOP POSTed → the stop frame.
//
// Usage: process_driver_bench [commands_per_client=500] [estop_trials=300] [--rcand PATH]
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bench_support.h"
#include "drivers/process/frame.h"
#include "drivers/process/process_driver.h"
#include "node/safety/safety.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/json.h"

using namespace rcan;
using namespace rcan::node;

namespace {

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

int64_t key_of(double v) { return std::llround(v * 1e7); }

// The driver process, played in-process: answers the handshake and heartbeats, timestamps
// apply frames (by speed) and stop frames as it reads them.
class Peer {
 public:
  explicit Peer(const std::string& path) {
    srv_ = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strncpy(a.sun_path, path.c_str(), sizeof a.sun_path - 1);
    ::unlink(path.c_str());
    if (::bind(srv_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(srv_, 1) != 0) {
      std::perror("peer socket");
      std::exit(1);
    }
    th_ = std::thread([this] { run(); });
  }
  ~Peer() {
    quit_ = true;
    th_.join();
    ::close(srv_);
  }
  // The time the apply frame with this speed was read (0: not yet).
  int64_t apply_ns(double v) {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = applies_.find(key_of(v));
    return it == applies_.end() ? 0 : it->second;
  }
  int64_t last_stop_ns() const { return last_stop_.load(std::memory_order_acquire); }

 private:
  void send(int fd, const std::string& json) {
    const std::string f = drivers::encode_frame(json);
    (void)!::send(fd, f.data(), f.size(), MSG_NOSIGNAL);
  }
  void run() {
    const int c = ::accept(srv_, nullptr, nullptr);
    drivers::FrameDecoder dec;
    char buf[65536];
    while (!quit_) {
      pollfd p{c, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      const ssize_t n = ::recv(c, buf, sizeof buf, 0);
      const int64_t t = now_ns();
      if (n <= 0) break;
      dec.feed(buf, static_cast<size_t>(n));
      while (true) {
        auto f = dec.next();
        if (!f.ok() || !*f) break;
        auto v = json::parse(**f);
        if (!v.ok()) continue;
        const std::string type = v->get("type")->as_string();
        if (type == "describe") {
          send(c, R"({"type":"describe","protocol":1,"name":"bench-peer"})");
        } else if (type == "heartbeat") {
          send(c, R"({"type":"heartbeat"})");
        } else if (type == "stop") {
          last_stop_.store(t, std::memory_order_release);
        } else if (type == "apply") {
          const json::Value* d = v->get("command")->get("drive");
          if (!d) continue;
          std::lock_guard<std::mutex> lock(mu_);
          applies_.emplace(key_of(d->get("linear_mps")->to_double()), t);
        }
      }
    }
    ::close(c);
  }
  int srv_ = -1;
  std::atomic<bool> quit_{false};
  std::thread th_;
  std::mutex mu_;
  std::map<int64_t, int64_t> applies_;
  std::atomic<int64_t> last_stop_{0};
};

struct Stats {
  double p50 = 0, p99 = 0, max = 0;
  size_t n = 0;
};

Stats stats(std::vector<double> us) {
  Stats s;
  if (us.empty()) return s;
  std::sort(us.begin(), us.end());
  s.n = us.size();
  s.p50 = us[us.size() / 2];
  s.p99 = us[std::min(us.size() - 1, static_cast<size_t>(us.size() * 0.99))];
  s.max = us.back();
  return s;
}

// `refused`: commands the driver refused (its queue of 32 frames was full: the peer did not
// read fast enough), not counted in the latencies.
void print(const char* what, const Stats& s, size_t refused = 0) {
  std::printf("%-44s n=%-6zu p50 %8.1f us   p99 %8.1f us   max %8.1f us", what, s.n, s.p50, s.p99,
              s.max);
  if (refused) std::printf("   (%zu refused)", refused);
  std::printf("\n");
}

bool wait_for(const std::function<bool()>& pred, int64_t timeout_ms = 2000) {
  const int64_t end = now_ns() + timeout_ms * 1'000'000;
  while (now_ns() < end) {
    if (pred()) return true;
    std::this_thread::yield();
  }
  return pred();
}

// `clients` threads dispatch `per_client` drive commands each (back to back); the latency of
// each, from the call to the peer reading it.
std::vector<double> command_latency(SafetyCore& core, Peer& peer, int clients, int per_client,
                                    int base, size_t& refused, bool closed = true) {
  std::vector<std::vector<std::pair<double, int64_t>>> sent(clients);
  std::vector<std::thread> th;
  std::atomic<size_t> bad{0};
  std::mutex why_mu;
  std::string why;
  for (int c = 0; c < clients; ++c)
    th.emplace_back([&, c] {
      for (int i = 0; i < per_client; ++i) {
        const double v = 0.1 + 1e-7 * (base + c * per_client + i);
        const int64_t t0 = now_ns();
        auto r = core.dispatch(ActuatorCommand::make_drive(v, 0, 1000));
        if (r.ok()) {
          sent[c].emplace_back(v, t0);
        } else if (bad.fetch_add(1) == 0) {
          std::lock_guard<std::mutex> lock(why_mu);
          why = r.error().message;
        }
        if (closed) wait_for([&] { return peer.apply_ns(v) != 0; });
      }
    });
  for (auto& t : th) t.join();
  refused = bad.load();
  if (refused) std::printf("  (first refusal: %s)\n", why.c_str());
  std::vector<double> us;
  for (auto& per : sent)
    for (auto& [v, t0] : per) {
      if (!wait_for([&] { return peer.apply_ns(v) != 0; })) continue;
      us.push_back((peer.apply_ns(v) - t0) / 1000.0);
    }
  return us;
}

std::vector<double> estop_latency(SafetyCore& core, Peer& peer, int trials, int hammer) {
  std::atomic<bool> quit{false};
  std::vector<std::thread> th;
  for (int h = 0; h < hammer; ++h)
    th.emplace_back([&, h] {
      int i = 0;
      while (!quit) {
        (void)core.dispatch(ActuatorCommand::make_drive(0.3 + 1e-7 * (h * 1000000 + ++i), 0, 500));
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    });
  std::vector<double> us;
  for (int k = 0; k < trials; ++k) {
    (void)core.resume(3, "bench");
    const double v = 0.05 + 1e-7 * k;
    if (!core.dispatch(ActuatorCommand::make_drive(v, 0, 1000)).ok()) continue;
    if (!wait_for([&] { return peer.apply_ns(v) != 0; })) continue;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    const int64_t t0 = now_ns();
    core.estop("bench", "bench");
    if (!wait_for([&] { return peer.last_stop_ns() > t0; })) continue;
    us.push_back((peer.last_stop_ns() - t0) / 1000.0);
  }
  quit = true;
  for (auto& t : th) t.join();
  (void)core.resume(3, "bench");
  return us;
}

// ---- through rcand ---------------------------------------------------------------------------

std::string message(const std::string& type, json::Object payload) {
  return json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                             {"message_id", bench::fast_uuid()},
                                             {"type", type},
                                             {"timestamp_ms", bench::wall_ms()},
                                             {"payload", std::move(payload)}}));
}

int post(uint16_t port, const std::string& body, const std::string& token) {
  return bench::sync_http(port, boost::beast::http::verb::post, "/rcan/v1/command", body, token);
}

// rcand on `root`/node with driver.process.socket = `sock` and the node's local issuer trusted
// by name (rcand-local) in its --config.
bool start_rcand(bench::Node& n, const std::string& rcand, const std::string& root,
                 const std::string& sock) {
  n.dir = root + "/node";
  if (!bench::start_node(n, rcand, {})) return false;  // the embedded run makes keys and issuer
  n.child->stop();
  std::ifstream seed_in(n.dir + "/issuer/ed25519.seed", std::ios::binary);
  std::string seed(32, '\0');
  seed_in.read(seed.data(), static_cast<std::streamsize>(seed.size()));
  seed.resize(static_cast<size_t>(seed_in.gcount()));
  auto pk = ed25519::public_key_from_seed(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(seed.data()), seed.size()));
  if (!pk.ok()) return false;
  auto pem = ed25519::public_key_to_pem(*pk);
  if (!pem.ok()) return false;
  std::ofstream(root + "/issuer.pem") << *pem;
  std::string yaml = bench::default_yaml_for(n.dir);
  auto replace = [&](const std::string& from, const std::string& to) {
    const size_t p = yaml.find(from);
    if (p != std::string::npos) yaml.replace(p, from.size(), to);
  };
  replace("  jwt:\n    leeway_s: 60\n",
          "  jwt:\n    leeway_s: 60\n    issuers:\n      - {issuer: "
          "rcand-local, key_file: " +
              root + "/issuer.pem}\n");
  replace("driver:\n  type: sim\n", "driver:\n  type: process\n  process: {socket: " + sock +
                                        ", max_linear_mps: 1.0, max_angular_radps: 2.0}\n");
  std::ofstream(root + "/process.rcan.yaml") << yaml;
  bench::Node m;
  m.dir = n.dir;
  if (!bench::start_node(m, rcand, {"--config", root + "/process.rcan.yaml"})) return false;
  n = std::move(m);
  return true;
}

void through_rcand(const std::string& rcand, const std::string& root, int per_client, int trials) {
  const std::string sock = root + "/rcand-drv.sock";
  Peer peer(sock);
  bench::Node n;
  if (!start_rcand(n, rcand, root, sock)) {
    std::fprintf(stderr, "rcand did not start with driver.type process\n");
    return;
  }
  bench::settle(n.child->pid());
  const std::string token =
      bench::token_for(n.dir + "/issuer/ed25519.seed", "rcand-local", n.ruri, "bench");
  std::printf("through rcand: POST /rcan/v1/command -> ... -> Unix socket -> peer\n");
  for (int clients : {1, 16}) {
    std::vector<std::vector<double>> lat(clients);
    std::atomic<size_t> failed{0};
    std::vector<std::thread> th;
    const int count = clients == 1 ? per_client : std::max(1, per_client / 4);
    for (int c = 0; c < clients; ++c)
      th.emplace_back([&, c] {
        for (int i = 0; i < count; ++i) {
          const double v = 0.1 + 1e-7 * (clients * 10000 + c * count + i);
          const std::string body = message(
              "COMMAND", json::Object{{"action", "move"}, {"linear", v}, {"duration_ms", 1000}});
          const int64_t t0 = now_ns();
          if (post(n.port, body, token) != 200 ||
              !wait_for([&] { return peer.apply_ns(v) != 0; })) {
            failed.fetch_add(1);
            continue;
          }
          lat[c].push_back((peer.apply_ns(v) - t0) / 1000.0);
        }
      });
    for (auto& t : th) t.join();
    std::vector<double> all;
    for (auto& l : lat) all.insert(all.end(), l.begin(), l.end());
    print(clients == 1 ? "COMMAND (HTTP) -> apply frame, 1 client"
                       : "COMMAND (HTTP) -> apply frame, 16 clients",
          stats(all), failed.load());
  }
  std::vector<double> us;
  for (int k = 0; k < trials; ++k) {
    const double v = 0.2 + 1e-7 * k;
    (void)post(n.port, message("SAFETY", json::Object{{"safety_event", "RESUME"}}), token);
    if (post(n.port,
             message("COMMAND",
                     json::Object{{"action", "move"}, {"linear", v}, {"duration_ms", 1000}}),
             token) != 200 ||
        !wait_for([&] { return peer.apply_ns(v) != 0; }))
      continue;
    const std::string estop =
        message("SAFETY", json::Object{{"safety_event", "ESTOP"}, {"reason", "bench"}});
    const int64_t t0 = now_ns();
    if (post(n.port, estop, token) != 200) continue;
    if (!wait_for([&] { return peer.last_stop_ns() > t0; })) continue;
    us.push_back((peer.last_stop_ns() - t0) / 1000.0);
  }
  print("ESTOP (HTTP) -> stop frame", stats(us), static_cast<size_t>(trials) - us.size());
  n.child->stop();
}

}  // namespace

int main(int argc, char** argv) {
  std::string rcand;
  std::vector<std::string> pos;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--rcand" && i + 1 < argc) {
      rcand = argv[++i];
    } else {
      pos.emplace_back(argv[i]);
    }
  }
  const int per_client = pos.size() > 0 ? std::atoi(pos[0].c_str()) : 500;
  const int trials = pos.size() > 1 ? std::atoi(pos[1].c_str()) : 300;
  char tmpl[] = "/tmp/rcan-procbench-XXXXXX";
  if (!mkdtemp(tmpl)) return 1;
  const std::string path = std::string(tmpl) + "/drv.sock";
  Peer peer(path);
  drivers::ProcessDriverOptions o;
  o.file.socket = path;
  o.info.name = "process";
  o.info.has_base = true;
  o.info.max_linear_mps = 1.0;
  o.info.max_angular_radps = 2.0;
  auto driver = std::make_unique<drivers::ProcessDriver>(o);
  if (!driver->start().ok() || !driver->healthy()) {
    std::fprintf(stderr, "the driver did not connect\n");
    return 1;
  }
  SafetyConfig cfg;
  cfg.limits.max_linear_mps = 1.0;
  SafetyCore core(std::move(driver), cfg);
  core.start();
  std::printf("driver.type process: SafetyCore -> ProcessDriver -> Unix socket -> peer\n");
  size_t refused = 0;
  (void)command_latency(core, peer, 1, 50, 0, refused);  // warm-up
  Stats one = stats(command_latency(core, peer, 1, per_client, 1000000, refused));
  print("COMMAND -> apply frame, 1 client", one, refused);
  Stats sixteen = stats(command_latency(core, peer, 16, per_client, 2000000, refused));
  print("COMMAND -> apply frame, 16 clients", sixteen, refused);
  Stats burst = stats(command_latency(core, peer, 16, per_client, 3000000, refused, false));
  print("COMMAND -> apply frame, 16 clients, open loop", burst, refused);
  print("ESTOP -> stop frame, idle", stats(estop_latency(core, peer, trials, 0)));
  print("ESTOP -> stop frame, 16 clients dispatching",
        stats(estop_latency(core, peer, trials, 16)));
  core.stop();
  ::unlink(path.c_str());
  if (!rcand.empty()) through_rcand(rcand, tmpl, per_client, std::min(trials, 100));
  std::error_code ec;
  std::filesystem::remove_all(tmpl, ec);
  return 0;
}
