// mDNS discovery end to end: two network namespaces joined by a veth pair, each with its own
// dbus-daemon and avahi-daemon. rcand in namespace A advertises _rcan._tcp; `rcan discover` in
// namespace B finds it with the TXT keys of docs/PROTOCOL.md and sees `status` follow ESTOP,
// claims and releases, and the advertisement come back after A's Avahi daemon restarts.
// Needs root (namespaces, mounts): otherwise each test says why it skipped. Without any
// Avahi daemon, rcand keeps serving and says so once (that part needs no privileges).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "rcan/crypto/jwt.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

constexpr const char* kIp = "/usr/sbin/ip";

bool exists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

json::Value parse(const std::string& s) {
  auto v = json::parse(s, {.max_depth = 64, .max_bytes = 1u << 20});
  EXPECT_TRUE(v.ok()) << s.substr(0, 300);
  return v.ok() ? *v : json::Value();
}

// One namespace with its own D-Bus system bus and Avahi daemon.
struct Namespace {
  std::string name, veth, addr, dir, bus;
  test::Process dbus, avahi;
  std::vector<std::string> env() const { return {"DBUS_SYSTEM_BUS_ADDRESS=unix:path=" + bus}; }
  std::vector<std::string> exec(std::vector<std::string> argv) const {
    std::vector<std::string> full{kIp, "netns", "exec", name};
    full.insert(full.end(), argv.begin(), argv.end());
    return full;
  }
  bool start_avahi() {
    std::string conf = dir + "/avahi.conf";
    return avahi.start(
               exec({"/bin/sh", "-c",
                     "mkdir -p /run/avahi-daemon && mount -t tmpfs tmpfs /run/avahi-daemon && "
                     "exec /usr/sbin/avahi-daemon -f " +
                         conf + " --no-drop-root --no-chroot --no-rlimits --no-proc-title"}),
               env()) &&
           avahi.wait_for_line("Server startup complete", 15000).has_value();
  }
};

class NetnsDiscovery : public ::testing::Test {
 protected:
  void SetUp() override {
    if (::geteuid() != 0)
      GTEST_SKIP() << "skipped: network namespaces need root (running as uid " << ::geteuid()
                   << ")";
    for (const char* bin : {kIp, "/usr/sbin/avahi-daemon", "/usr/bin/dbus-daemon", "/bin/sh"})
      if (!exists(bin))
        GTEST_SKIP() << "skipped: " << bin
                     << " is not installed (scripts/install-deps.sh installs it)";
    ::unsetenv("DBUS_SYSTEM_BUS_ADDRESS");  // children get each namespace's own bus only
    std::string tag = std::to_string(::getpid() % 100000);
    a_.name = "rcanA" + tag;
    b_.name = "rcanB" + tag;
    a_.veth = "vrA" + tag;
    b_.veth = "vrB" + tag;
    a_.addr = "10.77.0.1";
    b_.addr = "10.77.0.2";
    auto add = test::run({kIp, "netns", "add", a_.name});
    if (add.exit_code != 0)
      GTEST_SKIP() << "skipped: cannot create a network namespace: " << add.err;
    created_ = true;
    ASSERT_EQ(test::run({kIp, "netns", "add", b_.name}).exit_code, 0);
    auto link = test::run({kIp, "link", "add", a_.veth, "type", "veth", "peer", "name", b_.veth});
    if (link.exit_code != 0) GTEST_SKIP() << "skipped: cannot create a veth pair: " << link.err;
    for (Namespace* n : {&a_, &b_}) {
      ASSERT_EQ(test::run({kIp, "link", "set", n->veth, "netns", n->name}).exit_code, 0);
      ASSERT_EQ(
          test::run({kIp, "-n", n->name, "addr", "add", n->addr + "/24", "dev", n->veth}).exit_code,
          0);
      ASSERT_EQ(test::run({kIp, "-n", n->name, "link", "set", n->veth, "up"}).exit_code, 0);
      ASSERT_EQ(test::run({kIp, "-n", n->name, "link", "set", "lo", "up"}).exit_code, 0);
      n->dir = tmp_.path() + "/" + n->name;
      ::mkdir(n->dir.c_str(), 0700);
      n->bus = n->dir + "/system_bus_socket";
      std::ofstream(n->dir + "/dbus.conf")
          << "<!DOCTYPE busconfig PUBLIC \"-//freedesktop//DTD D-Bus Bus Configuration 1.0//EN\"\n"
             " \"http://www.freedesktop.org/standards/dbus/1.0/busconfig.dtd\">\n"
             "<busconfig><type>system</type><listen>unix:path="
          << n->bus
          << "</listen><auth>EXTERNAL</auth>\n"
             "<policy context=\"default\"><allow user=\"*\"/><allow own=\"*\"/><allow "
             "send_destination=\"*\"/>"
             "<allow receive_sender=\"*\"/></policy></busconfig>\n";
      std::ofstream(n->dir + "/avahi.conf")
          << "[server]\nhost-name=" << n->name << "\ndomain-name=local\nuse-ipv4=yes\nuse-ipv6=no\n"
          << "allow-interfaces=" << n->veth
          << "\nenable-dbus=yes\nratelimit-interval-usec=1000000\n"
          << "ratelimit-burst=1000\n[wide-area]\nenable-wide-area=no\n[publish]\npublish-hinfo=no\n"
          << "publish-workstation=no\n";
      ASSERT_TRUE(
          n->dbus.start(n->exec({"/usr/bin/dbus-daemon", "--config-file=" + n->dir + "/dbus.conf",
                                 "--nofork", "--nopidfile"})));
      for (int i = 0; i < 250 && !exists(n->bus); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      ASSERT_TRUE(exists(n->bus)) << n->dbus.err();
      ASSERT_TRUE(n->start_avahi()) << n->avahi.err();
    }
  }
  void TearDown() override {
    node_.reset();
    for (Namespace* n : {&a_, &b_}) {
      if (n->avahi.pid() > 0) n->avahi.stop(SIGTERM, 5000);
      if (n->dbus.pid() > 0) n->dbus.stop(SIGTERM, 5000);
    }
    if (created_) {
      (void)test::run({kIp, "netns", "del", a_.name});
      (void)test::run({kIp, "netns", "del", b_.name});  // the veth pair goes with them
    }
  }

  // Starts rcand inside A, bound to A's address, and waits for its advertisement.
  void start_node() {
    node_ = std::make_unique<test::Process>();
    node_dir_ = tmp_.path() + "/node";
    ASSERT_TRUE(node_->start(
        a_.exec({RCAND_PATH, "--data-dir", node_dir_, "--port", "8080", "--bind", "0.0.0.0"}),
        a_.env()));
    auto line = node_->wait_for_line("\"event\":\"listening\"", 30000);
    ASSERT_TRUE(line.has_value()) << node_->err();
    ruri_ = parse(*line).get("ruri")->as_string();
    ASSERT_TRUE(node_->wait_for_line("mdns_advertising", 15000).has_value()) << node_->err();
  }
  test::RunResult cli_in(const Namespace& n, std::vector<std::string> args) {
    std::vector<std::string> argv{RCAN_CLI_PATH};
    argv.insert(argv.end(), args.begin(), args.end());
    return test::run(n.exec(argv), "", n.env());
  }
  // Browses from B (mDNS only) until the robot shows `status`, a bounded number of times.
  json::Value discover_until(const std::string& status) {
    json::Value last;
    for (int i = 0; i < 15; ++i) {
      auto r = cli_in(b_, {"discover", "--hosts", "", "--timeout", "1500", "--json"});
      if (r.exit_code == 0) {
        last = parse(r.out);
        const auto& robots = last.get("robots")->as_array();
        if (robots.size() == 1 && robots[0].get("status")->as_string() == status) return robots[0];
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
    }
    ADD_FAILURE() << "never saw status " << status << "; last answer: " << json::dump(last) << "\n"
                  << node_->err();
    return {};
  }

  test::TempDir tmp_;
  Namespace a_, b_;
  bool created_ = false;
  std::unique_ptr<test::Process> node_;
  std::string node_dir_, ruri_;
};

TEST_F(NetnsDiscovery, RobotInOneNamespaceIsFoundFromTheOtherWithItsTxtKeys) {
  start_node();
  json::Value robot = discover_until("available");
  ASSERT_TRUE(robot.is_object());
  EXPECT_EQ(robot.get("ruri")->as_string(), ruri_);
  EXPECT_EQ(robot.get("source")->as_string(), "mdns");
  EXPECT_EQ(robot.get("url")->as_string(), "http://" + a_.addr + ":8080");
  EXPECT_TRUE(
      robot.get("reachable")->as_bool());  // confirmed with GET /rcan/v1/status across the veth
  const json::Value* txt = robot.get("txt");
  for (const char* k : {"ruri", "model", "caps", "roles", "role", "version", "name", "status"})
    EXPECT_NE(txt->get(k), nullptr) << "TXT key " << k << " missing: " << json::dump(*txt);
  EXPECT_EQ(txt->get("version")->as_string(), "1.0.0");
  EXPECT_EQ(txt->get("caps")->as_string(), "status,chat,teleop,nav,arm");
  // The table form names the robot and where it answers.
  auto table = cli_in(b_, {"discover", "--hosts", "", "--timeout", "1500"});
  EXPECT_NE(table.out.find("http://" + a_.addr + ":8080"), std::string::npos)
      << table.out << table.err;
}

TEST_F(NetnsDiscovery, StatusFollowsEstopClaimAndRelease) {
  start_node();
  discover_until("available");
  std::string url = "http://" + a_.addr + ":8080";
  std::string tok = node_dir_ + "/owner.token";
  ASSERT_EQ(
      cli_in(b_, {"estop", "--url", url, "--token-file", tok, "--reason", "mdns test"}).exit_code,
      0);
  discover_until("estop");
  ASSERT_EQ(cli_in(b_, {"resume", "--url", url, "--token-file", tok}).exit_code, 0);
  discover_until("available");
  ASSERT_EQ(cli_in(b_, {"claim", "--url", url, "--token-file", tok}).exit_code, 0);
  discover_until("claimed");
  ASSERT_EQ(cli_in(b_, {"release", "--url", url, "--token-file", tok}).exit_code, 0);
  discover_until("available");
}

TEST_F(NetnsDiscovery, AdvertisementReturnsAfterTheAvahiDaemonRestarts) {
  start_node();
  discover_until("available");
  a_.avahi.stop(SIGTERM, 5000);
  ASSERT_TRUE(node_->wait_for_line("mdns_unavailable", 10000).has_value()) << node_->err();
  ASSERT_TRUE(a_.start_avahi()) << a_.avahi.err();
  ASSERT_TRUE(node_->wait_for_line("mdns_available", 20000).has_value()) << node_->err();
  json::Value robot = discover_until("available");
  ASSERT_TRUE(robot.is_object());
  EXPECT_EQ(robot.get("ruri")->as_string(), ruri_);
  EXPECT_TRUE(node_->running());
}

// The dashboard's Robots view with dashboard.mdns (docs/DASHBOARD.md §Robots): a node in B lists
// the robot A announces, with the state it announces, and follows its ESTOP; a stop relayed to
// it is refused with nothing sent, since an announcement is no reason to send a token anywhere.
TEST_F(NetnsDiscovery, TheRobotsViewListsAnnouncedRobotsAndSendsThemNoToken) {
  if (!exists("/usr/bin/curl")) GTEST_SKIP() << "skipped: curl is not installed";
  start_node();
  const std::string dir = b_.dir + "/viewer";
  ::mkdir(dir.c_str(), 0700);
  ASSERT_EQ(test::run_cli({"keys", "generate", "--dir", dir + "/keys"}).exit_code, 0);
  ASSERT_EQ(test::run_cli({"audit", "new-secret", "--out", dir + "/audit.secret"}).exit_code, 0);
  const std::string secret = dir + "/ops.secret";
  std::ofstream(secret) << "0123456789abcdef0123456789abcdef-mdns-view-secret";
  ::chmod(secret.c_str(), 0600);
  const std::string viewer_ruri = "rcan://local.rcan/rcan/viewer/0000beef";
  std::ofstream(dir + "/robot.yaml")
      << "rcan_version: \"1.2\"\nruri: " << viewer_ruri << "\nnode: {data_dir: " << dir
      << "}\nsecurity:\n  jwt:\n    issuers: [{issuer: ops, key_file: " << secret
      << ", kind: hs256_secret}]\ndashboard: {mdns: true}\n";
  test::Process viewer;
  ASSERT_TRUE(viewer.start(b_.exec({RCAND_PATH, "--config", dir + "/robot.yaml", "--port", "8090"}),
                           b_.env()));
  ASSERT_TRUE(viewer.wait_for_line("\"event\":\"listening\"", 30000).has_value()) << viewer.err();
  auto key = jwt::SigningKey::from_file(secret, true);
  ASSERT_TRUE(key.ok());
  const int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  auto tok = jwt::issue(json::Object{{"iss", "ops"},
                                     {"sub", "operator"},
                                     {"aud", "rcan://local.rcan/rcan/*/*"},
                                     {"role", "user"},
                                     {"iat", now - 5},
                                     {"exp", now + 600}},
                        *key);
  ASSERT_TRUE(tok.ok());
  auto call = [&](const std::vector<std::string>& extra) {
    std::vector<std::string> argv{"/usr/bin/curl", "-s", "-H", "Authorization: Bearer " + *tok};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return test::run(b_.exec(argv)).out;
  };
  const std::string a_url = "http://" + a_.addr + ":8080";
  // Until the view lists A with `status` (up to 15 s).
  auto listed_as = [&](const std::string& status) {
    json::Value last;
    for (int i = 0; i < 75; ++i) {
      last = parse(call({"http://127.0.0.1:8090/api/robots"}));
      const json::Value* d = last.get("discovered");
      if (d && d->is_array())
        for (const json::Value& r : d->as_array())
          if (r.get("ruri")->as_string() == ruri_ && r.get("status")->as_string() == status)
            return r;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    ADD_FAILURE() << "never listed as " << status << ": " << json::dump(last) << "\n"
                  << viewer.err();
    return json::Value();
  };
  json::Value a = listed_as("available");
  ASSERT_TRUE(a.is_object());
  EXPECT_EQ(a.get("url")->as_string(), a_url);
  EXPECT_EQ(a.get("source")->as_string(), "mdns");
  EXPECT_EQ(a.get("interface")->as_string(), b_.veth);
  json::Value all = parse(call({"http://127.0.0.1:8090/api/robots"}));
  EXPECT_EQ(all.get("mdns")->as_string(), "on");
  EXPECT_EQ(all.get("configured")->to_double(), 0);
  for (const json::Value& r : all.get("discovered")->as_array())
    EXPECT_NE(r.get("ruri")->as_string(), viewer_ruri);  // never itself
  // A relay to the announced address: refused before anything is sent; A stays as it was.
  std::string refused =
      call({"-X", "POST", "-H", "Content-Type: application/json", "-d",
            "{\"robots\":[\"" + a_url + "\"]}", "http://127.0.0.1:8090/api/robots/estop"});
  EXPECT_NE(refused.find("nothing was sent"), std::string::npos) << refused;
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  listed_as("available");
  // A latched by its owner: the view follows the announcement.
  ASSERT_EQ(
      cli_in(b_, {"estop", "--url", a_url, "--token-file", node_dir_ + "/owner.token"}).exit_code,
      0);
  listed_as("estop");
  viewer.stop(SIGTERM, 10000);
}

// No privileges needed: a node with no D-Bus / Avahi keeps serving and says so once; the CLI
// falls back to probing.
TEST(NoAvahi, NodeKeepsServingAndSaysSoOnce) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node", {},
                      {"DBUS_SYSTEM_BUS_ADDRESS=unix:path=" + dir.path() + "/no-such-bus"});
  ASSERT_NE(d.port(), 0);
  auto st = test::run_cli({"status", "--url", d.url()});
  EXPECT_EQ(st.exit_code, 0) << st.err;
  d.proc().drain(200);
  const std::string& err = d.proc().err();
  size_t first = err.find("mdns_unavailable");
  ASSERT_NE(first, std::string::npos) << err;
  EXPECT_EQ(err.find("mdns_unavailable", first + 1), std::string::npos) << err;
  auto disc = test::run_cli({"discover", "--url", d.url(), "--timeout", "500", "--json"}, "",
                            {"DBUS_SYSTEM_BUS_ADDRESS=unix:path=" + dir.path() + "/no-such-bus"});
  ASSERT_EQ(disc.exit_code, 0) << disc.err;
  EXPECT_NE(disc.err.find("mDNS"), std::string::npos);
  json::Value v = parse(disc.out);
  EXPECT_FALSE(v.get("mdns_error")->as_string().empty());
  ASSERT_EQ(v.get("robots")->as_array().size(), 1u);
  EXPECT_EQ(v.get("robots")->as_array()[0].get("source")->as_string(), "probe");
}

}  // namespace
}  // namespace rcan
