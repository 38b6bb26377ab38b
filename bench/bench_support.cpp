// Shared pieces of the programs that drive a real rcand (bench_support.h).
// GCC 12 at -O3 reports -Wnull-dereference from inside Asio and libstdc++ once inlined here
// (middle-end false positives, as in src/transport/http_server.cpp). Off for this file only.
#pragma GCC diagnostic ignored "-Wnull-dereference"

#include "bench_support.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "config/config.h"
#include "rcan/crypto/jwt.h"
#include "rcan/json.h"

namespace rcan::bench {

namespace fs = std::filesystem;
namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = boost::beast::http;
using tcp = asio::ip::tcp;

int64_t mono_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
int64_t wall_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string fast_uuid() {
  thread_local std::mt19937_64 rng{std::random_device{}()};
  uint64_t a = rng(), b = rng();
  a = (a & 0xffffffffffff0fffULL) | 0x0000000000004000ULL;
  b = (b & 0x3fffffffffffffffULL) | 0x8000000000000000ULL;
  char s[40];
  std::snprintf(s, sizeof s, "%08x-%04x-%04x-%04x-%012llx", static_cast<unsigned>(a >> 32),
                static_cast<unsigned>((a >> 16) & 0xffff), static_cast<unsigned>(a & 0xffff),
                static_cast<unsigned>(b >> 48),
                static_cast<unsigned long long>(b & 0xffffffffffffULL));
  return s;
}

uint16_t free_port() {
  asio::io_context io;
  tcp::acceptor a(io, tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  return a.local_endpoint().port();
}

double pct(const std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  size_t i = static_cast<size_t>(std::ceil(q * static_cast<double>(v.size())));
  if (i > 0) --i;
  return v[std::min(i, v.size() - 1)];
}

// ---- processes -------------------------------------------------------------------------------

ProcStat proc_stat(pid_t pid) {
  ProcStat s;
  std::ifstream st("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  auto field = [&](const char* name, long& out) {
    size_t n = std::char_traits<char>::length(name);
    if (line.compare(0, n, name) == 0) out = std::atol(line.c_str() + n);
  };
  while (std::getline(st, line)) {
    field("VmRSS:", s.rss_kb);
    field("VmHWM:", s.hwm_kb);
    field("RssAnon:", s.rss_anon_kb);
    field("RssFile:", s.rss_file_kb);
    field("Threads:", s.threads);
  }
  std::ifstream sf("/proc/" + std::to_string(pid) + "/stat");
  std::string all((std::istreambuf_iterator<char>(sf)), std::istreambuf_iterator<char>());
  size_t p = all.rfind(')');
  if (p != std::string::npos) {
    std::istringstream is(all.substr(p + 2));
    std::string f;
    unsigned long ut = 0, stt = 0;
    for (int i = 3; i <= 15 && is >> f; ++i) {
      if (i == 14) ut = std::stoul(f);
      if (i == 15) stt = std::stoul(f);
    }
    s.cpu_s = static_cast<double>(ut + stt) / static_cast<double>(sysconf(_SC_CLK_TCK));
  }
  return s;
}

int count_fds(pid_t pid) {
  std::string path = "/proc/" + std::to_string(pid) + "/fd";
  DIR* d = opendir(path.c_str());
  if (!d) return -1;
  int n = 0;
  while (dirent* e = readdir(d))
    if (e->d_name[0] != '.') ++n;
  closedir(d);
  return n;
}

std::string thread_names(pid_t pid) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it("/proc/" + std::to_string(pid) + "/task", ec), end;
       !ec && it != end; it.increment(ec)) {
    std::ifstream f(it->path() / "comm");
    std::string name;
    if (std::getline(f, name)) names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : " ") + n;
  return out;
}

uint64_t dir_bytes(const std::string& dir) {
  std::error_code ec;
  uint64_t total = 0;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code e2;
    if (it->is_regular_file(e2)) {
      auto sz = it->file_size(e2);
      if (!e2) total += sz;
    }
  }
  return total;
}

namespace {
// The length of `path` without its trailing zero bytes, assuming no zero byte before them.
uint64_t data_length(const std::string& path) {
  int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  struct stat st {};
  uint64_t len = 0;
  if (fstat(fd, &st) == 0 && st.st_size > 0) {
    auto zero_at = [&](uint64_t off) {
      char ch = 1;
      return pread(fd, &ch, 1, static_cast<off_t>(off)) == 1 && ch == 0;
    };
    uint64_t lo = 0, hi = static_cast<uint64_t>(st.st_size);  // the first zero is in [lo, hi]
    while (lo < hi) {
      uint64_t mid = lo + (hi - lo) / 2;
      if (zero_at(mid))
        hi = mid;
      else
        lo = mid + 1;
    }
    len = lo;
  }
  close(fd);
  return len;
}
}  // namespace

uint64_t dir_data_bytes(const std::string& dir) {
  std::error_code ec;
  uint64_t total = 0;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code e2;
    if (it->is_regular_file(e2)) total += data_length(it->path().string());
  }
  return total;
}

Child::Child(std::vector<std::string> argv, std::string keep) : keep_(std::move(keep)) {
  int p[2];
  if (pipe2(p, O_CLOEXEC) != 0) return;
  t_spawn_ = mono_us();
  pid_ = fork();
  if (pid_ == 0) {
    dup2(p[1], 2);
    int devnull = open("/dev/null", O_WRONLY);
    if (devnull >= 0) dup2(devnull, 1);
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    execv(args[0], args.data());
    _exit(127);
  }
  close(p[1]);
  fd_ = p[0];
  drain_ = std::thread([this] {
    std::string pending;
    char b[8192];
    for (;;) {
      ssize_t k = read(fd_, b, sizeof b);
      if (k <= 0) break;
      pending.append(b, static_cast<size_t>(k));
      size_t nl;
      while ((nl = pending.find('\n')) != std::string::npos) {
        std::string line = pending.substr(0, nl);
        pending.erase(0, nl + 1);
        std::lock_guard<std::mutex> l(mu_);
        if (head_.size() < 65536) head_ += line + "\n";
        if (!keep_.empty() && line.find(keep_) != std::string::npos) kept_.push_back(line);
      }
    }
  });
}

Child::~Child() { stop(); }

bool Child::alive() const { return pid_ > 0 && waitpid(pid_, nullptr, WNOHANG) == 0; }

std::string Child::head() {
  std::lock_guard<std::mutex> l(mu_);
  return head_;
}

std::vector<std::string> Child::take_kept() {
  std::lock_guard<std::mutex> l(mu_);
  return std::exchange(kept_, {});
}

int Child::stop() {
  int st = -1;
  if (pid_ > 0) {
    kill(pid_, SIGTERM);
    waitpid(pid_, &st, 0);
    pid_ = -1;
  }
  if (drain_.joinable()) drain_.join();
  if (fd_ >= 0) close(fd_);
  fd_ = -1;
  return st;
}

int sync_http(uint16_t port, http::verb verb, const std::string& target, const std::string& body,
              const std::string& token, std::string* out) {
  try {
    asio::io_context io;
    beast::tcp_stream s(io);
    s.expires_after(std::chrono::seconds(10));
    s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
    http::request<http::string_body> req{verb, target, 11};
    req.set(http::field::host, "127.0.0.1");
    if (!token.empty()) req.set(http::field::authorization, "Bearer " + token);
    if (verb == http::verb::post) {
      req.set(http::field::content_type, "application/json");
      req.body() = body;
      req.prepare_payload();
    }
    http::write(s, req);
    beast::flat_buffer buf;
    http::response<http::string_body> res;
    http::read(s, buf, res);
    if (out) *out = res.body();
    beast::error_code ec;
    s.socket().shutdown(tcp::socket::shutdown_both, ec);
    return static_cast<int>(res.result_int());
  } catch (const std::exception&) {
    return 0;
  }
}

double wait_ready(Child& c, uint16_t port, double timeout_ms) {
  for (;;) {
    if (sync_http(port, http::verb::get, "/healthz", "", "") == 200)
      return static_cast<double>(mono_us() - c.spawned_us()) / 1000.0;
    if (!c.alive() || static_cast<double>(mono_us() - c.spawned_us()) / 1000.0 > timeout_ms)
      return -1;
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
}

// ---- the node under test --------------------------------------------------------------------

std::string token_for(const std::string& seed_file, const std::string& iss, const std::string& ruri,
                      const std::string& sub, int64_t lifetime_s) {
  auto key = jwt::SigningKey::from_file(seed_file);
  if (!key.ok()) return {};
  int64_t now = wall_ms() / 1000;
  auto t = jwt::issue(json::Object{{"iss", iss},
                                   {"sub", sub},
                                   {"aud", ruri},
                                   {"role", "creator"},
                                   {"scope", json::Array{"status", "control", "config", "chat"}},
                                   {"iat", now},
                                   {"exp", now + lifetime_s}},
                      *key);
  return t.ok() ? *t : std::string();
}

bool start_node(Node& n, const std::string& rcand, const std::vector<std::string>& extra,
                const std::string& keep) {
  n.port = free_port();
  std::vector<std::string> argv{
      rcand, "--data-dir", n.dir, "--port", std::to_string(n.port), "--log-level", "info"};
  argv.insert(argv.end(), extra.begin(), extra.end());
  n.child = std::make_unique<Child>(argv, keep);
  n.ready_ms = wait_ready(*n.child, n.port);
  if (n.ready_ms < 0) {
    std::fprintf(stderr, "rcand did not start:\n%s\n", n.child->head().c_str());
    return false;
  }
  // The "listening" log line (which names the RURI) may come just after the first answer.
  for (int i = 0; n.ruri.empty() && i < 5000; ++i) {
    std::string head = n.child->head();
    size_t p = head.find("\"ruri\":\"");
    if (p != std::string::npos) {
      n.ruri = head.substr(p + 8, head.find('"', p + 8) - p - 8);
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  if (n.ruri.empty())
    std::fprintf(stderr, "rcand did not log its RURI:\n%s\n", n.child->head().c_str());
  return !n.ruri.empty();
}

void settle(pid_t pid, int max_ms) {
  int64_t until = mono_us() + int64_t{max_ms} * 1000;
  while (mono_us() < until) {
    double c0 = proc_stat(pid).cpu_s;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    if (proc_stat(pid).cpu_s - c0 < 0.010) return;
  }
}

std::string default_yaml_for(const std::string& data_dir) {
  std::string device;
  {
    std::ifstream d(data_dir + "/device_id");
    std::getline(d, device);
  }
  std::string yaml(config::default_config_yaml());
  const std::string key = "{device_id}";
  size_t p = yaml.find(key);
  if (p != std::string::npos) yaml.replace(p, key.size(), device);
  return yaml;
}

// ---- answers --------------------------------------------------------------------------------

namespace {
const json::Value* str_member(const json::Value* o, const char* name) {
  if (!o || !o->is_object()) return nullptr;
  const json::Value* v = o->get(name);
  return v && v->is_string() ? v : nullptr;
}
}  // namespace

bool check_node_ack(int status, const std::string& body, const std::string& id, std::string& why) {
  auto v = json::parse(body, json::ParseOptions{});
  if (!v.ok() || !v->is_object()) {
    why = "status " + std::to_string(status) + ", body not a JSON object: " + body.substr(0, 200);
    return false;
  }
  const json::Value* t = str_member(&*v, "type");
  const json::Value* rt = str_member(&*v, "reply_to");
  const json::Value* pl = v->get("payload");
  if (status == 200 && t && t->as_string() == "ACK" && rt && rt->as_string() == id && pl &&
      pl->is_object()) {
    const json::Value* res = pl->get("result");
    if (str_member(pl, "command") && res && !res->is_null()) return true;
  }
  why = "status " + std::to_string(status) + ": " + body.substr(0, 300);
  return false;
}

bool check_node_error(int status, const std::string& body, const std::string& id, int want_status,
                      const std::string& error_code, const std::string& reason, std::string& why) {
  auto v = json::parse(body, json::ParseOptions{});
  bool good = v.ok() && v->is_object() && (want_status == 0 || status == want_status);
  if (good) {
    const json::Value* t = str_member(&*v, "type");
    const json::Value* rt = str_member(&*v, "reply_to");
    const json::Value* pl = v->get("payload");
    const json::Value* code = str_member(pl, "error_code");
    const json::Value* rs = str_member(pl, "reason");
    good = t && t->as_string() == "ERROR" && rt && rt->as_string() == id &&
           (error_code.empty() || (code && code->as_string() == error_code)) &&
           (reason.empty() || (rs && rs->as_string() == reason));
  }
  if (!good)
    why = "expected " + std::to_string(want_status) + " " + error_code + "/" + reason +
          ", got status " + std::to_string(status) + ": " + body.substr(0, 300);
  return good;
}

}  // namespace rcan::bench
