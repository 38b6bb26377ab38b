// Fail closed under real faults (docs/AUDIT.md §Faults, docs/NODE.md §Faults): a real rcand whose
// audit store is a small tmpfs that the test fills up and empties again, a real rcand whose wall
// clock libfaketime steps forwards and back while it runs (the monotonic clock untouched), and a
// real Mosquitto broker stopped under a robot. After each, the audit chain is verified with
// `rcan audit verify`.
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "node/admission/replay.h"
#include "rcan/crypto/cnf.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "test_support.h"
#include "transport/mqtt_client.h"

namespace rcan {
namespace {

namespace fs = std::filesystem;
using test::HttpReply;

int64_t real_wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

json::Value parse(const std::string& s) {
  auto v = json::parse(s, {.max_depth = 128, .max_bytes = 64u << 20});
  EXPECT_TRUE(v.ok()) << s.substr(0, 300);
  return v.ok() ? *v : json::Value();
}

std::string error_code(const HttpReply& r) {
  json::Value v = parse(r.body);
  const json::Value* p = v.get("payload");
  const json::Value* c = p ? p->get("error_code") : nullptr;
  return c && c->is_string() ? c->as_string() : "";
}

// Polls `pred` every 20 ms until it holds or `timeout_ms` passes (a bound, never a measurement).
bool eventually(const std::function<bool()>& pred, int timeout_ms = 10000) {
  auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return pred();
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::trunc);
  out << text;
}

// A configured rcand: robot keys and chain secret made with the CLI, an Ed25519 test issuer,
// `security_yaml` added inside the security block, `extra_yaml` at the top level, and extra
// environment variables for the process (libfaketime).
class Node {
 public:
  static constexpr const char* kRuri = "rcan://local.rcan/acme/rover/0a1b2c3d";

  Node(const std::string& root, std::string security_yaml, std::string extra_yaml,
       std::vector<std::string> env = {})
      : root_(root), env_(std::move(env)) {
    // rcand links jemalloc, which cannot start under libfaketime (CMakeLists.txt): a node
    // with a preloaded library runs the same daemon built on the C library's malloc.
    for (const auto& e : env_)
      if (e.rfind("LD_PRELOAD=", 0) == 0) binary_ = RCAND_SYSMALLOC_PATH;
    data_ = root_ + "/data";
    fs::create_directories(data_);
    fs::permissions(data_, fs::perms::owner_all);
    EXPECT_EQ(test::run_cli({"keys", "generate", "--dir", data_ + "/keys"}).exit_code, 0);
    EXPECT_EQ(test::run_cli({"audit", "new-secret", "--out", data_ + "/audit.secret"}).exit_code,
              0);
    seed_file_ = root_ + "/issuer.seed";
    uint8_t seed[32];
    EXPECT_TRUE(random_bytes(seed, sizeof seed));
    {
      std::ofstream out(seed_file_, std::ios::binary);
      out.write(reinterpret_cast<const char*>(seed), sizeof seed);
    }
    fs::permissions(seed_file_, fs::perms::owner_read | fs::perms::owner_write);
    auto pk = ed25519::public_key_from_seed(std::span<const uint8_t>(seed, sizeof seed));
    EXPECT_TRUE(pk.ok());
    auto pem = ed25519::public_key_to_pem(*pk);
    EXPECT_TRUE(pem.ok());
    write_text(root_ + "/issuer.pub.pem", *pem);
    write_text(
        root_ + "/robot.rcan.yaml",
        std::string("rcan_version: \"1.2\"\nruri: ") + kRuri +
            "\nrobot:\n  name: fault-rover\n  manufacturer: acme\n  model: rover\n  type: mobile\n"
            "safety:\n  local_safety_wins: true\n"
            "driver:\n  type: sim\n  sim:\n    tick_hz: 200\n"
            "security:\n  jwt:\n    issuers:\n      - issuer: test.local\n        key_file: " +
            root_ + "/issuer.pub.pem\n" + security_yaml + extra_yaml);
  }
  ~Node() { stop(); }

  bool start() {
    proc_ = std::make_unique<test::Process>();
    if (!proc_->start(
            {binary_, "--config", root_ + "/robot.rcan.yaml", "--port", "0", "--data-dir", data_},
            env_)) {
      ADD_FAILURE() << "cannot start rcand";
      return false;
    }
    auto line = proc_->wait_for_line("\"event\":\"listening\"", 60000);
    if (!line) {
      ADD_FAILURE() << "rcand did not start:\n" << proc_->err();
      return false;
    }
    std::string url = parse(*line).get("url")->as_string();
    port_ = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
    return true;
  }
  int stop() {
    if (!proc_ || !proc_->running()) return 0;
    return proc_->stop(SIGTERM, 15000);
  }
  test::Process& proc() { return *proc_; }
  uint16_t port() const { return port_; }
  const std::string& data_dir() const { return data_; }
  std::string secret_file() const { return data_ + "/audit.secret"; }

  // A token from the test issuer; iat/exp are relative to `now_s` (the node's clock by default
  // the real one), valid from `before_s` before it to `after_s` after it.
  // `cnf`: the claim binding the token to a key (rcan/crypto/cnf.h), as MQTT requires.
  std::string token(const std::string& role, std::vector<std::string> scopes,
                    const std::string& sub, int64_t before_s = 5, int64_t after_s = 3600,
                    std::optional<json::Value> cnf = std::nullopt) const {
    auto key = jwt::SigningKey::from_file(seed_file_);
    EXPECT_TRUE(key.ok());
    int64_t now = real_wall_ms() / 1000;
    json::Array sc;
    for (auto& s : scopes) sc.emplace_back(s);
    json::Object claims{{"iss", "test.local"}, {"sub", sub},  {"aud", kRuri},
                        {"role", role},        {"scope", sc}, {"iat", now - before_s},
                        {"exp", now + after_s}};
    if (cnf) claims.set("cnf", std::move(*cnf));
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }

  HttpReply call(const std::string& method, const std::string& path, const std::string& body,
                 const std::string& tok) const {
    std::vector<std::pair<std::string, std::string>> h;
    if (!tok.empty()) h.emplace_back("Authorization", "Bearer " + tok);
    return test::http(port_, method, path, body, h);
  }
  HttpReply get(const std::string& path, const std::string& tok = "") const {
    return call("GET", path, "", tok);
  }
  HttpReply post(const std::string& path, const std::string& body, const std::string& tok) const {
    return call("POST", path, body, tok);
  }
  json::Value status(const std::string& tok) const {
    return parse(get("/rcan/v1/status", tok).body);
  }

  // One metric line `name value` on /metrics (-1 when absent).
  double metric(const std::string& name) const {
    return test::metric_value(get("/metrics").body, name);
  }

 private:
  std::string root_, data_, seed_file_;
  std::vector<std::string> env_;
  std::string binary_ = RCAND_PATH;
  std::unique_ptr<test::Process> proc_;
  uint16_t port_ = 0;
};

std::string command(const std::string& action, json::Object params = {}, std::string id = "",
                    int64_t ts = 0) {
  json::Object payload{{"action", action}};
  for (auto& m : params) payload.set(m.first, m.second);
  json::Object m{{"version", "1.0.0"},
                 {"message_id", id.empty() ? new_uuid_v4() : id},
                 {"type", "COMMAND"},
                 {"timestamp_ms", ts ? ts : real_wall_ms()},
                 {"payload", payload}};
  return json::dump(json::Value(m));
}

// `rcan audit verify --data-dir` on a stopped node's audit directory, and its records.
void expect_chain_verifies(const std::string& audit_dir, const std::string& secret_file) {
  auto v =
      test::run_cli({"audit", "verify", "--data-dir", audit_dir, "--secret-file", secret_file});
  EXPECT_EQ(v.exit_code, 0) << v.out << v.err;
  EXPECT_NE(v.out.find("ok:"), std::string::npos) << v.out;
}

std::vector<json::Value> exported(const std::string& audit_dir) {
  auto e = test::run_cli({"audit", "export", "--data-dir", audit_dir});
  EXPECT_EQ(e.exit_code, 0) << e.err;
  std::vector<json::Value> out;
  size_t pos = 0;
  while (pos < e.out.size()) {
    size_t nl = e.out.find('\n', pos);
    if (nl == std::string::npos) nl = e.out.size();
    if (nl > pos) out.push_back(parse(e.out.substr(pos, nl - pos)));
    pos = nl + 1;
  }
  return out;
}

// The simulated robot's base (odometry, target speed) from a detailed status.
double base_number(const json::Value& status, const char* key) {
  const json::Value* r = status.get("robot");
  const json::Value* rr = r ? r->get("robot") : nullptr;
  const json::Value* b = rr ? rr->get("base") : nullptr;
  const json::Value* f = b ? b->get(key) : nullptr;
  EXPECT_TRUE(f && f->is_number()) << json::dump(status).substr(0, 400);
  return f && f->is_number() ? f->to_double() : -1;
}

std::string str(const json::Value& v, const char* key) {
  const json::Value* f = v.is_object() ? v.get(key) : nullptr;
  return f && f->is_string() ? f->as_string() : "";
}

// ------------------------------------------------------------------------------------------
// Disk full: the audit directory on a small tmpfs.

class Tmpfs {
 public:
  // Mounts a tmpfs of `bytes` at `dir`; ok() false (with why()) when this machine cannot.
  Tmpfs(const std::string& dir, uint64_t bytes) : dir_(dir) {
    fs::create_directories(dir_);
    std::string opts = "size=" + std::to_string(bytes) + ",mode=0700";
    if (::mount("tmpfs", dir_.c_str(), "tmpfs", MS_NOSUID | MS_NODEV, opts.c_str()) != 0) {
      why_ = std::string("mount -t tmpfs: ") + std::strerror(errno);
      return;
    }
    mounted_ = true;
  }
  ~Tmpfs() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
  }
  bool ok() const { return mounted_; }
  const std::string& why() const { return why_; }

  // Writes a file until the file system says ENOSPC; returns the bytes written.
  uint64_t fill(const std::string& name) {
    filler_ = dir_ + "/" + name;
    int fd = ::open(filler_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    EXPECT_GE(fd, 0) << std::strerror(errno);
    if (fd < 0) return 0;
    std::string chunk(64 * 1024, 'x');
    uint64_t total = 0;
    size_t n = chunk.size();
    for (;;) {
      ssize_t w = ::write(fd, chunk.data(), n);
      if (w > 0) {
        total += static_cast<uint64_t>(w);
        continue;
      }
      if (w < 0 && errno == EINTR) continue;
      if (w < 0 && errno == ENOSPC && n > 1) {  // top up the last pages
        n /= 2;
        continue;
      }
      EXPECT_EQ(errno, ENOSPC) << std::strerror(errno);
      break;
    }
    ::close(fd);
    return total;
  }
  void unfill() { fs::remove(filler_); }

 private:
  std::string dir_, filler_, why_;
  bool mounted_ = false;
};

// The whole story against one real node whose audit directory is `audit_dir`: `fill` makes its
// store refuse writes, `unfill` gives the space back.
// `failing_op` is what the recovery record must name as the operation that failed.
void audit_store_outage(const std::string& root, const std::string& audit_dir,
                        const std::function<void()>& fill, const std::function<void()>& unfill,
                        const std::string& failing_op) {
  // 64 KiB segments: a preallocated segment and its spare take 128 KiB.
  Node node(root + "/node", "  audit:\n    dir: " + audit_dir + "\n    max_segment_bytes: 65536\n",
            "");
  ASSERT_TRUE(node.start());
  const std::string owner = node.token("owner", {"status", "control", "config"}, "owner-1");

  // Healthy: a drive is accepted and recorded.
  HttpReply first = node.post("/rcan/v1/command",
                              command("move", {{"linear", 0.1}, {"duration_ms", 100}}), owner);
  ASSERT_EQ(first.status, 200) << first.body;
  EXPECT_TRUE(node.status(owner).get("audit_available")->as_bool());

  // The disk fills up. The log keeps recording into the space it preallocated; once that is
  // used up, the next record cannot be written and the command that needed it is refused.
  fill();
  std::vector<std::string> acked;
  std::string refused_id;
  for (int i = 0; i < 3000 && refused_id.empty(); ++i) {
    std::string id = new_uuid_v4();
    HttpReply r = node.post("/rcan/v1/command", command("status", {}, id), owner);
    if (r.status == 200) {
      acked.push_back(id);
      continue;
    }
    ASSERT_EQ(r.status, 503) << r.body;
    ASSERT_EQ(error_code(r), "AUDIT_UNAVAILABLE") << r.body;
    json::Value body = parse(r.body);
    EXPECT_EQ(str(body, "type"), "ERROR");  // the profile's error body
    EXPECT_EQ(str(body, "reply_to"), id);
    refused_id = id;
  }
  ASSERT_FALSE(refused_id.empty()) << "the full disk never stopped the audit log";
  EXPECT_GT(acked.size(), 10u);  // it really recorded into its preallocated space first

  // The condition shows: status, /healthz, metrics. (The first drive has come to rest.)
  auto at_rest = [&] {
    json::Value s = node.status(owner);
    const json::Value* r = s.get("robot");
    return r && str(*r, "state") == "idle";
  };
  ASSERT_TRUE(eventually(at_rest));
  json::Value st = node.status(owner);
  EXPECT_FALSE(st.get("audit_available")->as_bool());
  EXPECT_FALSE(node.status("").get("audit_available")->as_bool());  // in the public summary too
  EXPECT_EQ(node.get("/healthz").status, 503);
  EXPECT_EQ(node.metric("rcan_audit_available"), 0.0);
  EXPECT_GE(node.metric("rcan_audit_failures_total"), 1.0);
  const double odometry = base_number(st, "odometry_m");

  // Nothing is dispatched without its record: a drive is refused and the robot does not move.
  std::string drive_id = new_uuid_v4();
  HttpReply drive =
      node.post("/rcan/v1/command",
                command("move", {{"linear", 0.2}, {"duration_ms", 300}}, drive_id), owner);
  EXPECT_EQ(drive.status, 503) << drive.body;
  EXPECT_EQ(error_code(drive), "AUDIT_UNAVAILABLE");
  std::this_thread::sleep_for(
      std::chrono::milliseconds(400));  // longer than the drive would have run
  json::Value still = node.status(owner);
  EXPECT_EQ(base_number(still, "odometry_m"), odometry);
  EXPECT_EQ(base_number(still, "target_linear_mps"), 0.0);

  // ESTOP still works: latched and answered (the answer says the record could not be written).
  HttpReply estop = node.post("/api/stop", "", owner);
  ASSERT_EQ(estop.status, 200) << estop.body;
  json::Value ev = parse(estop.body);
  EXPECT_TRUE(ev.get("payload")->get("estop_active")->as_bool());
  EXPECT_EQ(str(*ev.get("payload"), "audit"), "unavailable");
  EXPECT_TRUE(node.status(owner).get("estop_active")->as_bool());
  // RESUME re-enables motion: not without its record. The latch holds.
  auto resume_msg = [] {
    return json::dump(
        json::Value(json::Object{{"version", "1.0.0"},
                                 {"message_id", new_uuid_v4()},
                                 {"type", "SAFETY"},
                                 {"timestamp_ms", real_wall_ms()},
                                 {"payload", json::Object{{"safety_event", "RESUME"}}}}));
  };
  HttpReply early = node.post("/rcan/v1/command", resume_msg(), owner);
  EXPECT_EQ(early.status, 503) << early.body;
  EXPECT_EQ(error_code(early), "AUDIT_UNAVAILABLE");
  EXPECT_TRUE(node.status(owner).get("estop_active")->as_bool());

  // Space returns: the node recovers by itself, without a restart.
  unfill();
  ASSERT_TRUE(
      eventually([&] { return node.status(owner).get("audit_available")->as_bool(); }, 15000))
      << "the audit log did not recover";
  EXPECT_EQ(node.get("/healthz").status, 200);
  EXPECT_EQ(node.metric("rcan_audit_available"), 1.0);
  EXPECT_GE(node.metric("rcan_audit_recoveries_total"), 1.0);
  HttpReply resume = node.post("/rcan/v1/command", resume_msg(), owner);
  ASSERT_EQ(resume.status, 200) << resume.body;
  std::string after_id = new_uuid_v4();
  HttpReply after =
      node.post("/rcan/v1/command",
                command("move", {{"linear", 0.2}, {"duration_ms", 200}}, after_id), owner);
  ASSERT_EQ(after.status, 200) << after.body;
  EXPECT_TRUE(eventually([&] { return base_number(node.status(owner), "odometry_m") > odometry; }));

  // The chain: every acknowledged record is there, the refused ones are not, the recovery is
  // recorded, and `rcan audit verify` passes on the directory.
  ASSERT_EQ(node.stop(), 0);
  std::set<std::string> ids;
  int recoveries = 0, late_estops = 0;
  for (const auto& r : exported(audit_dir)) {
    ids.insert(str(r, "message_id"));
    const json::Value* d = r.get("detail");
    if (str(r, "event") == "AUDIT_RECOVERY" && str(r, "outcome") == "repaired") {
      ++recoveries;
      EXPECT_NE(str(*d, "failure").find(failing_op), std::string::npos) << str(*d, "failure");
    }
    const json::Value* late = d ? d->get("recorded_after_audit_outage") : nullptr;
    if (str(r, "event") == "ESTOP" && late && late->is_bool() && late->as_bool()) ++late_estops;
  }
  for (const auto& id : acked) EXPECT_TRUE(ids.count(id)) << "acknowledged " << id << " is missing";
  EXPECT_FALSE(ids.count(refused_id));
  EXPECT_FALSE(ids.count(drive_id));
  EXPECT_TRUE(ids.count(after_id));
  EXPECT_EQ(recoveries, 1);
  EXPECT_EQ(late_estops, 1);  // the ESTOP acted at once; its record followed the recovery
  expect_chain_verifies(audit_dir, node.secret_file());
}

TEST(DiskFull, CommandsAreRefusedEstopWorksAndTheNodeRecoversWhenSpaceReturns) {
  test::TempDir tmp;
  const std::string mnt = tmp.file("auditfs");
  Tmpfs disk(mnt, 1u << 20);
  if (!disk.ok()) GTEST_SKIP() << "cannot mount a tmpfs for the audit store (" << disk.why() << ")";
  // A full file system: the audit log's write() itself fails with ENOSPC.
  audit_store_outage(
      tmp.path(), mnt + "/audit", [&] { ASSERT_GT(disk.fill("filler"), 0u); },
      [&] { disk.unfill(); }, "pwrite");
}

// An ext2 file system on a loop device whose backing file is sparse and lives on a small tmpfs.
// Filling that tmpfs makes the loop device fail writes at writeback: write() into the page
// cache succeeds, the fdatasync that should make it durable fails (the "fsyncgate" case).
class LoopFs {
 public:
  LoopFs(const std::string& outer, const std::string& mnt) : outer_(outer, 8u << 20), mnt_(mnt) {
    if (!outer_.ok()) {
      why_ = outer_.why();
      return;
    }
    const std::string img = outer + "/disk.img";
    { std::ofstream(img).close(); }
    fs::resize_file(img, 64u << 20);  // sparse: backed by tmpfs pages only where written
    auto mk = test::run({"/usr/sbin/mkfs.ext2", "-q", "-F", img});
    if (mk.exit_code != 0) {
      why_ = "mkfs.ext2: " + mk.err;
      return;
    }
    auto lo = test::run({"/usr/sbin/losetup", "-f", "--show", img});
    if (lo.exit_code != 0) {
      why_ = "losetup: " + lo.err;
      return;
    }
    dev_ = lo.out.substr(0, lo.out.find('\n'));
    fs::create_directories(mnt_);
    if (::mount(dev_.c_str(), mnt_.c_str(), "ext2", MS_NOSUID | MS_NODEV, "errors=continue") != 0) {
      why_ = std::string("mount ext2 on ") + dev_ + ": " + std::strerror(errno);
      return;
    }
    mounted_ = true;
  }
  ~LoopFs() {
    if (mounted_) ::umount2(mnt_.c_str(), MNT_DETACH);
    if (!dev_.empty()) test::run({"/usr/sbin/losetup", "-d", dev_});
  }
  bool ok() const { return mounted_; }
  const std::string& why() const { return why_; }
  Tmpfs& backing() { return outer_; }

 private:
  Tmpfs outer_;
  std::string mnt_, dev_, why_;
  bool mounted_ = false;
};

TEST(DiskFull, WritebackErrorsUnderTheFileSystemFailClosedAndRecoverToo) {
  test::TempDir tmp;
  LoopFs disk(tmp.file("backing"), tmp.file("auditfs"));
  if (!disk.ok())
    GTEST_SKIP() << "cannot set up an ext2 loop device over a tmpfs (" << disk.why() << ")";
  audit_store_outage(
      tmp.path(), tmp.file("auditfs") + "/audit",
      [&] { ASSERT_GT(disk.backing().fill("filler"), 0u); }, [&] { disk.backing().unfill(); },
      "fdatasync");
}

// ------------------------------------------------------------------------------------------
// Clock steps. First the replay guard alone (its clock is a parameter), then a real rcand under
// libfaketime: its wall clock is stepped back an hour and forward two while it runs; its
// monotonic clock is not faked.

TEST(ClockSteps, ReplayMemoryEvictedBeforeAStepBackDoesNotRefuseTheNewTime) {
  node::ReplayOptions o;
  o.capacity = 3;
  o.principal_share = 3;  // one principal, and it may hold the whole memory
  node::ReplayGuard g(o);
  const std::string p = "issuer\x1fsub";
  const int64_t t = 1'750'000'000'000;
  for (int i = 0; i < 4; ++i)
    ASSERT_TRUE(g.check(p, "m" + std::to_string(i), t + i, false, t + 10).ok());
  EXPECT_EQ(g.evictions(), 1u);
  // The evicted id cannot come back while it could be fresh.
  auto again = g.check(p, "m0", t, false, t + 20);
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, ErrorCode::kMessageStale);
  // The clock steps back an hour: messages stamped with the new time are fresh…
  const int64_t back = t - 3'600'000;
  for (int i = 0; i < 6; ++i)
    EXPECT_TRUE(g.check(p, "b" + std::to_string(i), back + 100 + i, false, back + 200).ok()) << i;
  // …ids from before the step are still remembered (they could become fresh once the clock
  // has caught up), and a replay of a new one is refused.
  auto replay = g.check(p, "b5", back + 105, false, back + 300);
  ASSERT_FALSE(replay.ok());
  EXPECT_EQ(replay.error().code, ErrorCode::kReplayDetected);
  // Evictions after the step took the oldest timestamps (the new ones): the pre-step ids that
  // remain still refuse their replays once the clock is back where it was.
  auto late = g.check(p, "m3", t + 3, false, t + 1000);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.error().code, ErrorCode::kReplayDetected);
  // Forward step: everything remembered is out of the window; the new time is fresh.
  const int64_t fwd = t + 7'200'000;
  EXPECT_TRUE(g.check(p, "f0", fwd, false, fwd + 5).ok());
  auto old = g.check(p, "m9", t + 5000, false, fwd + 10);
  ASSERT_FALSE(old.ok());
  EXPECT_EQ(old.error().code, ErrorCode::kMessageStale);
}

// libfaketime, if installed (scripts/install-deps.sh installs the `faketime` package).
std::string faketime_library() {
  for (const char* p : {"/usr/lib/x86_64-linux-gnu/faketime/libfaketimeMT.so.1",
                        "/usr/lib/aarch64-linux-gnu/faketime/libfaketimeMT.so.1",
                        "/usr/lib/faketime/libfaketimeMT.so.1"})
    if (::access(p, R_OK) == 0) return p;
  return "";
}

class SteppedClock {
 public:
  explicit SteppedClock(const std::string& file) : file_(file) { set(0); }
  // The node's wall clock is `offset_s` from the real one (libfaketime re-reads the file).
  void set(int64_t offset_s) {
    offset_ms_ = offset_s * 1000;
    write_text(file_ + ".tmp", (offset_s < 0 ? "" : "+") + std::to_string(offset_s) + "\n");
    fs::rename(file_ + ".tmp", file_);
  }
  int64_t node_now_ms() const { return real_wall_ms() + offset_ms_; }
  std::vector<std::string> env(const std::string& lib) const {
    std::vector<std::string> e{"LD_PRELOAD=" + lib, "FAKETIME_TIMESTAMP_FILE=" + file_,
                               "FAKETIME_DONT_FAKE_MONOTONIC=1", "FAKETIME_CACHE_DURATION=1"};
    // In the ASan tree the preloaded library comes before the ASan runtime, which ASan refuses
    // by default; libfaketime only wraps clock calls, so the check is turned off (and the
    // sanitizer options the test runner set are kept).
    const char* asan = std::getenv("ASAN_OPTIONS");
    e.push_back(std::string("ASAN_OPTIONS=") +
                (asan != nullptr && *asan != '\0' ? std::string(asan) + ":" : "") +
                "verify_asan_link_order=0");
    return e;
  }

 private:
  std::string file_;
  int64_t offset_ms_ = 0;
};

// The node's wall clock as it answers (an ANNOUNCE envelope's timestamp).
int64_t node_clock_ms(const Node& n) {
  json::Value v = parse(n.post("/rcan/v1/discover", "{}", "").body);
  const json::Value* t = v.get("timestamp_ms");
  return t && t->is_int() ? t->as_int() : 0;
}

TEST(ClockSteps, RealNodeUnderFaketimeKeepsReplayTtlAndAuditOrdering) {
  const std::string lib = faketime_library();
  if (lib.empty())
    GTEST_SKIP() << "libfaketime is not installed (scripts/install-deps.sh installs faketime)";
  test::TempDir tmp;
  SteppedClock clock(tmp.file("faketime.rc"));
  Node node(tmp.file("node"), "  msg_id_cache_size: 100\n", "", clock.env(lib));
  ASSERT_TRUE(node.start());
  ASSERT_LT(std::llabs(node_clock_ms(node) - real_wall_ms()), 5000)
      << "libfaketime moved the clock at +0";
  // Tokens valid across the whole test whatever the node's clock says (iat 2 h back, exp 3 h on).
  const std::string owner =
      node.token("owner", {"status", "control", "config"}, "owner-1", 7200, 10800);
  const std::string user = node.token("user", {"status", "control"}, "user-1", 7200, 10800);
  auto send = [&](const std::string& id, int64_t ts, const std::string& tok) {
    return node.post("/rcan/v1/command", command("status", {}, id, ts), tok);
  };

  // Send more ids than the OWNER's share of the replay memory (100 ids, 6 per principal), so that
  // its own evictions happen before the step.
  std::vector<std::pair<std::string, int64_t>> before;
  for (int i = 0; i < 110; ++i) {
    std::string id = new_uuid_v4();
    int64_t ts = clock.node_now_ms();
    HttpReply r = send(id, ts, owner);
    ASSERT_EQ(r.status, 200) << r.body;
    before.emplace_back(id, ts);
  }
  // A control session (USER: 1 h TTL, counted on the monotonic clock).
  HttpReply claim = node.post("/rcan/v1/auth/claim", "{}", user);
  ASSERT_EQ(claim.status, 200) << claim.body;
  auto session_expires_in = [&]() -> int64_t {
    json::Value st = node.status(owner);
    const json::Value* ss = st.get("sessions");
    if (!ss || !ss->is_array() || ss->as_array().empty()) return -1;
    const json::Value* e = ss->as_array()[0].get("expires_in");
    return e && e->is_int() ? e->as_int() : -1;
  };
  const int64_t ttl0 = session_expires_in();
  ASSERT_GT(ttl0, 3000);
  // A one-hour lease (its end is a wall-clock time, shown and persisted as such).
  HttpReply lease = node.post("/rcan/v1/leases", R"({"leasee":"lee","duration_s":3600})", owner);
  ASSERT_EQ(lease.status, 201) << lease.body;
  auto lease_remaining_s = [&]() -> int64_t {
    json::Value v = parse(node.get("/rcan/v1/leases", owner).body);
    const json::Value* ls = v.get("leases");
    if (!ls || !ls->is_array() || ls->as_array().empty()) return -1;
    const json::Value* r = ls->as_array()[0].get("remaining_s");
    return r && r->is_int() ? r->as_int() : -1;
  };
  const int64_t lease0 = lease_remaining_s();
  ASSERT_GT(lease0, 3500);

  // ---- The wall clock steps back one hour.
  clock.set(-3600);
  ASSERT_TRUE(eventually([&] {
    return std::llabs(node_clock_ms(node) - clock.node_now_ms()) < 5000;
  })) << "the node's clock did not step back";
  // A message stamped with the node's (new) time is fresh, also from the OWNER, whose replay
  // memory evicted its own ids from before the step.
  std::string fresh = new_uuid_v4();
  int64_t fresh_ts = clock.node_now_ms();
  HttpReply r1 = send(fresh, fresh_ts, user);
  EXPECT_EQ(r1.status, 200) << r1.body;
  HttpReply r1_owner = send(new_uuid_v4(), clock.node_now_ms(), owner);
  EXPECT_EQ(r1_owner.status, 200) << r1_owner.body;
  // Replays are still refused: an id from before the step with its own timestamp (now an hour in
  // the node's future: stale), the same id restamped with the new time by the principal that
  // used it (remembered: replay), and the new message sent again.
  HttpReply r2 = send(before.back().first, before.back().second, owner);
  EXPECT_EQ(r2.status, 408) << r2.body;
  EXPECT_EQ(error_code(r2), "MESSAGE_STALE");
  HttpReply r3 = send(before.back().first, clock.node_now_ms(), owner);
  EXPECT_EQ(r3.status, 409) << r3.body;
  EXPECT_EQ(error_code(r3), "REPLAY_DETECTED");
  HttpReply r4 = send(fresh, fresh_ts, user);
  EXPECT_EQ(r4.status, 409) << r4.body;
  EXPECT_EQ(error_code(r4), "REPLAY_DETECTED");
  // The session's TTL did not grow with the step, and it is still held.
  int64_t ttl1 = session_expires_in();
  EXPECT_GT(ttl1, 0);
  EXPECT_LE(ttl1, ttl0);
  // Nor did the lease's: its end moved with the step (after the next control tick).
  EXPECT_TRUE(eventually([&] {
    int64_t r = lease_remaining_s();
    return r > 3000 && r <= lease0;
  })) << "lease remaining "
      << lease_remaining_s() << " s after the step back";

  // ---- The wall clock steps forward two hours (one hour ahead of the real time).
  clock.set(3600);
  ASSERT_TRUE(eventually([&] {
    return std::llabs(node_clock_ms(node) - clock.node_now_ms()) < 5000;
  })) << "the node's clock did not step forward";
  std::string ahead = new_uuid_v4();
  int64_t ahead_ts = clock.node_now_ms();
  HttpReply r5 = send(ahead, ahead_ts, user);
  EXPECT_EQ(r5.status, 200) << r5.body;  // fresh by the node's clock (PROFILE.md §3)
  HttpReply r6 = send(ahead, ahead_ts, user);
  EXPECT_EQ(r6.status, 409) << r6.body;
  HttpReply r7 = send(fresh, fresh_ts, user);  // two hours old now
  EXPECT_EQ(r7.status, 408) << r7.body;
  // Two hours of wall clock did not end the one-hour session: it runs on the monotonic clock.
  int64_t ttl2 = session_expires_in();
  EXPECT_GT(ttl2, 0) << "the control session expired with the wall-clock step";
  EXPECT_LE(ttl2, ttl1);
  EXPECT_TRUE(eventually([&] {
    int64_t r = lease_remaining_s();
    return r > 3000 && r <= lease0;
  })) << "lease remaining "
      << lease_remaining_s() << " s after the step forward";
  HttpReply drive = node.post(
      "/rcan/v1/command",
      command("move", {{"linear", 0.1}, {"duration_ms", 100}}, "", clock.node_now_ms()), user);
  EXPECT_EQ(drive.status, 200) << drive.body;

  // ---- The audit chain: seq strictly increasing, timestamps follow the node's clock (back
  // and forth), and it verifies.
  ASSERT_EQ(node.stop(), 0);
  std::vector<json::Value> records = exported(node.data_dir() + "/audit");
  ASSERT_GT(records.size(), 110u);
  int64_t last_seq = 0;
  bool went_back = false;
  int64_t prev_ts = 0;
  for (const auto& r : records) {
    int64_t seq = r.get("seq")->as_int();
    EXPECT_EQ(seq, last_seq + 1);
    last_seq = seq;
    int64_t ts = r.get("timestamp_ms")->as_int();
    if (prev_ts && ts < prev_ts - 1'000'000) went_back = true;
    prev_ts = ts;
  }
  EXPECT_TRUE(went_back) << "the audit timestamps never showed the step back";
  expect_chain_verifies(node.data_dir() + "/audit", node.secret_file());
}

TEST(ClockSteps, AStepForwardDoesNotTimeOutOrAutoAllowAHeldCommand) {
  const std::string lib = faketime_library();
  if (lib.empty())
    GTEST_SKIP() << "libfaketime is not installed (scripts/install-deps.sh installs faketime)";
  test::TempDir tmp;
  SteppedClock clock(tmp.file("faketime.rc"));
  // Drives wait for an OWNER's approval for a minute; on timeout they would be let through.
  Node node(tmp.file("node"), "",
            "agent:\n  hitl_gates:\n    - action_types: [move]\n      require_auth: true\n"
            "      auth_timeout_ms: 60000\n      on_timeout: allow\n",
            clock.env(lib));
  ASSERT_TRUE(node.start());
  const std::string owner =
      node.token("owner", {"status", "control", "config"}, "owner-1", 7200, 10800);
  const std::string user = node.token("user", {"status", "control"}, "user-1", 7200, 10800);
  std::string id = new_uuid_v4();
  HttpReply held = node.post("/rcan/v1/command",
                             command("move", {{"linear", 0.2}, {"duration_ms", 200}}, id), user);
  ASSERT_EQ(held.status, 202) << held.body;
  auto pending = [&] {
    json::Value v = parse(node.get("/rcan/v1/pending", owner).body);
    const json::Value* p = v.get("pending");
    return p && p->is_array() ? p->as_array().size() : size_t{999};
  };
  ASSERT_EQ(pending(), 1u);
  const double odometry = base_number(node.status(owner), "odometry_m");
  // Two hours of wall clock in one step: the approval window has not run out.
  clock.set(7200);
  ASSERT_TRUE(eventually([&] {
    return std::llabs(node_clock_ms(node) - clock.node_now_ms()) < 5000;
  })) << "the node's clock did not step";
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));  // several passes of the hold timer
  EXPECT_EQ(pending(), 1u) << "the held command timed out with the wall-clock step";
  EXPECT_EQ(base_number(node.status(owner), "odometry_m"), odometry)
      << "the held drive ran unapproved";
  ASSERT_EQ(node.stop(), 0);
  for (const auto& r : exported(node.data_dir() + "/audit"))
    EXPECT_NE(str(r, "event"), "HITL_TIMEOUT") << json::dump(r);
  expect_chain_verifies(node.data_dir() + "/audit", node.secret_file());
}

// ------------------------------------------------------------------------------------------
// Broker and issuer outages (seed §6.1; docs/FLEET.md, docs/SESSIONS.md §Network partition).

// A Mosquitto broker on a free loopback port that the test stops and starts again.
class Broker {
 public:
  explicit Broker(const std::string& dir) : dir_(dir), port_(test::free_port()) {
    write_text(dir_ + "/mosquitto.conf",
               "listener " + std::to_string(port_) +
                   " 127.0.0.1\nallow_anonymous true\npersistence false\n");
  }
  ~Broker() { stop(); }
  bool start() {
    proc_ = std::make_unique<test::Process>();
    if (!proc_->start({"/usr/sbin/mosquitto", "-c", dir_ + "/mosquitto.conf"})) return false;
    return proc_->wait_for_line("running", 10000).has_value();
  }
  void stop() {
    if (proc_ && proc_->running()) proc_->stop(SIGTERM, 5000);
  }
  std::string url() const { return "mqtt://127.0.0.1:" + std::to_string(port_); }

 private:
  std::string dir_;
  uint16_t port_;
  std::unique_ptr<test::Process> proc_;
};

// The test's MQTT client: publishes commands and keeps the replies.
class MqttPeer {
 public:
  MqttPeer(const std::string& url, const std::string& reply_topic) {
    transport::MqttOptions o;
    o.url = url;
    client_ = std::make_unique<transport::MqttClient>(o);
    client_->subscribe(reply_topic, 1);
    client_->on_message([this](const transport::MqttMessage& m) {
      auto v = json::parse(m.payload);
      std::lock_guard<std::mutex> lk(mu_);
      if (v.ok()) replies_.push_back(*v);
    });
    EXPECT_TRUE(client_->start().ok());
    EXPECT_TRUE(eventually([&] { return client_->connected(); }));
    std::this_thread::sleep_for(std::chrono::milliseconds(150));  // the subscription is registered
  }
  void publish(const std::string& topic, const json::Value& v) {
    EXPECT_TRUE(client_->publish(topic, json::dump(v), 1, false).ok());
  }
  // The reply to `id` (type ACK or ERROR), waiting up to 10 s.
  std::optional<json::Value> reply_to(const std::string& id) {
    std::optional<json::Value> out;
    eventually([&] {
      std::lock_guard<std::mutex> lk(mu_);
      for (const auto& r : replies_)
        if (str(r, "reply_to") == id) out = r;
      return out.has_value();
    });
    return out;
  }

 private:
  std::unique_ptr<transport::MqttClient> client_;
  std::mutex mu_;
  std::vector<json::Value> replies_;
};

TEST(BrokerOutage, RobotKeepsServingHttpAndMqttCommandsResumeWithoutRunningTwice) {
  test::TempDir tmp;
  Broker broker(tmp.path());
  ASSERT_TRUE(broker.start());
  Node node(tmp.file("node"), "",
            "mqtt: {enabled: true, broker: \"" + broker.url() +
                "\", telemetry_hz: 0, keepalive_s: 5, reconnect: {min_s: 1, max_s: 2}}\n");
  ASSERT_TRUE(node.start());
  ASSERT_TRUE(node.proc().wait_for_line("mqtt_connected", 10000)) << node.proc().err();
  const std::string owner = node.token("owner", {"status", "control", "config"}, "owner-1");
  // Over MQTT the token is bound to the sender's key and each message signed with it.
  std::array<uint8_t, 32> seed{};
  seed.fill(9);
  auto sender = keys::derive(seed, seed);
  ASSERT_TRUE(sender.ok());
  const std::string mqtt_owner =
      node.token("owner", {"status", "control", "config"}, "owner-1", 5, 3600,
                 *cnf::make(msgsig::Alg::kEd25519, sender->pub.ed25519_pk));
  const std::string topic = "rcan/robot/local_rcan/acme/rover/0a1b2c3d/cmd";
  const std::string reply = "rcan/robot/local_rcan/acme/rover/0a1b2c3d/reply";
  auto mqtt_cmd = [&](const std::string& id) {
    json::Object m{
        {"version", "1.0.0"},
        {"message_id", id},
        {"type", "COMMAND"},
        {"timestamp_ms", real_wall_ms()},
        {"auth_token", mqtt_owner},
        {"payload", json::Object{{"action", "move"}, {"linear", 0.1}, {"duration_ms", 100}}}};
    EXPECT_TRUE(msgsig::sign_ed25519(m, sender->ed25519_seed.span()).ok());
    return json::Value(std::move(m));
  };
  const std::string a = new_uuid_v4();
  json::Value msg_a = mqtt_cmd(a);
  {
    MqttPeer peer(broker.url(), reply);
    peer.publish(topic, msg_a);
    auto ack = peer.reply_to(a);
    ASSERT_TRUE(ack);
    EXPECT_EQ(str(*ack, "type"), "ACK");
  }

  // The broker goes away. The robot keeps serving HTTP: status, commands, ESTOP and RESUME.
  broker.stop();
  ASSERT_TRUE(node.proc().wait_for_line("mqtt_disconnected", 10000)) << node.proc().err();
  HttpReply st = node.get("/rcan/v1/status", owner);
  ASSERT_EQ(st.status, 200);
  EXPECT_EQ(str(parse(st.body), "mode"),
            "NORMAL");  // a broker is not the issuer: no partition mode
  EXPECT_EQ(
      node.post("/rcan/v1/command", command("move", {{"linear", 0.1}, {"duration_ms", 100}}), owner)
          .status,
      200);
  EXPECT_EQ(node.post("/api/stop", "", owner).status, 200);
  EXPECT_TRUE(node.status(owner).get("estop_active")->as_bool());
  HttpReply resume = node.post(
      "/rcan/v1/command",
      json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                          {"message_id", new_uuid_v4()},
                                          {"type", "SAFETY"},
                                          {"timestamp_ms", real_wall_ms()},
                                          {"payload", json::Object{{"safety_event", "RESUME"}}}})),
      owner);
  EXPECT_EQ(resume.status, 200) << resume.body;

  // The broker comes back: the robot reconnects by itself, new commands over MQTT run, and a
  // command it already ran (what a redelivery after the reconnect looks like) is not run again.
  ASSERT_TRUE(broker.start());
  ASSERT_TRUE(node.proc().wait_for_line("\"connects\":2", 15000)) << node.proc().err();
  MqttPeer peer(broker.url(), reply);
  const std::string b = new_uuid_v4();
  peer.publish(topic, mqtt_cmd(b));
  auto ack_b = peer.reply_to(b);
  ASSERT_TRUE(ack_b);
  EXPECT_EQ(str(*ack_b, "type"), "ACK");
  peer.publish(topic, msg_a);
  auto again = peer.reply_to(a);
  ASSERT_TRUE(again);
  EXPECT_EQ(str(*again, "type"), "ERROR");
  EXPECT_EQ(str(*again->get("payload"), "error_code"), "REPLAY_DETECTED");

  ASSERT_EQ(node.stop(), 0);
  int commands_a = 0, commands_b = 0;
  for (const auto& r : exported(node.data_dir() + "/audit")) {
    if (str(r, "event") != "COMMAND") continue;
    if (str(r, "message_id") == a) ++commands_a;
    if (str(r, "message_id") == b) ++commands_b;
  }
  EXPECT_EQ(commands_a, 1);
  EXPECT_EQ(commands_b, 1);
  expect_chain_verifies(node.data_dir() + "/audit", node.secret_file());
}

// An issuer endpoint that accepts connections and never answers (a hung cloud, not a refused
// port): the probe times out, the node goes OFFLINE_AUTONOMOUS then LOCKDOWN as §6.1 says —
// and an ESTOP from a principal it cannot vouch for still stops the robot.
class SilentServer {
 public:
  SilentServer() {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a);
    ::listen(fd_, 64);  // the kernel completes handshakes; nobody ever reads or answers
    socklen_t len = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
  }
  ~SilentServer() { ::close(fd_); }
  uint16_t port() const { return port_; }

 private:
  int fd_ = -1;
  uint16_t port_ = 0;
};

TEST(IssuerOutage, HungIssuerDegradesToLockdownAndEstopStillWorks) {
  test::TempDir tmp;
  SilentServer issuer;
  Node node(tmp.file("node"), "",
            "offline:\n  issuer_url: http://127.0.0.1:" + std::to_string(issuer.port()) +
                "/jwks.json\n  issuer_poll_ms: 50\n  issuer_timeout_ms: 200\n  max_key_ttl_s: 2\n");
  ASSERT_TRUE(node.start());
  const std::string owner = node.token("owner", {"status", "control", "config"}, "owner-1");
  const std::string stranger = node.token("user", {"status", "control"}, "stranger");
  auto mode = [&] { return str(parse(node.get("/rcan/v1/status").body), "mode"); };
  // No good probe ever: the key cache is empty, so the node is in LOCKDOWN (§6.1: deny new
  // sessions, maintain existing).
  ASSERT_TRUE(eventually([&] { return mode() == "LOCKDOWN"; })) << mode();
  HttpReply claim = node.post("/rcan/v1/auth/claim", "{}", stranger);
  EXPECT_EQ(claim.status, 503);
  EXPECT_EQ(error_code(claim), "LOCKDOWN");
  HttpReply drive = node.post("/rcan/v1/command",
                              command("move", {{"linear", 0.1}, {"duration_ms", 100}}), stranger);
  EXPECT_EQ(drive.status, 503);
  EXPECT_EQ(error_code(drive), "LOCKDOWN");
  // The robot still serves, and a stop is never refused for anything but authentication.
  EXPECT_EQ(node.get("/healthz").status, 200);
  HttpReply stop = node.post("/api/stop", "", stranger);
  EXPECT_EQ(stop.status, 200) << stop.body;
  EXPECT_TRUE(node.status(owner).get("estop_active")->as_bool());
  ASSERT_EQ(node.stop(), 0);
  bool estop_tagged = false;
  for (const auto& r : exported(node.data_dir() + "/audit")) {
    const json::Value* d = r.get("detail");
    if (str(r, "event") == "ESTOP" && d && str(*d, "partition_mode") == "LOCKDOWN")
      estop_tagged = true;
  }
  EXPECT_TRUE(estop_tagged) << "the ESTOP record is not tagged for sync (log_for_sync)";
  expect_chain_verifies(node.data_dir() + "/audit", node.secret_file());
}

}  // namespace
}  // namespace rcan
