// The dashboard's Robots view against real nodes (docs/DASHBOARD.md §Robots): node A lists
// itself and the robots of its `dashboard.robots` with the state each one announces, and stops
// them — each robot gets POST /api/stop with the operator's own token and decides by its own
// issuers. The answer names every robot that did not confirm (refused, unreachable, silent),
// the relay is recorded on A, and a token never goes to an address the configuration does not
// list. Three rcand processes share one HS256 issuer; a fourth address refuses connections and a
// fifth accepts them and never answers.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "rcan/crypto/jwt.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan {
namespace {

namespace fs = std::filesystem;
using Headers = std::vector<std::pair<std::string, std::string>>;

int64_t now_s() {
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

json::Value parse(const std::string& s) {
  auto v = json::parse(s);
  return v.ok() ? std::move(v).value() : json::Value();
}

std::string str_of(const json::Value& v, const char* k) {
  const json::Value* f = v.is_object() ? v.get(k) : nullptr;
  return f && f->is_string() ? f->as_string() : std::string();
}

void write_file(const std::string& path, const std::string& text) {
  std::ofstream(path) << text;
  fs::permissions(path, fs::perms::owner_read | fs::perms::owner_write);
}

// A TCP listener on loopback that accepts connections and never answers; counts them.
class SilentListener {
 public:
  SilentListener() {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    EXPECT_EQ(listen(fd_, 16), 0);
    socklen_t len = sizeof a;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] {
      while (true) {
        int c = accept(fd_, nullptr, nullptr);
        if (c < 0) return;
        accepted_++;
        held_.push_back(c);  // held open, unanswered, until the destructor
      }
    });
  }
  ~SilentListener() {
    shutdown(fd_, SHUT_RDWR);
    close(fd_);
    thread_.join();
    for (int c : held_) close(c);
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  int accepted() const { return accepted_.load(); }

 private:
  int fd_ = -1;
  uint16_t port_ = 0;
  std::atomic<int> accepted_{0};
  std::vector<int> held_;
  std::thread thread_;
};

// One configured rcand: its data directory, keys, chain secret and YAML, and the shared issuer.
class Node {
 public:
  Node(const std::string& root, const std::string& name, const std::string& device,
       const std::string& secret_file, const std::string& extra_yaml = "")
      : dir_(root + "/" + name) {
    fs::create_directories(dir_);
    fs::permissions(dir_, fs::perms::owner_all);
    EXPECT_EQ(test::run_cli({"keys", "generate", "--dir", dir_ + "/keys"}).exit_code, 0);
    EXPECT_EQ(test::run_cli({"audit", "new-secret", "--out", dir_ + "/audit.secret"}).exit_code, 0);
    ruri_ = "rcan://local.rcan/rcan/sim-rover/" + device;
    write_file(dir_ + "/robot.yaml",
               "rcan_version: \"1.2\"\nruri: " + ruri_ + "\nrobot: {name: " + name +
                   "}\nnode: {data_dir: " + dir_ +
                   "}\nsecurity:\n  jwt:\n    issuers: [{issuer: ops-issuer, key_file: " +
                   secret_file + ", kind: hs256_secret}]\n" + extra_yaml);
    EXPECT_TRUE(proc_.start({RCAND_PATH, "--config", dir_ + "/robot.yaml", "--port", "0"}));
    auto line = proc_.wait_for_line("\"event\":\"listening\"", 30000);
    if (!line) {
      ADD_FAILURE() << proc_.err();
      return;
    }
    url_ = str_of(parse(*line), "url");
    port_ = static_cast<uint16_t>(std::stoi(url_.substr(url_.rfind(':') + 1)));
  }
  ~Node() {
    if (proc_.running()) proc_.stop(SIGTERM, 10000);
  }
  const std::string& url() const { return url_; }
  uint16_t port() const { return port_; }
  const std::string& ruri() const { return ruri_; }
  test::Process& proc() { return proc_; }
  bool latched(const std::string& token) const {
    auto r = test::http(port_, "GET", "/api/status", "", {{"Authorization", "Bearer " + token}});
    const json::Value v = parse(r.body);
    const json::Value* e = v.get("estop_active");
    return e && e->is_bool() && e->as_bool();
  }

 private:
  std::string dir_, ruri_, url_;
  uint16_t port_ = 0;
  test::Process proc_;
};

class RobotsViewTest : public ::testing::Test {
 protected:
  void SetUp() override {
    secret_ = tmp_.file("ops.secret");
    write_file(secret_, "0123456789abcdef0123456789abcdef-robots-view-secret");
    b_ = std::make_unique<Node>(tmp_.path(), "robot-b", "0000000b", secret_);
    c_ = std::make_unique<Node>(tmp_.path(), "robot-c", "0000000c", secret_);
    dead_ = "http://127.0.0.1:" + std::to_string(test::free_port());  // nothing listens
    a_ = std::make_unique<Node>(tmp_.path(), "robot-a", "0000000a", secret_,
                                "dashboard:\n  robots: [" + b_->url() + ", " + c_->url() + ", " +
                                    dead_ + ", " + silent_.url() +
                                    "]\n  poll_ms: 250\n  stop_timeout_ms: 1500\n");
    ASSERT_NE(a_->port(), 0);
    every_ = token("operator-1", "user", "rcan://local.rcan/rcan/sim-rover/*");
    owner_ = token("owner-1", "owner", "rcan://local.rcan/rcan/sim-rover/*");
  }
  // An HS256 token of the shared issuer for `aud`.
  std::string token(const std::string& sub, const std::string& role, const std::string& aud) {
    auto key = jwt::SigningKey::from_file(secret_, true);
    EXPECT_TRUE(key.ok());
    json::Object claims{{"iss", "ops-issuer"},
                        {"sub", sub},
                        {"aud", aud},
                        {"role", role},
                        {"scope", json::Array{"status", "control"}},
                        {"iat", now_s() - 5},
                        {"exp", now_s() + 3600}};
    auto t = jwt::issue(claims, *key);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : "";
  }
  test::HttpReply on_a(const std::string& method, const std::string& path, const std::string& body,
                       const std::string& tok) {
    Headers h;
    if (!tok.empty()) h.emplace_back("Authorization", "Bearer " + tok);
    return test::http(a_->port(), method, path, body, h);
  }
  // A's list, robot by URL.
  json::Value robot_in_list(const std::string& url) {
    json::Value v = parse(on_a("GET", "/api/robots", "", every_).body);
    const json::Value* list = v.get("robots");
    if (list && list->is_array())
      for (const json::Value& r : list->as_array())
        if (str_of(r, "url") == url) return r;
    return json::Value();
  }
  // Waits until A reads `url` in `status` (up to 10 s).
  bool wait_status(const std::string& url, const std::string& status) {
    for (int i = 0; i < 200; ++i) {
      if (str_of(robot_in_list(url), "status") == status) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }
  static json::Value result_for(const json::Value& answer, const std::string& url) {
    const json::Value* list = answer.get("results");
    if (list && list->is_array())
      for (const json::Value& r : list->as_array())
        if (str_of(r, "url") == url) return r;
    return json::Value();
  }

  test::TempDir tmp_;
  std::string secret_, dead_, every_, owner_;
  SilentListener silent_;
  std::unique_ptr<Node> b_, c_, a_;
};

TEST_F(RobotsViewTest, ListsThisNodeAndTheConfiguredRobotsWithTheirState) {
  EXPECT_EQ(on_a("GET", "/api/robots", "", "").status, 401);
  ASSERT_TRUE(wait_status(b_->url(), "available"));
  ASSERT_TRUE(wait_status(c_->url(), "available"));
  ASSERT_TRUE(wait_status(dead_, "unreachable"));
  ASSERT_TRUE(wait_status(silent_.url(), "unreachable"));
  json::Value v = parse(on_a("GET", "/api/robots", "", every_).body);
  EXPECT_EQ(str_of(*v.get("self"), "ruri"), a_->ruri());
  EXPECT_EQ(str_of(*v.get("self"), "status"), "available");
  EXPECT_EQ(v.get("configured")->to_double(), 4);
  json::Value b = robot_in_list(b_->url());
  EXPECT_EQ(str_of(b, "ruri"), b_->ruri());
  EXPECT_EQ(str_of(b, "name"), "robot-b");
  EXPECT_TRUE(b.get("reachable")->as_bool());
  EXPECT_GT(b.get("checked_ms")->to_double(), 0);
  EXPECT_NE(str_of(robot_in_list(dead_), "error").find("connect"), std::string::npos)
      << json::dump(robot_in_list(dead_));
  // B latched by someone else: A's list says so within a few polls.
  EXPECT_EQ(
      test::http(b_->port(), "POST", "/api/stop", "{}", {{"Authorization", "Bearer " + every_}})
          .status,
      200);
  EXPECT_TRUE(wait_status(b_->url(), "estop"));
  EXPECT_EQ(str_of(robot_in_list(c_->url()), "status"), "available");
}

// ESTOP all: every robot at once with the caller's token — here a USER's, as any role may stop.
TEST_F(RobotsViewTest, EstopAllSaysWhichRobotsConfirmedAndRecordsIt) {
  auto r = on_a("POST", "/api/robots/estop", "{\"reason\":\"aisle 3 blocked\"}", every_);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value v = parse(r.body);
  EXPECT_EQ(str_of(result_for(v, b_->url()), "result"), "confirmed") << r.body;
  EXPECT_EQ(str_of(result_for(v, c_->url()), "result"), "confirmed") << r.body;
  EXPECT_EQ(str_of(result_for(v, dead_), "result"), "unreachable") << r.body;
  EXPECT_EQ(str_of(result_for(v, silent_.url()), "result"), "timeout") << r.body;
  EXPECT_EQ(v.get("confirmed")->to_double(), 2);
  EXPECT_EQ(v.get("total")->to_double(), 4);
  EXPECT_FALSE(v.get("ok")->as_bool());
  EXPECT_TRUE(b_->latched(owner_));
  EXPECT_TRUE(c_->latched(owner_));
  EXPECT_FALSE(a_->latched(owner_));  // the relay stops the others; A's own ESTOP is /api/stop
  // Each robot recorded its own ESTOP by the operator; A recorded the relay and every result.
  std::string b_audit =
      test::http(b_->port(), "GET", "/api/audit?limit=50&event=ESTOP", "",
                 {{"Authorization", "Bearer " + token("owner-1", "owner", b_->ruri())}})
          .body;
  EXPECT_NE(b_audit.find("operator-1"), std::string::npos) << b_audit;
  auto audit = on_a("GET", "/api/audit?limit=10&event=ROBOTS_ESTOP", "", owner_);
  json::Value page = parse(audit.body);
  ASSERT_EQ(page.get("count")->to_double(), 1) << audit.body;
  const json::Value& rec = page.get("entries")->as_array()[0];
  EXPECT_EQ(str_of(rec, "outcome"), "failed") << audit.body;
  EXPECT_NE(audit.body.find("aisle 3 blocked"), std::string::npos) << audit.body;
  EXPECT_NE(audit.body.find("operator-1"), std::string::npos) << audit.body;
  EXPECT_NE(audit.body.find("\"" + dead_ + "\":\"unreachable\""), std::string::npos) << audit.body;
  EXPECT_NE(audit.body.find("\"" + b_->url() + "\":\"confirmed\""), std::string::npos)
      << audit.body;
}

TEST_F(RobotsViewTest, OneRobotIsStoppedAloneAndARobotThatRefusesTheTokenIsNamed) {
  auto r = on_a("POST", "/api/robots/estop", "{\"robots\":[\"" + c_->url() + "\"]}", every_);
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(parse(r.body).get("total")->to_double(), 1);
  EXPECT_TRUE(c_->latched(owner_));
  EXPECT_FALSE(b_->latched(owner_));
  // A token for A alone: B's issuers take it, its audience does not name B — B refuses and
  // stays as it was; the answer says so with B's own error code.
  const std::string only_a = token("operator-2", "owner", a_->ruri());
  r = on_a("POST", "/api/robots/estop", "{\"robots\":[\"" + b_->url() + "\"]}", only_a);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value b = result_for(parse(r.body), b_->url());
  EXPECT_EQ(str_of(b, "result"), "refused") << r.body;
  EXPECT_EQ(str_of(b, "error_code"), "AUTH_INVALID") << r.body;
  EXPECT_EQ(b.get("http_status")->to_double(), 401);
  EXPECT_FALSE(b_->latched(owner_));
}

// A token goes only where the configuration says: an address the request names that is not in
// dashboard.robots is refused before anything is sent, and nothing connects to it.
TEST_F(RobotsViewTest, ATokenIsNeverSentToAnAddressTheConfigurationDoesNotList) {
  SilentListener elsewhere;
  for (const std::string& body :
       {"{\"robots\":[\"" + elsewhere.url() + "\"]}",
        "{\"robots\":[\"" + b_->url() + "\",\"" + elsewhere.url() + "\"]}",
        "{\"robots\":[\"" + b_->url() + "/\"]}"}) {
    auto r = on_a("POST", "/api/robots/estop", body, every_);
    EXPECT_EQ(r.status, 400) << r.body;
    EXPECT_EQ(str_of(*parse(r.body).get("payload"), "error_code"), "SCHEMA_VALIDATION_FAILED");
    EXPECT_NE(r.body.find("nothing was sent"), std::string::npos) << r.body;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(elsewhere.accepted(), 0);
  EXPECT_FALSE(b_->latched(owner_));  // the list with one bad address sent nothing at all
  // Bad requests, each a 400 naming its field; no token, 401.
  for (const std::string& body :
       {std::string("{\"robots\":[]}"), std::string("{\"robots\":\"all\"}"),
        std::string("{\"robots\":[1]}"),
        std::string("{\"reason\":\"") + std::string(300, 'x') + "\"}",
        std::string("{\"reason\":5}")}) {
    auto r = on_a("POST", "/api/robots/estop", body, every_);
    EXPECT_EQ(r.status, 400) << body << " -> " << r.body;
  }
  EXPECT_EQ(on_a("POST", "/api/robots/estop", "[1,2]", every_).status, 400);
  EXPECT_EQ(on_a("POST", "/api/robots/estop", "{}", "").status, 401);
  EXPECT_EQ(on_a("POST", "/api/robots/estop", "{}", "not-a-token").status, 401);
  EXPECT_FALSE(b_->latched(owner_));
  EXPECT_FALSE(c_->latched(owner_));
}

// A node that lists no robot answers the view with itself alone, and refuses a relay in words.
TEST(RobotsViewAlone, ANodeWithoutRobotsListsItselfAndRefusesARelay) {
  test::TempDir tmp;
  const std::string secret = tmp.file("ops.secret");
  write_file(secret, "0123456789abcdef0123456789abcdef-robots-view-secret");
  Node a(tmp.path(), "robot-a", "0000000a", secret);
  auto key = jwt::SigningKey::from_file(secret, true);
  ASSERT_TRUE(key.ok());
  auto tok = jwt::issue(json::Object{{"iss", "ops-issuer"},
                                     {"sub", "op"},
                                     {"aud", a.ruri()},
                                     {"role", "guest"},
                                     {"iat", now_s() - 5},
                                     {"exp", now_s() + 600}},
                        *key);
  ASSERT_TRUE(tok.ok());
  Headers h{{"Authorization", "Bearer " + *tok}};
  auto r = test::http(a.port(), "GET", "/api/robots", "", h);
  ASSERT_EQ(r.status, 200) << r.body;
  json::Value v = parse(r.body);
  EXPECT_EQ(v.get("configured")->to_double(), 0);
  EXPECT_TRUE(v.get("robots")->as_array().empty());
  r = test::http(a.port(), "POST", "/api/robots/estop", "{}", h);
  EXPECT_EQ(r.status, 400);
  EXPECT_NE(r.body.find("dashboard.robots lists none"), std::string::npos) << r.body;
}

}  // namespace
}  // namespace rcan
