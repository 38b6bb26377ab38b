// Shared helpers for the test programs: vector files, temp dirs, child processes.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "rcan/encoding.h"
#include "rcan/json.h"

namespace rcan::test {

// Whole file as bytes; fails the current test (and returns "") when unreadable.
std::string read_file(const std::string& path);
// Parses tests/vectors/<name> (copied from the shared vector set; see tests/vectors/README.md).
json::Value load_vector(const std::string& name);
// Hex string to bytes; fails the current test on bad hex.
Bytes hex(std::string_view h);

// A fresh directory under $TMPDIR, removed with its contents on destruction.
// The value of the metric line `name value` in a Prometheus text body (-1 when absent).
inline double metric_value(const std::string& body, const std::string& name) {
  size_t at = 0;
  while ((at = body.find(name, at)) != std::string::npos) {
    bool line_start = at == 0 || body[at - 1] == '\n';
    size_t sp = at + name.size();
    if (line_start && sp < body.size() && body[sp] == ' ') return std::stod(body.substr(sp + 1));
    at = sp;
  }
  return -1;
}

class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

struct RunResult {
  int exit_code = -1;  // -1 when the process did not exit normally
  std::string out;
  std::string err;
};
// Runs argv[0] (a path) with arguments, feeding `stdin_data`; captures both outputs.
RunResult run(const std::vector<std::string>& argv, const std::string& stdin_data = {},
              const std::vector<std::string>& extra_env = {});
// Runs the rcan CLI built alongside the tests.
RunResult run_cli(const std::vector<std::string>& args, const std::string& stdin_data = {},
                  const std::vector<std::string>& extra_env = {});

// What a configured node's fixture needs on disk, made through the library instead of the CLI
// (the tests about the CLI run it themselves): a new robot key pair in `dir`, as `rcan keys
// generate --dir` writes it; a new audit chain secret at `path` (0600), as `rcan audit
// new-secret --out`; an Ed25519 token issuer in `dir`, as `rcan keys issuer --dir`. Each
// reports a failure to the running test and returns false.
bool generate_robot_keys(const std::string& dir);
bool create_audit_secret(const std::string& path);
bool create_token_issuer(const std::string& dir);

// Polls `pred` (every 20 ms) until it holds or `timeout_ms` passes; then its last answer.
bool eventually(const std::function<bool()>& pred, int timeout_ms = 5000);

// A loopback TCP port that was free a moment ago (bound to port 0, then closed): for servers
// the test starts that take a port on their command line.
uint16_t free_port();

// A TCP connection to 127.0.0.1:`port` from `source` (a loopback address such as 127.0.0.2, to
// be another client address; null: any), with a receive buffer of `rcvbuf` bytes when positive.
// `fd` is the socket (-1 when none could be made), `connected` whether the connect succeeded.
struct LoopbackSocket {
  int fd = -1;
  bool connected = false;
};
LoopbackSocket loopback_socket(uint16_t port, const char* source = nullptr, int rcvbuf = 0);

}  // namespace rcan::test

namespace rcan::test {

// A child process whose stderr is watched line by line (for daemons).
class Process {
 public:
  Process() = default;
  ~Process();
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  // Starts argv; stdout goes to /dev/null, stderr is captured.
  bool start(const std::vector<std::string>& argv, const std::vector<std::string>& extra_env = {});
  // Waits up to `timeout_ms` for a stderr line containing `needle`; returns the line.
  std::optional<std::string> wait_for_line(const std::string& needle, int timeout_ms);
  // Sends `sig` and waits up to `timeout_ms` for exit; returns the exit status (-1 if killed
  // by a signal or still running).
  int stop(int sig, int timeout_ms);
  bool running();
  pid_t pid() const { return pid_; }
  // Everything read from stderr so far.
  const std::string& err() const { return err_; }
  void drain(int timeout_ms);

 private:
  pid_t pid_ = -1;
  int err_fd_ = -1;
  std::string err_;
  size_t scanned_ = 0;
  int exit_status_ = -2;
};

struct HttpReply {
  int status = 0;  // 0 when the request failed at the socket level
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-cased
  std::string body;
  std::string header(const std::string& name) const {
    for (const auto& h : headers)
      if (h.first == name) return h.second;
    return {};
  }
};

// One HTTP/1.1 request on a fresh loopback connection (Connection: close).
HttpReply http(uint16_t port, const std::string& method, const std::string& target,
               const std::string& body = {},
               const std::vector<std::pair<std::string, std::string>> headers = {},
               int timeout_ms = 10000);

// A keep-alive HTTP/1.1 client on one loopback connection.
class HttpClient {
 public:
  explicit HttpClient(uint16_t port);
  ~HttpClient();
  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;
  bool connected() const { return fd_ >= 0; }
  HttpReply request(const std::string& method, const std::string& target,
                    const std::string& body = {},
                    const std::vector<std::pair<std::string, std::string>>& headers = {},
                    int timeout_ms = 10000);
  // Raw bytes (for hostile input); returns what came back before close/timeout.
  std::string raw(const std::string& bytes, int timeout_ms);

 private:
  int fd_ = -1;
  std::string buf_;
};

// A minimal RFC 6455 client (text frames, masking) over loopback.
class WsClient {
 public:
  WsClient() = default;
  ~WsClient();
  WsClient(const WsClient&) = delete;
  WsClient& operator=(const WsClient&) = delete;
  // Opens and upgrades; returns the HTTP status of the upgrade response (101 on success).
  int connect(uint16_t port, const std::string& path,
              const std::vector<std::pair<std::string, std::string>>& headers = {});
  bool send_text(const std::string& text);
  bool send_binary(const std::string& data);
  // Next text frame within timeout; nullopt on timeout or close (close_code() tells).
  std::optional<std::string> recv_text(int timeout_ms);
  int close_code() const { return close_code_; }

 private:
  bool send_frame(uint8_t opcode, const std::string& payload);
  int fd_ = -1;
  std::string buf_;
  int close_code_ = 0;
};

}  // namespace rcan::test
