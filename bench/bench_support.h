// Shared pieces of the programs that drive a real rcand (load_bench, soak): spawning the
// daemon with a temporary data directory, reading its process figures from /proc, minting
// tokens from its local issuer, one-shot HTTP exchanges, checking the node's ACKs.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "transport/beast.h"

namespace rcan::bench {

int64_t mono_us();
int64_t wall_ms();

// A UUIDv4-shaped id from a fast generator (the node requires unique ids, not secret ones).
std::string fast_uuid();

// A free loopback TCP port.
uint16_t free_port();

// The q-quantile of a sorted vector (0 when empty).
double pct(const std::vector<double>& sorted, double q);

// ---- processes -------------------------------------------------------------------------------

struct ProcStat {
  long rss_kb = 0, hwm_kb = 0;
  long rss_anon_kb = 0, rss_file_kb = 0;
  long threads = 0;
  double cpu_s = 0;  // utime + stime
};
ProcStat proc_stat(pid_t pid);

// Open file descriptors of a process (entries of /proc/<pid>/fd), -1 when unreadable.
int count_fds(pid_t pid);

// The names of a process's threads (/proc/<pid>/task/*/comm), sorted, joined by spaces.
std::string thread_names(pid_t pid);

// Bytes in the regular files under `dir` (recursively), 0 when it does not exist.
uint64_t dir_bytes(const std::string& dir);

// Bytes of data in the files under `dir`: a file's size less any run of zero bytes at its end
// (the audit log zero-fills its active segment and the next one ahead of time; records are
// JSON lines and never contain a zero byte).
uint64_t dir_data_bytes(const std::string& dir);

// A child process whose stderr is drained by a thread; lines naming `keep` are kept.
class Child {
 public:
  Child(std::vector<std::string> argv, std::string keep);
  ~Child();
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  pid_t pid() const { return pid_; }
  int64_t spawned_us() const { return t_spawn_; }
  bool alive() const;
  // The first 64 KiB of its stderr.
  std::string head();
  std::vector<std::string> take_kept();
  // SIGTERM and wait; returns the wait status (-1 when it was not running).
  int stop();

 private:
  std::string keep_;
  pid_t pid_ = -1;
  int fd_ = -1;
  int64_t t_spawn_ = 0;
  std::thread drain_;
  std::mutex mu_;
  std::string head_;
  std::vector<std::string> kept_;
};

// One blocking HTTP exchange (setup, /healthz, /metrics). Returns the status, 0 on failure.
int sync_http(uint16_t port, boost::beast::http::verb verb, const std::string& target,
              const std::string& body, const std::string& token, std::string* out = nullptr);

// Polls GET /healthz until it answers 200; returns ms since the child was spawned, or -1.
double wait_ready(Child& c, uint16_t port, double timeout_ms = 30000);

// ---- the node under test --------------------------------------------------------------------

struct Node {
  std::string dir;
  std::string ruri;
  uint16_t port = 0;
  std::unique_ptr<Child> child;
  double ready_ms = -1;
};

// Starts `rcand --data-dir n.dir --port <free> --log-level info <extra…>`, waits until it
// serves and has logged its RURI. `keep`: log lines to keep (Child::take_kept).
bool start_node(Node& n, const std::string& rcand, const std::vector<std::string>& extra,
                const std::string& keep = "estop.latency");

// A CREATOR token from the node's local issuer (seed file), audience `ruri`.
std::string token_for(const std::string& seed_file, const std::string& iss, const std::string& ruri,
                      const std::string& sub, int64_t lifetime_s = 3600);

// Waits until the process is quiet (start-up work such as the audit log's preallocated spare
// segment is done): CPU use below 5% over 200 ms, for at most `max_ms`.
void settle(pid_t pid, int max_ms = 5000);

// The embedded default configuration with the node's device id filled in (read from
// <data_dir>/device_id), ready for edits and `rcand --config`.
std::string default_yaml_for(const std::string& data_dir);

// ---- answers --------------------------------------------------------------------------------

// True when (status, body) is the node's ACK to message `id`: 200, type ACK, reply_to = id,
// a payload with a `command` and a non-null `result`. Otherwise `why` says what was wrong.
bool check_node_ack(int status, const std::string& body, const std::string& id, std::string& why);

// True when body is the node's ERROR to `id` with this HTTP status (0: any), this
// payload.error_code (empty: any) and payload.reason (empty: any).
bool check_node_error(int status, const std::string& body, const std::string& id, int want_status,
                      const std::string& error_code, const std::string& reason, std::string& why);

}  // namespace rcan::bench
