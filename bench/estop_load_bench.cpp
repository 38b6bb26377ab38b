// ESTOP under load: starts rcand on loopback, lets N clients stream authenticated COMMANDs over
// HTTP keep-alive, and meanwhile sends POST /api/stop (then RESUME) repeatedly, timing each
// ESTOP from the request to its answer. Prints throughput and ESTOP latency percentiles, and
// the node's own estop-to-driver figures from /metrics.
//
//   estop_load_bench [--rcand PATH] [--clients 64] [--stops 40] [--warmup-ms 1000]
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "rcan/crypto/jwt.h"
#include "rcan/errors.h"
#include "rcan/json.h"

using namespace rcan;
namespace fs = std::filesystem;

namespace {

double now_ms() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
int64_t wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

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
  // Returns the HTTP status (0 on failure); body in `body`.
  int post(const std::string& path, const std::string& body, const std::string& token,
           std::string* out = nullptr) {
    if (fd_ < 0) return 0;
    std::string req =
        "POST " + path + " HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + token +
        "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
        "\r\n\r\n" + body;
    if (send(fd_, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size()))
      return 0;
    return read_response(out);
  }
  int get(const std::string& path, std::string* out) {
    std::string req = "GET " + path + " HTTP/1.1\r\nHost: x\r\n\r\n";
    if (fd_ < 0 ||
        send(fd_, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size()))
      return 0;
    return read_response(out);
  }

 private:
  int read_response(std::string* out) {
    while (true) {
      size_t end = buf_.find("\r\n\r\n");
      if (end != std::string::npos) {
        size_t cl = 0;
        size_t p = buf_.find("Content-Length: ");
        if (p != std::string::npos && p < end)
          cl = std::strtoul(buf_.c_str() + p + 16, nullptr, 10);
        if (buf_.size() >= end + 4 + cl) {
          int status = std::atoi(buf_.c_str() + 9);
          if (out) *out = buf_.substr(end + 4, cl);
          buf_.erase(0, end + 4 + cl);
          return status;
        }
      }
      pollfd pf{fd_, POLLIN, 0};
      if (poll(&pf, 1, 10000) <= 0) return 0;
      char tmp[65536];
      ssize_t k = recv(fd_, tmp, sizeof tmp, 0);
      if (k <= 0) return 0;
      buf_.append(tmp, static_cast<size_t>(k));
    }
  }
  int fd_ = -1;
  std::string buf_;
};

std::string command_body(const std::string& action, json::Object params,
                         const std::string& type = "COMMAND") {
  json::Object payload{{"action", action}};
  for (auto& m : params) payload.set(m.first, m.second);
  return json::dump(json::Value(json::Object{{"version", "1.0.0"},
                                             {"message_id", new_uuid_v4()},
                                             {"type", type},
                                             {"timestamp_ms", wall_ms()},
                                             {"payload", payload}}));
}

double pct(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  size_t i = static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

}  // namespace

int main(int argc, char** argv) {
  std::string rcand = (fs::path(argv[0]).parent_path() / ".." / "bin" / "rcand").string();
  int clients = 64, stops = 40, warmup_ms = 1000;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--rcand")
      rcand = argv[i + 1];
    else if (a == "--clients")
      clients = std::atoi(argv[i + 1]);
    else if (a == "--stops")
      stops = std::atoi(argv[i + 1]);
    else if (a == "--warmup-ms")
      warmup_ms = std::atoi(argv[i + 1]);
  }
  char tmpl[] = "/tmp/rcand-bench-XXXXXX";
  std::string dir = mkdtemp(tmpl);
  int errpipe[2];
  if (pipe(errpipe) != 0) return 1;
  pid_t pid = fork();
  if (pid == 0) {
    dup2(errpipe[1], 2);
    close(errpipe[0]);
    execl(rcand.c_str(), rcand.c_str(), "--data-dir", (dir + "/node").c_str(), "--port", "0",
          "--log-level", "warn", static_cast<char*>(nullptr));
    _exit(127);
  }
  close(errpipe[1]);
  std::string err;
  uint16_t port = 0;
  double t_start = now_ms();
  while (!port && now_ms() - t_start < 30000) {
    char b[4096];
    pollfd pf{errpipe[0], POLLIN, 0};
    if (poll(&pf, 1, 100) > 0) {
      ssize_t k = read(errpipe[0], b, sizeof b);
      if (k <= 0) break;
      err.append(b, static_cast<size_t>(k));
    }
    size_t p = err.find("http://127.0.0.1:");
    if (p != std::string::npos) port = static_cast<uint16_t>(std::atoi(err.c_str() + p + 17));
  }
  if (!port) {
    std::fprintf(stderr, "rcand did not start:\n%s\n", err.c_str());
    return 1;
  }
  // Drain rcand's stderr in the background so it never blocks on a full pipe.
  std::thread drain([fd = errpipe[0]] {
    char b[4096];
    while (read(fd, b, sizeof b) > 0) {
    }
  });
  std::string ruri;
  {
    size_t p = err.find("simulated robot ");
    ruri = err.substr(p + 16, err.find(' ', p + 16) - p - 16);
  }
  auto key = jwt::SigningKey::from_file(dir + "/node/issuer/ed25519.seed");
  if (!key.ok()) return 1;
  auto token = [&](const std::string& sub) {
    int64_t now = wall_ms() / 1000;
    return *jwt::issue(json::Object{{"iss", "rcand-local"},
                                    {"sub", sub},
                                    {"aud", ruri},
                                    {"role", "creator"},
                                    {"scope", json::Array{"status", "control", "config"}},
                                    {"iat", now},
                                    {"exp", now + 3600}},
                       *key);
  };

  std::atomic<bool> stop{false};
  std::atomic<uint64_t> ok{0}, refused{0}, failed{0};
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c) {
    threads.emplace_back([&, c] {
      Conn conn(port);
      std::string tok = token("load-" + std::to_string(c));
      while (!stop.load(std::memory_order_relaxed)) {
        int s = conn.post("/rcan/v1/command",
                          command_body("move", {{"linear", 0.2}, {"duration_ms", 100}}), tok);
        if (s == 200)
          ok++;
        else if (s == 423 || s == 429)
          refused++;
        else {
          failed++;
          if (s == 0) break;
        }
      }
    });
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(warmup_ms));
  std::string admin = token("bench-operator");
  std::vector<double> lat;
  uint64_t ok0 = ok.load();
  double t0 = now_ms();
  for (int i = 0; i < stops; ++i) {
    Conn c(port);
    double s = now_ms();
    int st = c.post("/api/stop", "{\"reason\":\"bench\"}", admin);
    double e = now_ms();
    if (st == 200) lat.push_back(e - s);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::string body = "{\"version\":\"1.0.0\",\"type\":\"SAFETY\",\"message_id\":\"" +
                       new_uuid_v4() + "\",\"timestamp_ms\":" + std::to_string(wall_ms()) +
                       ",\"payload\":{\"safety_event\":\"RESUME\"}}";
    Conn r2(port);
    r2.post("/rcan/v1/command", body, admin);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  double elapsed = (now_ms() - t0) / 1000.0;
  uint64_t done = ok.load() - ok0;
  std::string metrics;
  {
    Conn m(port);
    m.get("/metrics", &metrics);
  }
  stop = true;
  for (auto& t : threads) t.join();
  kill(pid, SIGTERM);
  int status = 0;
  waitpid(pid, &status, 0);
  drain.join();
  fs::remove_all(dir);

  std::printf("estop_load_bench: %d clients streaming COMMANDs over HTTP keep-alive\n", clients);
  std::printf("  commands accepted: %.0f/s (refused while latched: %llu, failed: %llu)\n",
              static_cast<double>(done) / elapsed, static_cast<unsigned long long>(refused.load()),
              static_cast<unsigned long long>(failed.load()));
  std::printf("  POST /api/stop answered: %zu of %d\n", lat.size(), stops);
  std::printf("  ESTOP request→answer ms: p50 %.2f  p99 %.2f  max %.2f\n", pct(lat, 0.5),
              pct(lat, 0.99), lat.empty() ? 0.0 : *std::max_element(lat.begin(), lat.end()));
  // The node's own timer: estop() call → driver stop (histogram, microseconds).
  for (const char* name : {"rcan_pipeline_stage_seconds_sum{stage=\"estop_to_driver\"}",
                           "rcan_pipeline_stage_seconds_count{stage=\"estop_to_driver\"}"}) {
    size_t p = metrics.find(name);
    if (p != std::string::npos)
      std::printf("  node %s\n", metrics.substr(p, metrics.find('\n', p) - p).c_str());
  }
  return lat.size() == static_cast<size_t>(stops) ? 0 : 1;
}
