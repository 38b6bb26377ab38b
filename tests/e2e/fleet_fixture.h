// The fleet tests' fixture (fleet_mqtt_test.cpp, fleet_failover_test.cpp): a Mosquitto broker
// and a NATS node or cluster on free loopback ports, real rcand processes as fleet members, the
// real `rcan fleet` CLI and a watching MQTT client (docs/FLEET.md).
#pragma once

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

#include "config/config.h"
#include "rcan/crypto/cnf.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "rcan/mqtt_topics.h"
#include "test_support.h"
#include "transport/mqtt_client.h"

namespace rcan::fleet_test {

namespace fs = std::filesystem;

inline int64_t wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline json::Value parse(const std::string& s) {
  auto v = json::parse(s);
  EXPECT_TRUE(v.ok()) << s.substr(0, 400);
  return v.ok() ? *v : json::Value();
}

inline std::string str_of(const json::Value& v, const char* key) {
  const json::Value* f = v.is_object() ? v.get(key) : nullptr;
  return f != nullptr && f->is_string() ? f->as_string() : std::string();
}
inline std::string payload_str(const json::Value& v, const char* key) {
  const json::Value* p = v.is_object() ? v.get("payload") : nullptr;
  return p != nullptr ? str_of(*p, key) : std::string();
}

// Fields of the CLI's output that may be missing (an old CLI): never dereference null.
inline const json::Value* path_of(const json::Value& v, std::initializer_list<const char*> keys) {
  const json::Value* at = &v;
  for (const char* k : keys) {
    at = at->is_object() ? at->get(k) : nullptr;
    if (at == nullptr) return nullptr;
  }
  return at;
}
inline int64_t int_at(const json::Value& v, std::initializer_list<const char*> keys) {
  const json::Value* f = path_of(v, keys);
  return f != nullptr && f->is_int() ? f->as_int() : -1;
}
inline std::string bool_at(const json::Value& v, std::initializer_list<const char*> keys) {
  const json::Value* f = path_of(v, keys);
  return f != nullptr && f->is_bool() ? (f->as_bool() ? "true" : "false") : "missing";
}
inline std::string str_at(const json::Value& v, std::initializer_list<const char*> keys) {
  const json::Value* f = path_of(v, keys);
  return f != nullptr && f->is_string() ? f->as_string() : std::string();
}

inline uint16_t free_port() {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

inline void write_file(const std::string& path, const std::string& text,
                       fs::perms perms = fs::perms::owner_read | fs::perms::owner_write) {
  std::ofstream(path) << text;
  fs::permissions(path, perms);
}

// A Mosquitto broker on a free loopback port.
class Broker {
 public:
  explicit Broker(const std::string& dir, const std::string& extra_conf = "")
      : dir_(dir), port_(free_port()) {
    write_file(dir_ + "/mosquitto.conf",
               "listener " + std::to_string(port_) +
                   " 127.0.0.1\nallow_anonymous true\npersistence false\n" + extra_conf);
    start();
  }
  ~Broker() { stop(); }
  void start() {
    proc_ = std::make_unique<test::Process>();
    ASSERT_TRUE(proc_->start({"/usr/sbin/mosquitto", "-c", dir_ + "/mosquitto.conf"}));
    ASSERT_TRUE(proc_->wait_for_line("running", 10000)) << proc_->err();
  }
  void stop() {
    if (proc_ && proc_->running()) proc_->stop(SIGTERM, 5000);
  }
  std::string url() const { return "mqtt://127.0.0.1:" + std::to_string(port_); }
  uint16_t port() const { return port_; }

 private:
  std::string dir_;
  uint16_t port_;
  std::unique_ptr<test::Process> proc_;
};

// The test's own MQTT client: records every message it receives.
class Watcher {
 public:
  struct Msg {
    std::string topic;
    json::Value body;
    bool retained = false;
    int qos = 0;  // as delivered: the lower of the publisher's and this subscription's
  };
  // `qos` 0: a subscription NATS serves without JetStream (which a settling cluster may not).
  Watcher(const std::string& url, const std::vector<std::string>& filters, int qos = 1) {
    transport::MqttOptions o;
    o.url = url;
    client_ = std::make_unique<transport::MqttClient>(o);
    for (const auto& f : filters) client_->subscribe(f, qos);
    client_->on_message([this](const transport::MqttMessage& m) {
      auto v = json::parse(m.payload);
      std::lock_guard<std::mutex> lk(mu_);
      msgs_.push_back(Msg{m.topic, v.ok() ? *v : json::Value(), m.retained, m.qos});
      cv_.notify_all();
    });
    EXPECT_TRUE(client_->start().ok());
    for (int i = 0; i < 500 && !client_->connected(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    EXPECT_TRUE(client_->connected());
    // Every SUBACK in; a subscription a clustered broker refused while it settles is asked for
    // again (up to 10 s).
    EXPECT_TRUE(client_->wait_subscribed(5000));
    for (int i = 0; i < 20 && !client_->refused_subscriptions().empty(); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      client_->retry_refused();
      client_->wait_subscribed(5000);
    }
    EXPECT_TRUE(client_->refused_subscriptions().empty());
  }
  // The client's network thread calls on_message: stop it before msgs_ and mu_ go away.
  ~Watcher() { client_.reset(); }
  void publish(const std::string& topic, const json::Value& v, bool retain = false) {
    ASSERT_TRUE(client_->publish(topic, json::dump(v), 1, retain).ok());
  }
  // The first message (from the start of the log) satisfying `pred`, waiting up to `ms`.
  std::optional<Msg> wait(const std::function<bool(const Msg&)>& pred, int ms = 10000) {
    std::unique_lock<std::mutex> lk(mu_);
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    size_t i = 0;
    while (true) {
      for (; i < msgs_.size(); ++i)
        if (pred(msgs_[i])) return msgs_[i];
      if (cv_.wait_until(lk, deadline) == std::cv_status::timeout) {
        for (; i < msgs_.size(); ++i)
          if (pred(msgs_[i])) return msgs_[i];
        return std::nullopt;
      }
    }
  }
  std::vector<Msg> all() {
    std::lock_guard<std::mutex> lk(mu_);
    return {msgs_.begin(), msgs_.end()};
  }

 private:
  std::unique_ptr<transport::MqttClient> client_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Msg> msgs_;
};

// A broker URL for the robot's YAML, or a flow list ("[url, url]") as it is (failover).
inline std::string quoted(const std::string& broker) {
  return !broker.empty() && broker.front() == '[' ? broker : "\"" + broker + "\"";
}

// A fleet member's robot keys in <root>/<name>/keys (made once), and the public half of its
// Ed25519 key in <root>/members/<name>/ed25519.pub: the fleet's members directory, which
// `rcan fleet --members-dir` verifies every reply and status against (docs/FLEET.md). The
// operator has it before the robot first runs.
inline void member_keys(const std::string& root, const std::string& name) {
  const std::string dir = root + "/" + name;
  fs::create_directories(dir);
  fs::permissions(dir, fs::perms::owner_all);
  if (!fs::exists(dir + "/keys")) {
    EXPECT_TRUE(test::generate_robot_keys(dir + "/keys"));
  }
  fs::create_directories(root + "/members/" + name);
  fs::copy_file(dir + "/keys/ed25519.pub", root + "/members/" + name + "/ed25519.pub",
                fs::copy_options::overwrite_existing);
}

// One fleet member: its own data directory, keys (member_keys), chain secret and config.
class Robot {
 public:
  Robot(const std::string& root, const std::string& name, const std::string& device,
        const std::string& broker, const std::string& secret_file,
        const std::string& extra_yaml = "", const std::string& mqtt_extra = "")
      : dir_(root + "/" + name), name_(name) {
    member_keys(root, name);
    EXPECT_TRUE(test::create_audit_secret(dir_ + "/audit.secret"));
    ruri_ = "rcan://local.rcan/rcan/sim-rover/" + device;
    std::string yaml =
        "rcan_version: \"1.2\"\nruri: " + ruri_ + "\nnode: {data_dir: " + dir_ +
        "}\nsecurity:\n  jwt:\n    issuers: [{issuer: fleet-issuer, key_file: " + secret_file +
        ", kind: hs256_secret}]\nmqtt: {enabled: true, broker: " + quoted(broker) +
        ", telemetry_hz: 0, keepalive_s: 5, reconnect: {min_s: 1, max_s: 2}" + mqtt_extra +
        "}\nfleet: {fleet_id: alpha, member_id: " + name +
        ", robots: [robot-a, robot-b, robot-c]}\n" + extra_yaml;
    write_file(dir_ + "/robot.yaml", yaml);
    start();
  }
  ~Robot() {
    if (proc_ && proc_->running()) proc_->stop(SIGTERM, 10000);
  }
  void start() {
    proc_ = std::make_unique<test::Process>();
    ASSERT_TRUE(proc_->start({RCAND_PATH, "--config", dir_ + "/robot.yaml", "--port", "0"}));
    auto line = proc_->wait_for_line("\"event\":\"listening\"", 30000);
    ASSERT_TRUE(line) << proc_->err();
    std::string url = str_of(parse(*line), "url");
    port_ = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
    ASSERT_TRUE(proc_->wait_for_line("mqtt_connected", 10000)) << proc_->err();
  }
  void kill9() { proc_->stop(SIGKILL, 5000); }
  void restart() {
    proc_->stop(SIGTERM, 10000);
    start();
  }
  test::Process& proc() { return *proc_; }
  uint16_t port() const { return port_; }
  const std::string& ruri() const { return ruri_; }
  const std::string& dir() const { return dir_; }
  // The safety core's view over HTTP (with a token valid for this robot).
  json::Value status(const std::string& token) const {
    auto r = test::http(port_, "GET", "/api/status", "", {{"Authorization", "Bearer " + token}});
    return parse(r.body);
  }
  std::string audit(const std::string& token) const {
    return test::http(port_, "GET", "/api/audit?limit=1000", "",
                      {{"Authorization", "Bearer " + token}})
        .body;
  }

 private:
  std::string dir_, name_, ruri_;
  uint16_t port_ = 0;
  std::unique_ptr<test::Process> proc_;
};

// The audit records of `event` in a robot's log (GET /api/audit).
inline std::vector<json::Value> audit_events(const Robot& r, const std::string& token,
                                             const std::string& event) {
  std::vector<json::Value> out;
  json::Value all = parse(r.audit(token));
  const json::Value* entries = all.get("entries");
  if (entries == nullptr || !entries->is_array()) return out;
  for (const auto& e : entries->as_array())
    if (str_of(e, "event") == event) out.push_back(e);
  return out;
}

class FleetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    broker_ = std::make_unique<Broker>(tmp_.path());
    secret_ = tmp_.file("fleet.secret");
    write_file(secret_, "0123456789abcdef0123456789abcdef-fleet-test-secret");
    // The commander's key pair: fleet tokens are bound to it (cnf), and its messages signed.
    key_dir_ = tmp_.file("fleet-keys");
    ASSERT_TRUE(test::generate_robot_keys(key_dir_));
    auto k = keys::load_dir(key_dir_);
    ASSERT_TRUE(k.ok()) << k.error().message;
    keys_ = std::make_shared<keys::RobotKeys>(std::move(k).value());
    fleet_token_ = token("owner", {"robot-a", "robot-b", "robot-c"});
    write_file(tmp_.file("fleet.token"), fleet_token_);
  }
  void TearDown() override {
    robots_.clear();
    broker_.reset();
  }
  // An HS256 token from the fleet issuer, for every sim-rover of the registry; `fleet`
  // lists the members it may command (empty: no fleet claim). `bound`: bound (cnf) to the
  // commander's key, as robots require on MQTT — its Ed25519 key, or its ML-DSA-65 key (`alg`).
  std::string token(const std::string& role, std::vector<std::string> fleet,
                    const std::string& sub = "coordinator",
                    const std::string& aud = "rcan://local.rcan/rcan/sim-rover/*",
                    bool bound = true, msgsig::Alg alg = msgsig::Alg::kEd25519) {
    auto key = jwt::SigningKey::from_file(secret_, true);
    EXPECT_TRUE(key.ok());
    int64_t now = wall_ms() / 1000;
    json::Object claims{{"iss", "fleet-issuer"},
                        {"sub", sub},
                        {"aud", aud},
                        {"role", role},
                        {"scope", json::Array{"status", "control"}},
                        {"iat", now - 5},
                        {"exp", now + 3600}};
    if (!fleet.empty()) {
      json::Array f;
      for (auto& m : fleet) f.emplace_back(m);
      claims.set("fleet", f);
    }
    if (bound)
      claims.set("cnf", *cnf::make(alg, alg == msgsig::Alg::kEd25519 ? keys_->pub.ed25519_pk
                                                                     : keys_->pub.mldsa65_pk));
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }
  Robot& add_robot(const std::string& name, const std::string& device,
                   const std::string& extra_yaml = "", const std::string& mqtt_extra = "") {
    robots_[name] = std::make_unique<Robot>(tmp_.path(), name, device, broker_->url(), secret_,
                                            extra_yaml, mqtt_extra);
    return *robots_[name];
  }
  // The swarm block of the swarm tests, with the members' shared secret (written 0600 once).
  std::string swarm_yaml() {
    const std::string secret = tmp_.file("swarm.secret");
    if (!fs::exists(secret))
      write_file(secret, "swarm-test-secret-0123456789abcdef0123456789abcdef");
    return "swarm: {swarm_id: s42, members: [robot-a, robot-b, robot-c], leader: robot-a, "
           "formation: follow-leader, join_policy: approval, heartbeat_ms: 100, "
           // 15 missed heartbeats: a loaded test machine (sanitizers, e2e tests in parallel)
           // must not make the leader look dead before the test has watched it lead.
           "leader_timeout_ms: 1500, secret_file: " +
           secret + "}\n";
  }
  void three_robots(const std::string& extra_yaml = "") {
    add_robot("robot-a", "0000000a", extra_yaml);
    add_robot("robot-b", "0000000b", extra_yaml);
    add_robot("robot-c", "0000000c", extra_yaml);
  }
  test::RunResult fleet(std::vector<std::string> args) {
    args.insert(args.begin(), "fleet");
    args.insert(args.end(), {"--broker", broker_->url(), "--token", tmp_.file("fleet.token"),
                             "--key-dir", key_dir_, "--members-dir", members_dir()});
    return test::run_cli(args);
  }
  // The fleet's members directory: each robot's public key, written by Robot.
  std::string members_dir() const { return tmp_.path() + "/members"; }
  // A message as `rcan fleet` sends it: signed by the commander's key unless `sign` is false.
  json::Value command_msg(const std::string& type, json::Object payload, const std::string& tok,
                          const std::string& id = new_uuid_v4(), bool sign = true) {
    json::Object m{{"version", "1.0.0"}, {"message_id", id},
                   {"type", type},       {"timestamp_ms", wall_ms()},
                   {"auth_token", tok},  {"payload", std::move(payload)}};
    if (sign) {
      EXPECT_TRUE(msgsig::sign_ed25519(m, keys_->ed25519_seed.span()).ok());
    }
    return json::Value(std::move(m));
  }
  // `m` signed by the commander's key (the key fleet tokens are bound to).
  json::Value signed_msg(json::Object m) {
    EXPECT_TRUE(msgsig::sign_ed25519(m, keys_->ed25519_seed.span()).ok());
    return json::Value(std::move(m));
  }
  static bool moving(const json::Value& status) {
    // /api/status with a token: the safety core's state under "safety".
    std::string s = json::dump(status);
    return s.find("\"state\":\"moving\"") != std::string::npos;
  }
  // The robot comes to rest (it decelerates over a few control ticks after a STOP); a 30 s
  // drive that was not stopped would still be running when this gives up.
  bool comes_to_rest(const Robot& r) {
    for (int i = 0; i < 100; ++i) {
      if (!moving(r.status(fleet_token_))) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }

  test::TempDir tmp_;
  std::unique_ptr<Broker> broker_;
  std::string secret_;
  std::string fleet_token_;
  std::string key_dir_;
  std::shared_ptr<keys::RobotKeys> keys_;
  std::map<std::string, std::unique_ptr<Robot>> robots_;
};

// ---- NATS (docs/FLEET.md §Running on NATS)

// nats-server (scripts/install-deps.sh), or empty when it is not installed.
inline std::string nats_server_path() {
  for (const char* p :
       {"/usr/sbin/nats-server", "/usr/bin/nats-server", "/usr/local/bin/nats-server"})
    if (::access(p, X_OK) == 0) return p;
  return {};
}

// NATS with its MQTT listener (which needs JetStream and a server name) on loopback: one node,
// or a cluster of `nodes` with routes between them; the MQTT streams are replicated on up to
// three nodes. NATS does no QoS 2: it grants QoS 1 to a QoS 2 subscription and drops the
// connection of a client that publishes at QoS 2.
class Nats {
 public:
  Nats(const std::string& dir, int nodes) {
    std::string routes;
    std::set<uint16_t> taken;  // free_port() may give a port twice: each one is bound later
    auto port = [&] {
      uint16_t p = free_port();
      while (!taken.insert(p).second) p = free_port();
      return p;
    };
    for (int i = 0; i < nodes; ++i) {
      ports_.push_back({port(), port(), port()});  // client, cluster, MQTT
      routes +=
          std::string(i ? ", " : "") + "nats-route://127.0.0.1:" + std::to_string(ports_.back()[1]);
    }
    for (int i = 0; i < nodes; ++i) {
      std::string name = "n" + std::to_string(i + 1);
      std::string conf = "server_name: " + name +
                         "\nlisten: 127.0.0.1:" + std::to_string(ports_[i][0]) +
                         "\njetstream { store_dir: \"" + dir + "/js-" + name +
                         "\" }\nmqtt { listen: 127.0.0.1:" + std::to_string(ports_[i][2]) + " }\n";
      if (nodes > 1)
        conf += "cluster { name: rcan, listen: 127.0.0.1:" + std::to_string(ports_[i][1]) +
                ", routes: [" + routes + "] }\n";
      write_file(dir + "/" + name + ".conf", conf);
      procs_.push_back(std::make_unique<test::Process>());
      EXPECT_TRUE(procs_.back()->start({nats_server_path(), "-c", dir + "/" + name + ".conf"}));
    }
    for (auto& p : procs_)
      EXPECT_TRUE(p->wait_for_line("Listening for MQTT clients", 15000)) << p->err();
    if (nodes > 1) wait_ready();
  }
  ~Nats() {
    for (auto& p : procs_)
      if (p->running()) p->stop(SIGTERM, 10000);
  }
  std::string url(int node) const {
    return "mqtt://127.0.0.1:" + std::to_string(ports_[static_cast<size_t>(node)][2]);
  }
  uint16_t mqtt_port(int node) const { return ports_[static_cast<size_t>(node)][2]; }
  void kill(int node) { procs_[static_cast<size_t>(node)]->stop(SIGKILL, 5000); }

 private:
  // MQTT sessions live in JetStream. The cluster is ready when it has a metadata leader (the
  // leader logs it; a follower may learn of it without a line) and every node opens a
  // persistent session, which it can only do through that leader (up to 40 s in all).
  void wait_ready() {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(40);
    auto leader_logged = [&] {
      for (auto& p : procs_)
        if (p->err().find("metadata leader") != std::string::npos) return true;
      return false;
    };
    while (!leader_logged() && std::chrono::steady_clock::now() < end)
      for (auto& p : procs_) p->drain(100);
    ASSERT_TRUE(leader_logged()) << procs_[0]->err();
    for (size_t i = 0; i < procs_.size(); ++i) {
      bool opened = false;
      while (!opened && std::chrono::steady_clock::now() < end) {
        transport::MqttOptions o;
        o.url = url(static_cast<int>(i));
        o.client_id = "ready-probe-" + std::to_string(i);
        o.clean_session = false;
        transport::MqttClient c(o);
        if (!c.start().ok()) break;
        for (int t = 0; t < 100 && !c.connected(); ++t)
          std::this_thread::sleep_for(std::chrono::milliseconds(50));
        opened = c.connected();
      }
      EXPECT_TRUE(opened) << "node " << i + 1 << " opens no MQTT session\n" << procs_[i]->err();
    }
  }

 public:
  test::Process& proc(int node) { return *procs_[static_cast<size_t>(node)]; }

 private:
  std::vector<std::array<uint16_t, 3>> ports_;
  std::vector<std::unique_ptr<test::Process>> procs_;
};

class NatsFleetTest : public FleetTest {
 protected:
  void SetUp() override {
    if (nats_server_path().empty())
      GTEST_SKIP() << "nats-server is not installed (scripts/install-deps.sh installs it)";
    FleetTest::SetUp();
  }
  Robot& robot_on(const std::string& url, const std::string& name, const std::string& device,
                  const std::string& mqtt_extra = "") {
    robots_[name] =
        std::make_unique<Robot>(tmp_.path(), name, device, url, secret_, "", mqtt_extra);
    return *robots_[name];
  }
  test::RunResult fleet_via(const std::string& url, std::vector<std::string> args) {
    args.insert(args.begin(), "fleet");
    args.insert(args.end(), {"--broker", url, "--token", tmp_.file("fleet.token"), "--key-dir",
                             key_dir_, "--members-dir", members_dir()});
    return test::run_cli(args);
  }
  bool latched(const std::string& name) {
    return json::dump(robots_[name]->status(fleet_token_)).find("\"estop_active\":true") !=
           std::string::npos;
  }
};

}  // namespace rcan::fleet_test
