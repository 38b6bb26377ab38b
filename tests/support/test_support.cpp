#include "test_support.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "rcan/audit/secret.h"
#include "rcan/crypto/keys.h"

extern char** environ;

namespace rcan::test {

namespace {

// The parent's environment with `extra` ("NAME=value", replacing a variable of the same name)
// (prepared before fork: no allocation in the child).
std::vector<std::string> child_env(const std::vector<std::string>& extra) {
  auto name_of = [](const std::string& e) { return e.substr(0, e.find('=')); };
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e) {
    std::string v(*e);
    bool replaced = false;
    for (const auto& x : extra) replaced = replaced || name_of(x) == name_of(v);
    if (!replaced) env.push_back(std::move(v));
  }
  for (const auto& e : extra) env.push_back(e);
  return env;
}

// In the forked child: exec argv[0] with `env`; exits 127 when exec fails.
[[noreturn]] void exec_child(const std::vector<std::string>& argv, std::vector<std::string>& env) {
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  std::vector<char*> envp;
  for (auto& e : env) envp.push_back(e.data());
  envp.push_back(nullptr);
  execve(args[0], args.data(), envp.data());
  _exit(127);
}

}  // namespace

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    ADD_FAILURE() << "cannot read " << path;
    return {};
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

json::Value load_vector(const std::string& name) {
  std::string text = read_file(std::string(RCAN_VECTORS_DIR) + "/" + name);
  json::ParseOptions opts;
  opts.max_bytes = 64u << 20;
  opts.max_depth = 256;
  auto v = json::parse(text, opts);
  if (!v.ok()) {
    ADD_FAILURE() << "vector " << name << " does not parse: " << v.error().message;
    return {};
  }
  return std::move(v).value();
}

Bytes hex(std::string_view h) {
  auto b = from_hex(h);
  if (!b) {
    ADD_FAILURE() << "bad hex in test data";
    return {};
  }
  return *b;
}

TempDir::TempDir() {
  const char* base = std::getenv("TMPDIR");
  std::string tmpl = std::string(base && *base ? base : "/tmp") + "/rcan-test-XXXXXX";
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  if (mkdtemp(buf.data()) == nullptr) {
    ADD_FAILURE() << "mkdtemp failed: " << std::strerror(errno);
  }
  path_ = buf.data();
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

RunResult run(const std::vector<std::string>& argv, const std::string& stdin_data,
              const std::vector<std::string>& extra_env) {
  RunResult r;
  int in_pipe[2], out_pipe[2], err_pipe[2];
  if (pipe(in_pipe) != 0 || pipe(out_pipe) != 0 || pipe(err_pipe) != 0) {
    ADD_FAILURE() << "pipe failed";
    return r;
  }
  std::vector<std::string> env_strings = child_env(extra_env);
  pid_t pid = fork();
  if (pid == 0) {
    dup2(in_pipe[0], 0);
    dup2(out_pipe[1], 1);
    dup2(err_pipe[1], 2);
    for (int fd : {in_pipe[0], in_pipe[1], out_pipe[0], out_pipe[1], err_pipe[0], err_pipe[1]})
      close(fd);
    exec_child(argv, env_strings);
  }
  close(in_pipe[0]);
  close(out_pipe[1]);
  close(err_pipe[1]);
  // Feed stdin and drain both outputs without deadlocking on full pipes.
  size_t written = 0;
  int in_fd = in_pipe[1];
  if (stdin_data.empty()) {
    close(in_fd);
    in_fd = -1;
  } else {
    fcntl(in_fd, F_SETFL, O_NONBLOCK);
  }
  bool out_open = true, err_open = true;
  char buf[65536];
  while (out_open || err_open || in_fd >= 0) {
    pollfd fds[3];
    int n = 0;
    int out_i = -1, err_i = -1, in_i = -1;
    if (out_open) {
      fds[n] = {out_pipe[0], POLLIN, 0};
      out_i = n++;
    }
    if (err_open) {
      fds[n] = {err_pipe[0], POLLIN, 0};
      err_i = n++;
    }
    if (in_fd >= 0) {
      fds[n] = {in_fd, POLLOUT, 0};
      in_i = n++;
    }
    // Silence is not a hang: a CLI may wait its own --timeout-ms (ctest's TIMEOUT ends a hang).
    if (poll(fds, static_cast<nfds_t>(n), 300000) <= 0) break;
    if (out_i >= 0 && fds[out_i].revents) {
      ssize_t k = read(out_pipe[0], buf, sizeof buf);
      if (k <= 0)
        out_open = false;
      else
        r.out.append(buf, static_cast<size_t>(k));
    }
    if (err_i >= 0 && fds[err_i].revents) {
      ssize_t k = read(err_pipe[0], buf, sizeof buf);
      if (k <= 0)
        err_open = false;
      else
        r.err.append(buf, static_cast<size_t>(k));
    }
    if (in_i >= 0 && fds[in_i].revents) {
      ssize_t k = write(in_fd, stdin_data.data() + written, stdin_data.size() - written);
      if (k > 0) written += static_cast<size_t>(k);
      if (k < 0 || written == stdin_data.size()) {
        close(in_fd);
        in_fd = -1;
      }
    }
  }
  if (in_fd >= 0) close(in_fd);
  close(out_pipe[0]);
  close(err_pipe[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

RunResult run_cli(const std::vector<std::string>& args, const std::string& stdin_data,
                  const std::vector<std::string>& extra_env) {
  std::vector<std::string> argv;
#ifdef RCAN_TEST_EMULATOR
  // A cross build's programs run under the emulator (qemu-user; cmake/toolchain-arm64.cmake),
  // the CLI a test starts included: its words are separated by '|'.
  std::string_view emu = RCAN_TEST_EMULATOR;
  for (size_t at = 0; at <= emu.size();) {
    size_t end = std::min(emu.find('|', at), emu.size());
    if (end > at) argv.emplace_back(emu.substr(at, end - at));
    at = end + 1;
  }
#endif
  argv.push_back(RCAN_CLI_PATH);
  argv.insert(argv.end(), args.begin(), args.end());
  return run(argv, stdin_data, extra_env);
}

bool generate_robot_keys(const std::string& dir) {
  auto k = keys::generate();
  if (!k.ok()) {
    ADD_FAILURE() << "robot keys: " << k.error().message;
    return false;
  }
  Status s = keys::write_dir(dir, *k);
  if (!s.ok()) ADD_FAILURE() << "robot keys in " << dir << ": " << s.error().message;
  return s.ok();
}

bool create_audit_secret(const std::string& path) {
  Status s = audit::create_secret_file(path);
  if (!s.ok()) ADD_FAILURE() << "audit secret " << path << ": " << s.error().message;
  return s.ok();
}

bool create_token_issuer(const std::string& dir) {
  auto made = keys::ensure_issuer_dir(dir);
  if (!made.ok()) ADD_FAILURE() << "token issuer in " << dir << ": " << made.error().message;
  return made.ok();
}

bool eventually(const std::function<bool()>& pred, int timeout_ms) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return pred();
}

uint16_t free_port() {
  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  uint16_t port = 0;
  if (fd >= 0 && ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
    port = ntohs(a.sin_port);
  if (fd >= 0) ::close(fd);
  return port;
}

LoopbackSocket loopback_socket(uint16_t port, const char* source, int rcvbuf) {
  LoopbackSocket s;
  s.fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (s.fd < 0) return s;
  if (rcvbuf > 0) ::setsockopt(s.fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
  if (source != nullptr) {
    sockaddr_in src{};
    src.sin_family = AF_INET;
    ::inet_pton(AF_INET, source, &src.sin_addr);
    if (::bind(s.fd, reinterpret_cast<sockaddr*>(&src), sizeof src) != 0) return s;
  }
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  s.connected = ::connect(s.fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
  return s;
}

}  // namespace rcan::test

// ---------------------------------------------------------------------------------------------
// Processes, HTTP and WebSocket clients.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>

#include <chrono>
#include <random>
#include <thread>

namespace rcan::test {
namespace {

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

int connect_loopback(uint16_t port) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    close(fd);
    return -1;
  }
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

bool write_all(int fd, const std::string& s) {
  size_t off = 0;
  while (off < s.size()) {
    ssize_t k = ::send(fd, s.data() + off, s.size() - off, MSG_NOSIGNAL);
    if (k <= 0) return false;
    off += static_cast<size_t>(k);
  }
  return true;
}

// Reads more bytes into buf; false on close/error/timeout.
bool read_more(int fd, std::string& buf, int64_t deadline) {
  int64_t left = deadline - now_ms();
  if (left <= 0) return false;
  pollfd p{fd, POLLIN, 0};
  if (poll(&p, 1, static_cast<int>(left)) <= 0) return false;
  char tmp[65536];
  ssize_t k = ::recv(fd, tmp, sizeof tmp, 0);
  if (k <= 0) return false;
  buf.append(tmp, static_cast<size_t>(k));
  return true;
}

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Parses one response from buf (consuming it); false when incomplete.
bool parse_response(std::string& buf, HttpReply& r, bool eof) {
  size_t end = buf.find("\r\n\r\n");
  if (end == std::string::npos) return false;
  std::istringstream head(buf.substr(0, end));
  std::string line;
  std::getline(head, line);
  if (line.size() < 12) return false;
  r.status = std::atoi(line.c_str() + 9);
  r.headers.clear();
  size_t content_length = std::string::npos;
  bool chunked = false;
  while (std::getline(head, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    size_t c = line.find(':');
    if (c == std::string::npos) continue;
    std::string name = lower(line.substr(0, c));
    std::string value = line.substr(c + 1);
    while (!value.empty() && value.front() == ' ') value.erase(0, 1);
    if (name == "content-length") content_length = std::stoul(value);
    if (name == "transfer-encoding" && lower(value).find("chunked") != std::string::npos)
      chunked = true;
    r.headers.emplace_back(name, value);
  }
  size_t body_start = end + 4;
  if (chunked) {
    std::string body;
    size_t pos = body_start;
    while (true) {
      size_t le = buf.find("\r\n", pos);
      if (le == std::string::npos) return false;
      size_t n = std::stoul(buf.substr(pos, le - pos), nullptr, 16);
      if (buf.size() < le + 2 + n + 2) return false;
      if (n == 0) {
        buf.erase(0, le + 4);
        r.body = body;
        return true;
      }
      body.append(buf, le + 2, n);
      pos = le + 2 + n + 2;
    }
  }
  if (content_length == std::string::npos) {
    if (r.status == 101 || r.status == 204 || r.status == 304) {
      r.body.clear();
      buf.erase(0, body_start);
      return true;
    }
    if (!eof) return false;
    r.body = buf.substr(body_start);
    buf.clear();
    return true;
  }
  if (buf.size() < body_start + content_length) return false;
  r.body = buf.substr(body_start, content_length);
  buf.erase(0, body_start + content_length);
  return true;
}

std::string build_request(const std::string& method, const std::string& target,
                          const std::string& body,
                          const std::vector<std::pair<std::string, std::string>>& headers,
                          bool close_conn) {
  std::string req = method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\n";
  bool has_ct = false;
  for (const auto& h : headers) {
    req += h.first + ": " + h.second + "\r\n";
    if (lower(h.first) == "content-type") has_ct = true;
  }
  if (!body.empty() && !has_ct) req += "Content-Type: application/json\r\n";
  if (!body.empty() || method == "POST" || method == "PUT" || method == "DELETE")
    req += "Content-Length: " + std::to_string(body.size()) + "\r\n";
  if (close_conn) req += "Connection: close\r\n";
  req += "\r\n" + body;
  return req;
}

}  // namespace

Process::~Process() {
  if (pid_ > 0 && running()) stop(SIGKILL, 5000);
  if (err_fd_ >= 0) {
    for (int i = 0; i < 256; ++i) {  // whatever the child wrote before it exited
      size_t before = err_.size();
      drain(10);
      if (err_.size() == before) break;
    }
    close(err_fd_);
  }
  // In the sanitizer trees a daemon's ASan/LSan/TSan report goes to the run's log directory
  // (scripts/sanitized-ctest.sh), but UBSan, inside ASan's runtime, always writes to stderr:
  // a report there fails the test that started the process.
  if (err_.find(": runtime error: ") != std::string::npos)
    ADD_FAILURE() << "UndefinedBehaviorSanitizer report in a child process's stderr:\n" << err_;
}

bool Process::start(const std::vector<std::string>& argv,
                    const std::vector<std::string>& extra_env) {
  int pipefd[2];
  if (pipe2(pipefd, O_CLOEXEC) != 0) return false;
  std::vector<std::string> env_strings = child_env(extra_env);
  pid_ = fork();
  if (pid_ == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);  // never outlive a crashed test
    int devnull = open("/dev/null", O_RDWR);
    dup2(devnull, 0);
    dup2(devnull, 1);
    dup2(pipefd[1], 2);
    exec_child(argv, env_strings);
  }
  close(pipefd[1]);
  err_fd_ = pipefd[0];
  fcntl(err_fd_, F_SETFL, O_NONBLOCK);
  return pid_ > 0;
}

void Process::drain(int timeout_ms) {
  int64_t deadline = now_ms() + timeout_ms;
  while (err_fd_ >= 0) {
    pollfd p{err_fd_, POLLIN, 0};
    int left = static_cast<int>(std::max<int64_t>(0, deadline - now_ms()));
    if (poll(&p, 1, left) <= 0) return;
    char buf[65536];
    ssize_t k = read(err_fd_, buf, sizeof buf);
    if (k <= 0) return;
    err_.append(buf, static_cast<size_t>(k));
    if (now_ms() >= deadline) return;
  }
}

std::optional<std::string> Process::wait_for_line(const std::string& needle, int timeout_ms) {
  int64_t deadline = now_ms() + timeout_ms;
  while (true) {
    size_t pos = err_.find(needle, scanned_ > needle.size() ? 0 : 0);
    if (pos != std::string::npos) {
      size_t b = err_.rfind('\n', pos);
      b = b == std::string::npos ? 0 : b + 1;
      size_t e = err_.find('\n', pos);
      if (e != std::string::npos) return err_.substr(b, e - b);
    }
    if (now_ms() >= deadline || !running()) {
      drain(50);
      pos = err_.find(needle);
      if (pos != std::string::npos) {
        size_t b = err_.rfind('\n', pos);
        b = b == std::string::npos ? 0 : b + 1;
        size_t e = err_.find('\n', pos);
        return err_.substr(b, e == std::string::npos ? std::string::npos : e - b);
      }
      return std::nullopt;
    }
    drain(50);
  }
}

bool Process::running() {
  if (pid_ <= 0) return false;
  if (exit_status_ != -2) return false;
  int status = 0;
  pid_t r = waitpid(pid_, &status, WNOHANG);
  if (r == 0) return true;
  exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return false;
}

int Process::stop(int sig, int timeout_ms) {
  if (pid_ <= 0) return -1;
  if (running()) kill(pid_, sig);
  int64_t deadline = now_ms() + timeout_ms;
  while (running() && now_ms() < deadline) {
    drain(20);
  }
  if (running()) {
    kill(pid_, SIGKILL);
    while (running()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    return -1;
  }
  drain(20);
  return exit_status_;
}

HttpReply http(uint16_t port, const std::string& method, const std::string& target,
               const std::string& body,
               const std::vector<std::pair<std::string, std::string>> headers, int timeout_ms) {
  HttpReply r;
  int fd = connect_loopback(port);
  if (fd < 0) return r;
  int64_t deadline = now_ms() + timeout_ms;
  if (write_all(fd, build_request(method, target, body, headers, true))) {
    std::string buf;
    bool eof = false;
    while (!parse_response(buf, r, eof)) {
      if (eof) {
        r.status = 0;
        break;
      }
      if (!read_more(fd, buf, deadline)) eof = true;
    }
  }
  close(fd);
  return r;
}

HttpClient::HttpClient(uint16_t port) { fd_ = connect_loopback(port); }
HttpClient::~HttpClient() {
  if (fd_ >= 0) close(fd_);
}

HttpReply HttpClient::request(const std::string& method, const std::string& target,
                              const std::string& body,
                              const std::vector<std::pair<std::string, std::string>>& headers,
                              int timeout_ms) {
  HttpReply r;
  if (fd_ < 0) return r;
  int64_t deadline = now_ms() + timeout_ms;
  if (!write_all(fd_, build_request(method, target, body, headers, false))) return r;
  bool eof = false;
  while (!parse_response(buf_, r, eof)) {
    if (eof) {
      r.status = 0;
      close(fd_);
      fd_ = -1;
      return r;
    }
    if (!read_more(fd_, buf_, deadline)) eof = true;
  }
  return r;
}

std::string HttpClient::raw(const std::string& bytes, int timeout_ms) {
  if (fd_ < 0) return {};
  write_all(fd_, bytes);
  int64_t deadline = now_ms() + timeout_ms;
  std::string out = buf_;
  buf_.clear();
  while (read_more(fd_, out, deadline)) {
  }
  return out;
}

WsClient::~WsClient() {
  if (fd_ >= 0) close(fd_);
}

int WsClient::connect(uint16_t port, const std::string& path,
                      const std::vector<std::pair<std::string, std::string>>& headers) {
  fd_ = connect_loopback(port);
  if (fd_ < 0) return 0;
  std::string req = "GET " + path +
                    " HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
  for (const auto& h : headers) req += h.first + ": " + h.second + "\r\n";
  req += "\r\n";
  if (!write_all(fd_, req)) return 0;
  HttpReply r;
  int64_t deadline = now_ms() + 5000;
  bool eof = false;
  while (!parse_response(buf_, r, eof)) {
    if (eof) return 0;
    if (!read_more(fd_, buf_, deadline)) eof = true;
  }
  return r.status;
}

bool WsClient::send_frame(uint8_t opcode, const std::string& payload) {
  if (fd_ < 0) return false;
  std::string f;
  f.push_back(static_cast<char>(0x80 | opcode));
  size_t n = payload.size();
  if (n < 126) {
    f.push_back(static_cast<char>(0x80 | n));
  } else if (n < 65536) {
    f.push_back(static_cast<char>(0x80 | 126));
    f.push_back(static_cast<char>(n >> 8));
    f.push_back(static_cast<char>(n & 0xff));
  } else {
    f.push_back(static_cast<char>(0x80 | 127));
    for (int i = 7; i >= 0; --i) f.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
  }
  static std::mt19937 rng(12345);
  uint8_t mask[4];
  for (auto& m : mask) m = static_cast<uint8_t>(rng());
  f.append(reinterpret_cast<char*>(mask), 4);
  for (size_t i = 0; i < n; ++i) f.push_back(static_cast<char>(payload[i] ^ mask[i % 4]));
  return write_all(fd_, f);
}

bool WsClient::send_text(const std::string& text) { return send_frame(0x1, text); }
bool WsClient::send_binary(const std::string& data) { return send_frame(0x2, data); }

std::optional<std::string> WsClient::recv_text(int timeout_ms) {
  int64_t deadline = now_ms() + timeout_ms;
  while (true) {
    if (buf_.size() >= 2) {
      uint8_t b0 = static_cast<uint8_t>(buf_[0]), b1 = static_cast<uint8_t>(buf_[1]);
      size_t len = b1 & 0x7f, hdr = 2;
      if (len == 126) {
        if (buf_.size() < 4) goto more;
        len = (static_cast<uint8_t>(buf_[2]) << 8) | static_cast<uint8_t>(buf_[3]);
        hdr = 4;
      } else if (len == 127) {
        if (buf_.size() < 10) goto more;
        len = 0;
        for (int i = 0; i < 8; ++i)
          len = (len << 8) | static_cast<uint8_t>(buf_[2 + static_cast<size_t>(i)]);
        hdr = 10;
      }
      if (buf_.size() >= hdr + len) {
        std::string payload = buf_.substr(hdr, len);
        buf_.erase(0, hdr + len);
        uint8_t op = b0 & 0x0f;
        if (op == 0x1) return payload;
        if (op == 0x8) {
          close_code_ = payload.size() >= 2 ? (static_cast<uint8_t>(payload[0]) << 8) |
                                                  static_cast<uint8_t>(payload[1])
                                            : 1005;
          return std::nullopt;
        }
        if (op == 0x9) send_frame(0xA, payload);
        continue;
      }
    }
  more:
    if (!read_more(fd_, buf_, deadline)) {
      if (now_ms() < deadline && close_code_ == 0) close_code_ = 1006;
      return std::nullopt;
    }
  }
}

}  // namespace rcan::test
