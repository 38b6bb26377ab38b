// A fleet through one Mosquitto broker or a NATS cluster: N simulated robots (default 200), each
// a complete node stack in this process — safety core and simulated robot, HMAC audit log on
// disk, the one pipeline, and its own MQTT connection (MqttNode) — exactly what rcand wires up
// (on the same allocator, jemalloc), minus the HTTP port. The bench starts the broker(s) on free
// loopback ports, then:
//
//   1. fleet ESTOP: publishes a retained SAFETY ESTOP on the fleet's estop topic (QoS 2 on
//      Mosquitto, QoS 1 on NATS, which does no QoS 2; the robots subscribe at mqtt.estop_qos,
//      1 unless --estop-qos 0 or 2) and
//      times, per robot, publish → the safety core latching (measured inside the robot's
//      Actuation) and publish → the robot's ACK arriving back at the coordinator;
//   2. RESUME, then a broadcast FLEET_COMMAND (`status`, then a short `move`): times publish →
//      each robot's ACK at the coordinator.
//
// Repeats each round --rounds times, each once the robots and the brokers are back to their idle
// CPU rates, and prints percentiles over all robot×round samples.
//
//   fleet_bench [--robots 200] [--rounds 5] [--estop-qos 0|1|2] [--segment-kib 1024]
//               [--broker mosquitto|nats] [--nats-nodes 3] [--light 0|1]
//               [--mosquitto /usr/sbin/mosquitto] [--nats-server /usr/sbin/nats-server]
//               [--perf-ctl FIFO --profile-round N] [--warm-up 0|1]
//               [--nats-consumers replicated|memory] [--ramp N] [--reply-qos 0|1]
//               [--coordinator-alg ed25519|ml-dsa-65] [--members node|transport]
//               [--robot-dir DIR] [--preallocate 0|1]
//
// --broker nats: a cluster of --nats-nodes nats-server processes (MQTT listener, JetStream,
// routes between them, docs/FLEET.md §Running on NATS); robot i connects to node i mod N, the
// coordinator to node 1, so most ESTOPs cross the cluster.
//
// --nats-consumers memory: the NATS nodes keep each MQTT subscription's JetStream consumer in
// memory on one node (`mqtt { consumer_replicas: 1, consumer_memory_storage: true }`) instead of
// replicated on disk as the streams are: a robot renews its subscriptions on every reconnect,
// so a consumer lost with its node costs nothing that failover does not redo.
//
// --ramp N: robots start N at a time, each batch connected with every subscription granted
// before the next starts (a broker that creates state per session, as NATS does in JetStream,
// is not asked for 1,000 sessions at once).
//
// --light 1: light members, so that 1,000 fit on a small machine: each robot's audit log keeps
// its records, chain and fsyncs but preallocates nothing (a preallocated segment per robot is
// 1,000 zero-filled files written while measuring) and writes its index inline.
//
// --robot-dir DIR: the robots' latch files and audit logs go under DIR (the brokers' files stay
// in the temporary directory). `--robot-dir /dev/shm` puts them in memory, where fdatasync
// costs nothing: not a configuration that keeps a latch or a record, but the measure of what the
// two durable writes of an ESTOP cost on this machine's disk (the difference between the runs).
//
// --preallocate 0|1: each audit segment zero-filled before use (rcand's default) or not,
// whatever --light says.
//
// --coordinator-alg ml-dsa-65: the coordinator signs with ML-DSA-65 (its fleet token binds that
// key) instead of Ed25519; the robots verify an ML-DSA-65 signature instead of an Ed25519 one.
//
// --members transport: each robot is its MQTT connection alone (same client id scheme,
// persistent session, subscriptions, QoS and broker node), answering every fleet message with a
// bare ACK: no parse, signature check, safety core or audit log. What the broker(s) and the
// connections cost on their own — the floor under the full members' numbers.
//
// The CPU lines: the whole process less the idle fleet's rate over the same window; "of the
// robots" also less the coordinator's thread (the operator's side, receiving every ACK); and per
// thread name (scheduler run time), so that the MQTT thread, the audit writer and the safety
// loop show apart.
//
// --reply-qos 0: the robots answer at QoS 0 (mqtt.reply_qos, docs/FLEET.md §Replies at QoS 0);
// the coordinator still subscribes at QoS 1.
//
// --warm-up 1: one broadcast `status` before round 1, so that the first ESTOP is no longer each
// robot's first message (the fleet token is verified then); separates first-message costs from
// the ESTOP's own.
//
// --perf-ctl FIFO --profile-round N: writes "enable" / "disable" to a `perf record --control
// fifo:FIFO --delay=-1` control fifo around round N's ESTOP, so that a profile holds that round
// alone (e.g. round 1, each robot's first message, against round 2).
// --profile-round -1: around every round's ESTOP (more samples for a flat profile).
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "base/clock.h"
#include "node/api/node.h"
#include "node/bindings/mqtt_node.h"
#include "node/fleet/fleet.h"
#include "node/safety/actuation_safety.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"
#include "node/services/node_services.h"
#include "rcan/audit/audit_log.h"
#include "rcan/crypto/cnf.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcan/mqtt_topics.h"
#include "runtime/log.h"
#include "transport/mqtt_client.h"

using namespace rcan;
namespace fs = std::filesystem;

namespace {

// CPU seconds used by this process so far (every robot's threads).
double cpu_now() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) / 1e6;
}

// Minor page faults of this process so far.
long faults_now() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_minflt + ru.ru_majflt;
}

// Voluntary context switches (the thread slept: a wake-up) of this process's threads, summed
// by thread name (the node names its threads: mqtt-io, audit-writer, safety-tick, …).
// Per thread name, summed over this process's threads: voluntary context switches (wake-ups)
// and CPU time (the scheduler's runtime, /proc/.../schedstat, in ns).
struct ThreadCounts {
  long wakeups = 0;
  double cpu_ns = 0;
};
std::map<std::string, ThreadCounts> counts_by_thread() {
  std::map<std::string, ThreadCounts> out;
  std::error_code ec;
  const std::string self = std::to_string(::gettid());  // the reader: not counted
  for (const auto& e : fs::directory_iterator("/proc/self/task", ec)) {
    if (e.path().filename() == self) continue;
    std::ifstream comm(e.path() / "comm");
    std::string name;
    std::getline(comm, name);
    ThreadCounts& c = out[name];
    std::ifstream st(e.path() / "status");
    std::string line;
    while (std::getline(st, line))
      if (line.rfind("voluntary_ctxt_switches:", 0) == 0) c.wakeups += std::atol(line.c_str() + 24);
    std::ifstream sched(e.path() / "schedstat");
    double run_ns = 0;
    if (sched >> run_ns) c.cpu_ns += run_ns;
  }
  return out;
}

double mono_ms() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
int64_t wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

uint16_t free_port() {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

// Records when the safety core latched: the call plus the time it took to stop the driver
// (estop()'s result), not the latch file written after it.
class TimedActuation final : public node::Actuation {
 public:
  explicit TimedActuation(node::SafetyActuation& inner) : inner_(inner) {}
  bool estop_active() const override { return inner_.estop_active(); }
  uint64_t estop_epoch() const override { return inner_.estop_epoch(); }
  double estop(const std::string& source, const std::string& reason, Role by,
               node::EstopLatchFn on_latch, bool persist_here) override {
    const double called_at = mono_ms();
    double us = inner_.estop(source, reason, by, std::move(on_latch), persist_here);
    latched_at.store(called_at + us / 1000.0);
    return us;
  }
  Status resume(Role role, const std::string& source) override {
    return inner_.resume(role, source);
  }
  void stop(const std::string& source) override { inner_.stop(source); }
  Result<node::PreparedCommand> prepare(const Message& msg, const ActionSpec& spec,
                                        int64_t deadline, const std::string& sid,
                                        std::optional<uint64_t> stream_epoch) override {
    return inner_.prepare(msg, spec, deadline, sid, stream_epoch);
  }
  Result<json::Value> apply(const node::PreparedCommand& cmd) override { return inner_.apply(cmd); }
  void arm_deadman(const std::string& s, int64_t t) override { inner_.arm_deadman(s, t); }
  void feed_deadman(const std::string& s) override { inner_.feed_deadman(s); }
  void disarm_deadman(const std::string& s) override { inner_.disarm_deadman(s); }
  Status rearm(const std::string& s) override { return inner_.rearm(s); }
  json::Value status() const override { return inner_.status(); }
  json::Value telemetry() const override { return inner_.telemetry(); }
  std::atomic<double> latched_at{0};

 private:
  node::SafetyActuation& inner_;
};

struct Robot {
  std::string member;
  // --members transport: only this connection, answering every message with a bare ACK.
  std::unique_ptr<transport::MqttClient> bare;
  std::atomic<double> heard_at{0};  // when `bare` received the round's ESTOP
  std::unique_ptr<node::SafetyCore> core;
  std::unique_ptr<node::SafetyActuation> act;
  std::unique_ptr<TimedActuation> timed;
  std::unique_ptr<audit::AuditLog> audit;
  std::unique_ptr<node::NodeServices> svc;
  std::unique_ptr<node::Node> node;
  std::unique_ptr<node::MqttNode> mqtt;

  bool subscribed() const { return bare ? bare->all_subscribed() : mqtt->subscribed(); }
  bool connected() const { return bare ? bare->connected() : mqtt->connected(); }
  double latched_at() const { return bare ? heard_at.load() : timed->latched_at.load(); }
  void clear_latch() { bare ? heard_at.store(0) : timed->latched_at.store(0); }
};

// The pipeline's stage timers (wall time per stage, node/metrics.h), summed over all robots:
// stage → {sum_us, count}. A round's deltas show where its time went.
constexpr const char* kStages[] = {"parse",     "shape", "token",     "decode", "auth",
                                   "freshness", "fleet", "authorize", "replay", "safety_state",
                                   "dispatch",  "audit", "total"};
std::map<std::string, std::pair<double, uint64_t>> stage_totals(
    const std::vector<std::unique_ptr<Robot>>& robots) {
  std::map<std::string, std::pair<double, uint64_t>> out;
  for (const auto& r : robots)
    for (const char* name : kStages) {
      if (!r->svc) continue;
      const rcan::Histogram& h = r->svc->metrics.stage(name);
      auto& [sum, n] = out[name];
      sum += h.sum_us();
      n += h.count();
    }
  return out;
}

double pct(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  size_t i = static_cast<size_t>(p / 100.0 * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

void report(const char* what, const std::vector<double>& v, size_t expected) {
  std::printf("%-34s n=%zu/%zu  p50 %.2f ms  p90 %.2f ms  p99 %.2f ms  max %.2f ms\n", what,
              v.size(), expected, pct(v, 50), pct(v, 90), pct(v, 99),
              v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()));
}

// The coordinator's side: one client subscribed to every member's reply topic.
class Coordinator {
 public:
  explicit Coordinator(const std::string& url) {
    transport::MqttOptions o;
    o.url = url;
    o.thread_name = "coordinator";
    client_ = std::make_unique<transport::MqttClient>(o);
    client_->subscribe("rcan/fleet/bench/robot/+/reply", 1);
    client_->on_message([this](const transport::MqttMessage& m) {
      double t = mono_ms();
      auto v = json::parse(m.payload);
      if (!v.ok()) return;
      const json::Value* rt = v->get("reply_to");
      const json::Value* ty = v->get("type");
      if (rt == nullptr || !rt->is_string() || ty == nullptr || !ty->is_string()) return;
      std::string member = m.topic.substr(std::string("rcan/fleet/bench/robot/").size());
      member = member.substr(0, member.find('/'));
      std::lock_guard<std::mutex> lk(mu_);
      if (rt->as_string() != awaiting_ || (ty->as_string() != "ACK" && ty->as_string() != "ERROR"))
        return;
      if (ty->as_string() == "ERROR") ++errors_;
      if (acked_.emplace(member, t).second) cv_.notify_all();
    });
    (void)client_->start();
    for (int i = 0; i < 3000 && !client_->connected(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (!client_->connected())
      std::fprintf(stderr, "fleet_bench: the coordinator could not connect to %s\n", url.c_str());
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  // Publishes and waits for `n` answers (up to `timeout_ms`); returns member → arrival time.
  std::map<std::string, double> round(const std::string& topic, const json::Value& msg,
                                      const std::string& id, int qos, bool retain, size_t n,
                                      double* t0, int timeout_ms, int* errors) {
    {
      std::lock_guard<std::mutex> lk(mu_);
      awaiting_ = id;
      acked_.clear();
      errors_ = 0;
    }
    *t0 = mono_ms();
    if (Status s = client_->publish(topic, json::dump(msg), qos, retain); !s.ok()) {
      std::fprintf(stderr, "fleet_bench: the coordinator's publish on %s failed: %s\n",
                   topic.c_str(), s.error().message.c_str());
      *errors = static_cast<int>(n);
      return {};
    }
    std::unique_lock<std::mutex> lk(mu_);
    cv_.wait_for(lk, std::chrono::milliseconds(timeout_ms), [&] { return acked_.size() >= n; });
    *errors = errors_;
    return acked_;
  }
  bool connected() const { return client_->connected(); }

 private:
  std::unique_ptr<transport::MqttClient> client_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::string awaiting_;
  std::map<std::string, double> acked_;
  int errors_ = 0;
};

// The command line.
struct Options {
  int robots_n = 200, rounds = 5, estop_qos = 1;
  // Each robot's audit log preallocates its active segment and a spare (zero-filled, see
  // docs/AUDIT.md §Durability). A real robot does that once on its own storage; 200 robots
  // in one process would write 2 × 200 × 64 MiB to one disk while being measured, so the
  // bench gives each log 1 MiB segments (--segment-kib) — the records and fsyncs are the same.
  uint64_t segment_bytes = 1024ull << 10;
  std::string mosquitto = "/usr/sbin/mosquitto";
  std::string perf_ctl;
  int profile_round = 0;
  int warm_up = 0;
  std::string broker = "mosquitto";
  int nats_nodes = 3;
  std::string nats_server = "/usr/sbin/nats-server";
  int light = 0;
  std::string members = "node";  // or "transport"
  std::string nats_consumers = "replicated";
  int ramp = 0;  // 0: every robot at once
  int reply_qos = 1;
  std::string coordinator_alg = "ed25519";
  std::string robot_dir;  // where the robots' state goes; empty: with the brokers' files
  int preallocate = -1;   // the audit segments zero-filled: -1 as --light says, 0 no, 1 yes
  int publish_qos() const { return broker == "nats" ? 1 : 2; }
};

// False (after printing the usage) when an option is out of range.
bool parse_options(int argc, char** argv, Options& o) {
  // A QoS: the whole argument a number, else -1 (refused below; atoi would make "x" QoS 0).
  auto qos_arg = [](const char* s) {
    char* end = nullptr;
    const long v = std::strtol(s, &end, 10);
    return end != s && *end == '\0' && v >= 0 && v <= 2 ? static_cast<int>(v) : -1;
  };
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--robots")
      o.robots_n = std::atoi(argv[i + 1]);
    else if (a == "--rounds")
      o.rounds = std::atoi(argv[i + 1]);
    else if (a == "--estop-qos")
      o.estop_qos = qos_arg(argv[i + 1]);
    else if (a == "--mosquitto")
      o.mosquitto = argv[i + 1];
    else if (a == "--perf-ctl")
      o.perf_ctl = argv[i + 1];
    else if (a == "--profile-round")
      o.profile_round = std::atoi(argv[i + 1]);
    else if (a == "--warm-up")
      o.warm_up = std::atoi(argv[i + 1]);
    else if (a == "--segment-kib")
      o.segment_bytes = std::strtoull(argv[i + 1], nullptr, 10) << 10;
    else if (a == "--broker")
      o.broker = argv[i + 1];
    else if (a == "--nats-nodes")
      o.nats_nodes = std::atoi(argv[i + 1]);
    else if (a == "--nats-server")
      o.nats_server = argv[i + 1];
    else if (a == "--light")
      o.light = std::atoi(argv[i + 1]);
    else if (a == "--members")
      o.members = argv[i + 1];

    else if (a == "--nats-consumers")
      o.nats_consumers = argv[i + 1];
    else if (a == "--ramp")
      o.ramp = std::atoi(argv[i + 1]);
    else if (a == "--reply-qos")
      o.reply_qos = qos_arg(argv[i + 1]);
    else if (a == "--coordinator-alg")
      o.coordinator_alg = argv[i + 1];
    else if (a == "--robot-dir")
      o.robot_dir = argv[i + 1];
    else if (a == "--preallocate")
      o.preallocate = std::atoi(argv[i + 1]);
  }
  if (o.robots_n < 1 || o.robots_n > 2000 || o.rounds < 1 || o.rounds > 1000 ||
      o.segment_bytes < (64u << 10) || (o.estop_qos < 0 || o.estop_qos > 2) ||
      (o.broker != "mosquitto" && o.broker != "nats") || o.nats_nodes < 1 || o.nats_nodes > 5 ||
      (o.nats_consumers != "replicated" && o.nats_consumers != "memory") || o.ramp < 0 ||
      (o.reply_qos != 0 && o.reply_qos != 1) || (o.members != "node" && o.members != "transport") ||
      (o.coordinator_alg != "ed25519" && o.coordinator_alg != "ml-dsa-65") || o.preallocate < -1 ||
      o.preallocate > 1) {
    std::fprintf(stderr,
                 "usage: fleet_bench [--robots 1..2000] [--rounds 1..1000] [--estop-qos 0|1|2] "
                 "[--segment-kib N] [--broker mosquitto|nats] [--nats-nodes 1..5] [--light 0|1] "
                 "[--mosquitto PATH] [--nats-server PATH] [--perf-ctl FIFO --profile-round N] "
                 "[--warm-up 0|1] [--nats-consumers replicated|memory] [--ramp N] "
                 "[--reply-qos 0|1] [--coordinator-alg ed25519|ml-dsa-65] "
                 "[--members node|transport] [--robot-dir DIR] [--preallocate 0|1]\n");
    return false;
  }
  return true;
}

// The run's shared state: the broker, the fleet's token and members, the robots.
struct Fleet {
  Options opt;
  fs::path dir;
  fs::path robots_dir;  // each robot's latch file and audit log, under <robots_dir>/<member>
  std::vector<pid_t> brokers;
  std::vector<std::string> urls;  // one per broker node; the coordinator uses the first
  std::string url;
  std::vector<std::string> members;
  std::string token;  // bound (cnf) to the coordinator's key, as MQTT requires
  std::array<uint8_t, 32> coordinator_seed{};
  std::optional<mldsa65::KeyPair> coordinator_pq;  // --coordinator-alg ml-dsa-65
  std::optional<jwt::VerificationKey> verify;
  std::vector<std::unique_ptr<Robot>> robots;

  size_t size() const { return static_cast<size_t>(opt.robots_n); }
  // A message of `type` from the coordinator, carrying the fleet token, signed by its key.
  json::Value message(const std::string& type, json::Object payload, const std::string& id) const {
    json::Object m{{"version", "1.0.0"},  {"message_id", id},
                   {"type", type},        {"timestamp_ms", wall_ms()},
                   {"auth_token", token}, {"payload", std::move(payload)}};
    Status signed_ = coordinator_pq ? msgsig::sign_mldsa65(m, coordinator_pq->secret_key,
                                                           coordinator_pq->public_key)
                                    : msgsig::sign_ed25519(m, coordinator_seed);
    if (!signed_.ok()) std::fprintf(stderr, "cannot sign\n");
    return json::Value(std::move(m));
  }
};

// Starts `argv` with stderr to `log`.
pid_t spawn(const std::vector<std::string>& argv, const fs::path& log) {
  pid_t pid = fork();
  if (pid == 0) {
    int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    dup2(fd, 1);
    dup2(fd, 2);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execv(args[0], args.data());
    _exit(127);
  }
  return pid;
}

// Waits until `log` holds `line` (up to `timeout_ms`).
bool wait_for_log(const fs::path& log, const std::string& line, int timeout_ms) {
  for (int waited = 0; waited < timeout_ms; waited += 50) {
    std::ifstream in(log);
    for (std::string l; std::getline(in, l);)
      if (l.find(line) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

// The broker(s), on free loopback ports: one Mosquitto, or a NATS cluster with its MQTT
// listeners. False when one did not come up.
bool start_broker(Fleet& f) {
  if (f.opt.broker == "mosquitto") {
    uint16_t port = free_port();
    std::ofstream(f.dir / "mosquitto.conf")
        << "listener " << port
        << " 127.0.0.1\nset_tcp_nodelay true\nallow_anonymous true\npersistence false\n"
           "max_queued_messages 10000\n";
    f.brokers.push_back(spawn({f.opt.mosquitto, "-c", (f.dir / "mosquitto.conf").string()},
                              f.dir / "mosquitto.log"));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    f.urls.push_back("mqtt://127.0.0.1:" + std::to_string(port));
  } else {
    const int n = f.opt.nats_nodes;
    std::vector<std::array<uint16_t, 3>> ports;  // client, cluster, MQTT
    std::string routes;
    std::set<uint16_t> taken;  // free_port() may give a port twice: each one is bound later
    auto port = [&] {
      uint16_t p = free_port();
      while (!taken.insert(p).second) p = free_port();
      return p;
    };
    for (int i = 0; i < n; ++i) {
      ports.push_back({port(), port(), port()});
      routes +=
          std::string(i ? ", " : "") + "nats-route://127.0.0.1:" + std::to_string(ports[i][1]);
    }
    for (int i = 0; i < n; ++i) {
      std::string name = "n" + std::to_string(i + 1);
      std::ofstream conf(f.dir / (name + ".conf"));
      conf << "server_name: " << name << "\nlisten: 127.0.0.1:" << ports[i][0]
           << "\nmax_connections: 10000\njetstream { store_dir: \""
           << (f.dir / ("js-" + name)).string() << "\" }\nmqtt { listen: 127.0.0.1:" << ports[i][2]
           << (f.opt.nats_consumers == "memory"
                   ? ", consumer_replicas: 1, consumer_memory_storage: true"
                   : "")
           << " }\n";
      if (n > 1)
        conf << "cluster { name: rcan, listen: 127.0.0.1:" << ports[i][1] << ", routes: [" << routes
             << "] }\n";
      conf.close();
      f.brokers.push_back(spawn({f.opt.nats_server, "-c", (f.dir / (name + ".conf")).string()},
                                f.dir / (name + ".log")));
      f.urls.push_back("mqtt://127.0.0.1:" + std::to_string(ports[i][2]));
    }
    for (int i = 0; i < n; ++i) {
      fs::path log = f.dir / ("n" + std::to_string(i + 1) + ".log");
      if (!wait_for_log(log, "Listening for MQTT clients", 20000) ||
          (n > 1 && !wait_for_log(log, "metadata leader", 30000))) {
        std::fprintf(stderr, "fleet_bench: NATS node %d did not come up (see %s)\n", i + 1,
                     log.c_str());
        return false;
      }
    }
  }
  f.url = f.urls.front();
  return true;
}

// One fleet token for all (HS256 issuer shared by the fleet).
void issue_fleet_token(Fleet& f) {
  std::string secret = "fleet-bench-secret-0123456789abcdef0123456789";
  auto signing = jwt::SigningKey::hs256_secret(
      {reinterpret_cast<const uint8_t*>(secret.data()), secret.size()});
  f.verify = *signing->verification_key();
  for (int i = 0; i < f.opt.robots_n; ++i) {
    char b[32];
    std::snprintf(b, sizeof b, "r%04d", i);
    f.members.emplace_back(b);
  }
  // The whole fleet by its id (a list of 1,000 members would not fit the 8 KiB token limit).
  json::Array fleet_claim{"fleet:bench"};
  f.coordinator_seed.fill(0x5a);
  auto pub = ed25519::public_key_from_seed(f.coordinator_seed);
  if (f.opt.coordinator_alg == "ml-dsa-65")
    f.coordinator_pq = *mldsa65::keygen_from_seed(f.coordinator_seed);
  int64_t now_s = wall_ms() / 1000;
  f.token = *jwt::issue(
      json::Object{
          {"iss", "fleet-issuer"},
          {"sub", "bench"},
          {"aud", "rcan://local.rcan/bench/sim/*"},
          {"role", "owner"},
          {"scope", json::Array{"status", "control"}},
          {"fleet", fleet_claim},
          {"cnf", f.coordinator_pq ? *cnf::make(msgsig::Alg::kMlDsa65, f.coordinator_pq->public_key)
                                   : *cnf::make(msgsig::Alg::kEd25519, *pub)},
          {"iat", now_s - 5},
          {"exp", now_s + 3600}},
      *signing);
}

// Robot `i`'s node stack, started, with its MQTT connection; null (after saying why) when a
// part did not start.
std::unique_ptr<Robot> start_robot(const Fleet& f, const config::FleetConfig& fc, int i) {
  auto r = std::make_unique<Robot>();
  r->member = f.members[static_cast<size_t>(i)];
  char dev[16];
  std::snprintf(dev, sizeof dev, "%08x", i + 1);
  std::string ruri = std::string("rcan://local.rcan/bench/sim/") + dev;
  fs::path rd = f.robots_dir / r->member;
  fs::create_directories(rd);
  node::SimRobotConfig sim;
  node::SafetyConfig sc;
  r->core = std::make_unique<node::SafetyCore>(std::make_unique<node::SimRobot>(sim), sc);
  // The latch file, as rcand keeps it (<data_dir>/safety): an ESTOP's ACK waits until it is
  // durable, and a RESUME rewrites it.
  if (Status s = r->core->open((rd / "safety").string()); !s.ok()) {
    std::fprintf(stderr, "safety state: %s\n", s.error().message.c_str());
    return nullptr;
  }
  r->act = std::make_unique<node::SafetyActuation>(*r->core, r->member);
  r->timed = std::make_unique<TimedActuation>(*r->act);
  audit::AuditOptions ao;
  ao.secret = "bench-chain-secret-0123456789";
  ao.robot_ruri = ruri;
  ao.max_segment_bytes = f.opt.segment_bytes;
  if (f.opt.light != 0) {
    ao.preallocate = false;
    ao.background_index = false;
  }
  if (f.opt.preallocate >= 0) ao.preallocate = f.opt.preallocate == 1;
  auto log = audit::AuditLog::open((rd / "audit").string(), std::move(ao));
  if (!log.ok()) {
    std::fprintf(stderr, "audit log: %s\n", log.error().message.c_str());
    return nullptr;
  }
  r->audit = std::move(log).value();
  node::NodeSettings ns;
  ns.ruri = ruri;
  ns.name = r->member;
  node::AuthOptions auth;
  auth.trust.add("fleet-issuer", *f.verify);
  auth.verify.audience = ruri;
  auth.verify.fleet_ids = {dev, ruri, r->member, "fleet:bench"};  // as rcand sets them
  r->svc = std::make_unique<node::NodeServices>(ns, rcan::Clock::system(), std::move(auth),
                                                *r->timed, *r->audit);
  config::FleetConfig mine = fc;
  mine.member_id = r->member;
  r->svc->fleet = std::make_shared<node::FleetMembership>(node::FleetMembership{mine, {}});
  r->node = std::make_unique<node::Node>(*r->svc);
  r->core->start();
  r->node->start();
  node::MqttNodeOptions mo;
  mo.mqtt.enabled = true;
  mo.mqtt.broker = f.urls[static_cast<size_t>(i) % f.urls.size()];
  mo.mqtt.telemetry_hz = 0;
  mo.mqtt.publish_audit = false;
  mo.mqtt.estop_qos = f.opt.estop_qos;
  mo.mqtt.reply_qos = f.opt.reply_qos;
  mo.fleet = mine;
  mo.ruri = *parse_ruri(ruri);
  r->mqtt = std::make_unique<node::MqttNode>(*r->node, *r->svc, mo);
  if (Status s = r->mqtt->start(); !s.ok()) {
    std::fprintf(stderr, "mqtt: %s\n", s.error().message.c_str());
    return nullptr;
  }
  return r;
}

// --members transport: robot `i` as its MQTT connection alone, as a robot's (same client id
// scheme, persistent session, subscriptions and QoS, broker node), answering every fleet message
// with a bare ACK at --reply-qos and noting when the ESTOP arrived. No parse, signature check,
// safety core or audit log: what the brokers and the connections cost on their own.
std::unique_ptr<Robot> start_bare(const Fleet& f, int i) {
  auto r = std::make_unique<Robot>();
  r->member = f.members[static_cast<size_t>(i)];
  const auto topics = mqtt::fleet_topics("rcan", "bench");
  transport::MqttOptions o;
  o.url = f.urls[static_cast<size_t>(i) % f.urls.size()];
  o.client_id = "rcand-bench-" + r->member;
  o.clean_session = false;
  o.max_qos = 1;
  r->bare = std::make_unique<transport::MqttClient>(o);
  r->bare->subscribe(topics.estop(), f.opt.estop_qos);
  r->bare->subscribe(topics.cmd(), 1);
  Robot* self = r.get();
  const std::string reply = topics.member(r->member).reply();
  const std::string estop_topic = topics.estop();
  const int qos = f.opt.reply_qos;
  r->bare->on_message([self, reply, estop_topic, qos](const transport::MqttMessage& m) {
    if (m.payload.empty() || m.retained) return;
    if (m.topic == estop_topic && m.payload.find("\"ESTOP\"") != std::string::npos)
      self->heard_at.store(mono_ms());
    // The message id: the value after "message_id":" (the coordinator writes no spaces).
    const std::string key = "\"message_id\":\"";
    const size_t at = m.payload.find(key);
    if (at == std::string::npos) return;
    const size_t from = at + key.size(), to = m.payload.find('"', from);
    if (to == std::string::npos) return;
    (void)self->bare->publish(
        reply, "{\"type\":\"ACK\",\"reply_to\":\"" + m.payload.substr(from, to - from) + "\"}", qos,
        false);
  });
  if (Status s = r->bare->start(); !s.ok()) {
    std::fprintf(stderr, "mqtt: %s\n", s.error().message.c_str());
    return nullptr;
  }
  return r;
}

// Starts robots [from, to) (8 builder threads); false when one did not start.
bool build_robots(Fleet& f, const config::FleetConfig& fc, int from, int to) {
  std::atomic<int> next{from};
  std::atomic<bool> failed{false};
  auto build = [&] {
    for (int i = next.fetch_add(1); i < to && !failed.load(); i = next.fetch_add(1)) {
      auto r = f.opt.members == "transport" ? start_bare(f, i) : start_robot(f, fc, i);
      if (!r) {
        failed.store(true);
        return;
      }
      f.robots[static_cast<size_t>(i)] = std::move(r);
    }
  };
  std::vector<std::thread> builders;
  for (int t = 0; t < 8; ++t) builders.emplace_back(build);
  for (auto& t : builders) t.join();
  return !failed.load();
}

// Waits up to 2 minutes until robots [0, to) are connected with every subscription granted.
bool wait_subscribed(Fleet& f, int to) {
  auto first = f.robots.begin(), last = f.robots.begin() + to;
  size_t up = 0;
  for (int i = 0; i < 12000; ++i) {
    up = static_cast<size_t>(
        std::count_if(first, last, [](const auto& r) { return r->subscribed(); }));
    if (up == static_cast<size_t>(to)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const size_t connected =
      static_cast<size_t>(std::count_if(first, last, [](const auto& r) { return r->connected(); }));
  std::fprintf(stderr,
               "fleet_bench: after 2 minutes %zu of %d robots are connected to the broker and "
               "%zu have every subscription granted\n",
               connected, to, up);
  return false;
}

// Starts every robot (--ramp N: N at a time, each batch subscribed before the next) and waits
// until all are connected to the broker with every subscription granted.
bool start_robots(Fleet& f) {
  config::FleetConfig fc;
  fc.fleet_id = "bench";
  fc.robots = f.members;
  f.robots.resize(f.size());
  double t_start = mono_ms();
  const int n = f.opt.robots_n, step = f.opt.ramp > 0 ? f.opt.ramp : n;
  for (int from = 0; from < n; from += step) {
    const int to = std::min(n, from + step);
    if (!build_robots(f, fc, from, to) || !wait_subscribed(f, to)) return false;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // subscriptions settle
  const std::string where = f.opt.broker == "mosquitto"
                                ? std::string("one Mosquitto")
                                : "a " + std::to_string(f.opt.nats_nodes) +
                                      "-node NATS cluster (robot i on node i mod " +
                                      std::to_string(f.opt.nats_nodes) + ", coordinator on node 1)";
  std::printf(
      "fleet_bench: %d %s robots (one MQTT connection each, estop subscription QoS %d, ESTOP "
      "published at QoS %d, replies at QoS %d) on %s, up in %.0f ms\n",
      f.opt.robots_n,
      f.opt.members == "transport" ? "transport-only"
      : f.opt.light                ? "light"
                                   : "full",
      f.opt.estop_qos, f.opt.publish_qos(), f.opt.reply_qos, where.c_str(), mono_ms() - t_start);
  return true;
}

// CPU seconds the broker processes have used so far (utime + stime, /proc/PID/stat).
double broker_cpu_now(const std::vector<pid_t>& pids) {
  double total = 0;
  const double hz = static_cast<double>(sysconf(_SC_CLK_TCK));
  for (pid_t pid : pids) {
    std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
    std::string stat;
    std::getline(in, stat);
    size_t close = stat.rfind(')');  // the command name may hold spaces
    if (close == std::string::npos) continue;
    std::istringstream rest(stat.substr(close + 2));
    std::string field;
    unsigned long long utime = 0, stime = 0;
    for (int i = 3; i <= 15 && rest >> field; ++i) {
      if (i == 14) utime = std::strtoull(field.c_str(), nullptr, 10);
      if (i == 15) stime = std::strtoull(field.c_str(), nullptr, 10);
    }
    total += static_cast<double>(utime + stime) / hz;
  }
  return total;
}

// What the idle fleet costs: CPU of this process (all robots) over 2 s with no traffic, and
// which threads woke how often. Returns the CPU seconds used per second.
double report_idle_cost(int robots_n, const std::vector<pid_t>& brokers, double* broker_share) {
  auto wake0 = counts_by_thread();
  double c0 = cpu_now(), b0 = broker_cpu_now(brokers), w0 = mono_ms();
  std::this_thread::sleep_for(std::chrono::seconds(2));
  const double secs = (mono_ms() - w0) / 1000.0;
  double share = (cpu_now() - c0) / secs;
  *broker_share = (broker_cpu_now(brokers) - b0) / secs;
  std::printf(
      "idle: %.1f%% of one core for %d robots (%.0f us of CPU per robot per second); "
      "broker(s) %.1f%%\n",
      share * 100, robots_n, share * 1e6 / robots_n, *broker_share * 100);
  const auto after = counts_by_thread();
  std::printf("idle wake-ups per robot per second:");
  for (auto& [name, c] : after)
    if (c.wakeups - wake0[name].wakeups > 0)
      std::printf(" %s %.2f", name.c_str(),
                  static_cast<double>(c.wakeups - wake0[name].wakeups) / secs / robots_n);
  std::printf("\nidle CPU by thread, us per robot per second:");
  for (auto& [name, c] : after)
    if ((c.cpu_ns - wake0[name].cpu_ns) / 1000 / secs / robots_n >= 0.5)
      std::printf(" %s %.0f", name.c_str(),
                  (c.cpu_ns - wake0[name].cpu_ns) / 1000 / secs / robots_n);
  std::printf("\n");
  return share;
}

// Waits (up to 10 s) until this process and the brokers are back to their idle CPU rates: the
// previous round's broadcast move completes 50 ms after its ACK and each robot then publishes
// its COMPLETED, so a round that began at once would share the CPU with the last one's tail.
void settle(const std::vector<pid_t>& brokers, double idle_share, double broker_idle_share) {
  const double t0 = mono_ms();
  while (mono_ms() - t0 < 10000) {
    double c0 = cpu_now(), b0 = broker_cpu_now(brokers), w0 = mono_ms();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const double secs = (mono_ms() - w0) / 1000.0;
    if ((cpu_now() - c0) / secs <= idle_share * 1.5 + 0.02 &&
        (broker_cpu_now(brokers) - b0) / secs <= broker_idle_share * 1.5 + 0.05)
      break;
  }
}

// What the rounds measured, over all robot×round samples.
struct Results {
  std::vector<double> latch, estop_ack, status_ack, move_ack;
  double estop_cpu_ms = 0;
  double estop_net_cpu_ms = 0;     // less what the idle fleet would have used meanwhile
  double estop_broker_cpu_ms = 0;  // the broker process(es), same window
  double idle_share = 0;           // CPU seconds per second of the idle fleet
  std::map<std::string, ThreadCounts> estop_threads;  // summed over the ESTOP rounds
  double status_net_cpu_ms = 0;  // broadcast `status`, publish to last ACK, less idle
  int failures = 0;
};

// --warm-up 1: one broadcast `status` before round 1.
void warm_up(const Fleet& f, Coordinator& coord) {
  std::string wid = new_uuid_v4();
  double tw = 0;
  int werr = 0;
  auto wacks = coord.round(
      "rcan/fleet/bench/cmd",
      f.message("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "bench"}}, wid),
      wid, 1, false, f.size(), &tw, 10000, &werr);
  std::printf("warm-up: broadcast status answered by %zu/%d robots\n", wacks.size(),
              f.opt.robots_n);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
}

// One round's fleet ESTOP: latency to latched and to the ACK, CPU, page faults, wake-ups and
// the pipeline's stage means, printed as the round's lines.
void estop_round(const Fleet& f, Coordinator& coord, int round, Results& res) {
  const Options& o = f.opt;
  const size_t n = f.size();
  for (auto& r : f.robots) r->clear_latch();
  double t0 = 0;
  int errors = 0;
  std::string id = new_uuid_v4();
  // The bench's own bookkeeping (reading 5,000 threads' counters) stays out of the CPU window.
  auto stages0 = stage_totals(f.robots);
  auto wake0 = counts_by_thread();
  auto perf = [&](const char* cmd) {
    if (o.perf_ctl.empty() || (o.profile_round != -1 && round + 1 != o.profile_round)) return;
    std::ofstream(o.perf_ctl) << cmd << "\n";
  };
  double cpu0 = cpu_now(), broker0 = broker_cpu_now(f.brokers), w0 = mono_ms();
  long faults0 = faults_now();
  perf("enable");
  auto acks = coord.round(
      "rcan/fleet/bench/estop",
      f.message("SAFETY", json::Object{{"safety_event", "ESTOP"}, {"fleet_id", "bench"}}, id), id,
      f.opt.publish_qos(), true, n, &t0, 10000, &errors);
  for (auto& [m, t] : acks) res.estop_ack.push_back(t - t0);
  perf("disable");
  const double round_cpu_ms = (cpu_now() - cpu0) * 1000;
  const double round_net_cpu_ms = round_cpu_ms - res.idle_share * (mono_ms() - w0);
  res.estop_broker_cpu_ms += (broker_cpu_now(f.brokers) - broker0) * 1000;
  const double round_faults = static_cast<double>(faults_now() - faults0) / o.robots_n;
  auto stages1 = stage_totals(f.robots);
  res.estop_cpu_ms += round_cpu_ms;
  res.estop_net_cpu_ms += round_net_cpu_ms;
  for (auto& [name, c] : counts_by_thread()) {
    res.estop_threads[name].wakeups += c.wakeups - wake0[name].wakeups;
    res.estop_threads[name].cpu_ns += c.cpu_ns - wake0[name].cpu_ns;
  }
  std::vector<double> round_latch;
  for (auto& r : f.robots) {
    double t = r->latched_at();
    if (t > 0) round_latch.push_back(t - t0);
  }
  // Round 1 is each robot's first message: the fleet JWT is verified (later rounds find it
  // in the robot's verified-token cache) and every path runs for the first time.
  std::printf(
      "  round %d: ESTOP latched on %zu/%zu  p50 %.2f ms  p99 %.2f ms  max %.2f ms  CPU %.0f "
      "us/robot (%.0f less idle)  %.1f page faults/robot%s\n",
      round + 1, round_latch.size(), n, pct(round_latch, 50), pct(round_latch, 99),
      round_latch.empty() ? 0.0 : *std::max_element(round_latch.begin(), round_latch.end()),
      round_cpu_ms * 1000 / o.robots_n, round_net_cpu_ms * 1000 / o.robots_n, round_faults,
      round == 0 && o.warm_up == 0 ? "  (first message)" : "");
  std::printf("           stage means (wall, us):");
  for (const char* name : kStages) {
    const double dsum = stages1[name].first - stages0[name].first;
    const uint64_t dn = stages1[name].second - stages0[name].second;
    if (dn > 0) std::printf(" %s %.0f", name, dsum / static_cast<double>(dn));
  }
  std::printf("\n");
  res.latch.insert(res.latch.end(), round_latch.begin(), round_latch.end());
  res.failures += errors + static_cast<int>(n - acks.size());
}

// After a round's ESTOP: RESUME, then a broadcast `status` and a short `move`.
// After a round's ESTOP: RESUME, then a broadcast `status` (its CPU measured like the ESTOP's,
// less the idle fleet's, the coordinator included: an MQTT command's cost) and a short `move`.
void resume_and_command(const Fleet& f, Coordinator& coord, Results& res) {
  const size_t n = f.size();
  double t0 = 0;
  int errors = 0;
  std::string rid = new_uuid_v4();
  auto acks = coord.round(
      "rcan/fleet/bench/estop",
      f.message("SAFETY", json::Object{{"safety_event", "RESUME"}, {"fleet_id", "bench"}}, rid),
      rid, f.opt.publish_qos(), true, n, &t0, 10000, &errors);
  res.failures += errors + static_cast<int>(n - acks.size());
  std::string sid = new_uuid_v4();
  const double cpu0 = cpu_now(), w0 = mono_ms();
  acks = coord.round(
      "rcan/fleet/bench/cmd",
      f.message("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "bench"}}, sid),
      sid, 1, false, n, &t0, 10000, &errors);
  res.status_net_cpu_ms += (cpu_now() - cpu0) * 1000 - res.idle_share * (mono_ms() - w0);
  for (auto& [m, t] : acks) res.status_ack.push_back(t - t0);
  res.failures += errors + static_cast<int>(n - acks.size());
  std::string mid = new_uuid_v4();
  acks = coord.round(
      "rcan/fleet/bench/cmd",
      f.message("FLEET_COMMAND",
                json::Object{{"command", "move"},
                             {"fleet_id", "bench"},
                             {"params", json::Object{{"linear", 0.1}, {"duration_ms", 50}}}},
                mid),
      mid, 1, false, n, &t0, 10000, &errors);
  for (auto& [m, t] : acks) res.move_ack.push_back(t - t0);
  res.failures += errors + static_cast<int>(n - acks.size());
}

void print_report(const Fleet& f, const Results& res) {
  const int rounds = f.opt.rounds, robots_n = f.opt.robots_n;
  size_t expected = f.size() * static_cast<size_t>(rounds);
  report("fleet ESTOP publish -> latched", res.latch, expected);
  report("fleet ESTOP publish -> ACK back", res.estop_ack, expected);
  std::printf(
      "fleet ESTOP CPU (all robots, publish to last ACK): %.1f ms per round, %.0f us per robot\n",
      res.estop_cpu_ms / rounds, res.estop_cpu_ms * 1000 / rounds / robots_n);
  // The window is publish → last ACK; on a slow return path most of it is idle time, which
  // the idle fleet costs anyway (report_idle_cost): what the ESTOP itself cost is the rest.
  std::printf(
      "fleet ESTOP CPU less the idle fleet's over the same window: %.1f ms per round, %.0f us per "
      "robot\n",
      res.estop_net_cpu_ms / rounds, res.estop_net_cpu_ms * 1000 / rounds / robots_n);
  // The robots' own: less the coordinator's thread (the operator's side, which receives every
  // ACK) over the same windows.
  const auto coord = res.estop_threads.find("coordinator");
  const double coord_ms = coord == res.estop_threads.end() ? 0 : coord->second.cpu_ns / 1e6;
  std::printf(
      "fleet ESTOP CPU of the robots (less idle, less the coordinator): %.1f ms per round, %.0f "
      "us per robot\n",
      (res.estop_net_cpu_ms - coord_ms) / rounds,
      (res.estop_net_cpu_ms - coord_ms) * 1000 / rounds / robots_n);
  std::printf(
      "broadcast status CPU less the idle fleet's (coordinator included): %.0f us per robot\n",
      res.status_net_cpu_ms * 1000 / rounds / robots_n);
  std::printf(
      "broker CPU (all broker processes, same window): %.1f ms per round, %.0f us per robot\n",
      res.estop_broker_cpu_ms / rounds, res.estop_broker_cpu_ms * 1000 / rounds / robots_n);
  std::printf("fleet ESTOP thread wake-ups per robot:");
  for (auto& [name, c] : res.estop_threads)
    if (c.wakeups > 0)
      std::printf(" %s %.2f", name.c_str(), static_cast<double>(c.wakeups) / rounds / robots_n);
  std::printf("\n");
  // By thread: the robots' threads, and the coordinator's (the operator's side, not a robot's:
  // it receives every ACK).
  std::printf("fleet ESTOP CPU by thread, us per robot:");
  for (auto& [name, c] : res.estop_threads)
    if (c.cpu_ns / 1000 / rounds / robots_n >= 0.5)
      std::printf(" %s %.0f", name.c_str(), c.cpu_ns / 1000 / rounds / robots_n);
  std::printf("\n");
  report("broadcast status -> ACK back", res.status_ack, expected);
  report("broadcast move -> ACK back", res.move_ack, expected);
  std::printf("refused or missing answers: %d\n", res.failures);
}

// Stops the robots and the broker and removes the temporary directory.
void stop_fleet(Fleet& f) {
  std::erase(f.robots, nullptr);  // a start that failed half-way
  for (auto& r : f.robots)
    if (r->bare)
      r->bare->stop();
    else
      r->mqtt->stop();
  for (auto& r : f.robots) {
    if (r->bare) continue;
    r->node->shutdown();
    r->core->stop();
  }
  f.robots.clear();
  for (pid_t b : f.brokers) kill(b, SIGTERM);
  for (pid_t b : f.brokers) waitpid(b, nullptr, 0);
  std::error_code ec;
  fs::remove_all(f.dir, ec);
  if (f.robots_dir != f.dir) fs::remove_all(f.robots_dir, ec);
}

}  // namespace

// 1,000 robots in one process means some 7,000 threads in it, where each robot on its own
// machine has a handful. Linux (6.16 and later) gives a process its own futex hash table, sized
// for the CPUs (16 slots on 2 vCPUs): every mutex or condition-variable hand-off of any robot
// then walks the waiters of hundreds of others under one spinlock (180 us per idle safety tick
// was measured). A table sized for the threads puts each robot back where it would be in a
// process of its own. Older kernels have no such table and refuse the call, which is harmless.
void size_futex_table(int robots) {
  constexpr int kPrFutexHash = 78, kSetSlots = 1;  // <linux/prctl.h> PR_FUTEX_HASH
  unsigned long slots = 16;
  while (slots < static_cast<unsigned long>(robots) * 16) slots *= 2;
  (void)::prctl(kPrFutexHash, kSetSlots, slots, 0UL, 0UL);
}

int main(int argc, char** argv) {
  Fleet f;
  if (!parse_options(argc, argv, f.opt)) return 2;
  size_futex_table(f.opt.robots_n);
  rcan::set_log_level(rcan::LogLevel::kError);
  signal(SIGPIPE, SIG_IGN);
  f.dir = fs::temp_directory_path() / ("fleet_bench_" + std::to_string(getpid()));
  fs::create_directories(f.dir);
  f.robots_dir = f.opt.robot_dir.empty()
                     ? f.dir
                     : fs::path(f.opt.robot_dir) / ("fleet_bench_" + std::to_string(getpid()));
  fs::create_directories(f.robots_dir);
  issue_fleet_token(f);
  if (!start_broker(f) || !start_robots(f)) {
    stop_fleet(f);
    return 1;
  }
  double broker_idle_share = 0;
  const double idle_share = report_idle_cost(f.opt.robots_n, f.brokers, &broker_idle_share);

  Coordinator coord(f.url);
  Results res;
  res.idle_share = idle_share;
  if (f.opt.warm_up != 0) warm_up(f, coord);
  settle(f.brokers, res.idle_share, broker_idle_share);
  for (int round = 0; round < f.opt.rounds; ++round) {
    estop_round(f, coord, round, res);
    resume_and_command(f, coord, res);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    settle(f.brokers, res.idle_share, broker_idle_share);
  }
  print_report(f, res);
  stop_fleet(f);
  return res.failures == 0 ? 0 : 1;
}
