#include "drivers/process/process_driver.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <spawn.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include "base/clock.h"
#include "runtime/log.h"

extern char** environ;

namespace rcan::drivers {
namespace {

constexpr size_t kMaxQueuedFrames = 32;
constexpr int64_t kRedundantStopMs = 250;    // a stop with nothing moved since: at most 4/s
constexpr int64_t kBackoffResetMs = 10'000;  // healthy this long: the back-off starts over
constexpr int64_t kMaxPollMs = 100;

int64_t now_ms() { return steady_ms(); }

std::string errno_text(int e) {
  char buf[128];
  return std::string(strerror_r(e, buf, sizeof buf));
}

std::string exit_text(int status) {
  if (WIFEXITED(status)) return "exit status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return "killed by signal " + std::to_string(WTERMSIG(status));
  return "status " + std::to_string(status);
}

// Starts `argv` in its own process group with an empty signal mask and default dispositions
// (rcand blocks its termination signals in every thread), /dev/null as stdin, `out_fd` and
// `err_fd` (rcand's pipes: never rcand's own stdout and stderr, whose lines are rcand's log) as
// its stdout and stderr, `child_fd` as fd 3 and no other descriptor of rcand. Returns the pid or
// -errno.
pid_t spawn_driver(const std::vector<std::string>& command, int child_fd, int out_fd, int err_fd) {
  posix_spawn_file_actions_t fa;
  posix_spawnattr_t attr;
  posix_spawn_file_actions_init(&fa);
  posix_spawnattr_init(&attr);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, out_fd, 1);  // out_fd, err_fd > 2: rcand holds 0-2
  posix_spawn_file_actions_adddup2(&fa, err_fd, 2);
  posix_spawn_file_actions_adddup2(&fa, child_fd, 3);
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 34))
  posix_spawn_file_actions_addclosefrom_np(&fa, 4);
#endif
  sigset_t empty, defaults;
  sigemptyset(&empty);
  sigemptyset(&defaults);
  for (int s : {SIGTERM, SIGINT, SIGHUP, SIGQUIT, SIGPIPE, SIGCHLD, SIGUSR1, SIGUSR2})
    sigaddset(&defaults, s);
  posix_spawnattr_setsigmask(&attr, &empty);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  posix_spawnattr_setpgroup(&attr, 0);
  posix_spawnattr_setflags(&attr,
                           POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETPGROUP);
  std::vector<std::string> env_strings;
  for (char** e = environ; e && *e; ++e)
    if (strncmp(*e, "RCAN_DRIVER_FD=", 15) != 0) env_strings.emplace_back(*e);
  env_strings.emplace_back("RCAN_DRIVER_FD=3");
  std::vector<char*> envp, argv;
  for (auto& s : env_strings) envp.push_back(s.data());
  envp.push_back(nullptr);
  std::vector<std::string> args = command;
  for (auto& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, argv[0], &fa, &attr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&attr);
  return rc == 0 ? pid : -rc;
}

}  // namespace

ProcessDriver::ProcessDriver(ProcessDriverOptions opts)
    : opts_(std::move(opts)), backoff_ms_(opts_.file.restart_backoff_ms) {
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
}

ProcessDriver::~ProcessDriver() {
  quit_.store(true, std::memory_order_release);
  wake();
  if (io_.joinable()) io_.join();
  if (wake_fd_ >= 0) ::close(wake_fd_);
  for (Output& o : output_)
    if (o.fd >= 0) ::close(o.fd);
}

Status ProcessDriver::start() {
  if (wake_fd_ < 0) return Error(ErrorCode::kInternal, "driver: eventfd: " + errno_text(errno));
  if (opts_.file.command.empty() && opts_.file.socket.empty())
    return Error(ErrorCode::kInternal, "driver.process needs a command or a socket");
  io_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "driver-io");
    io_loop();
  });
  const auto deadline = steady_now() + std::chrono::milliseconds(opts_.file.startup_timeout_ms);
  MutexLock lock(rmu_);
  while (!ready_.load(std::memory_order_acquire) && faults_ == 0 && steady_now() < deadline)
    ready_cv_.wait_until(rmu_, deadline);
  if (!ready_.load(std::memory_order_acquire))
    log(LogLevel::kWarn, "driver_process_not_ready", json::Object{{"fault", fault_}});
  return Status::Ok();
}

void ProcessDriver::wake() noexcept {
  if (wake_fd_ < 0) return;
  const uint64_t one = 1;
  [[maybe_unused]] ssize_t n = ::write(wake_fd_, &one, sizeof one);
}

// ---- the caller's side ------------------------------------------------------------------------

Status ProcessDriver::apply(const node::ActuatorCommand& cmd) {
  // A stop command takes the stop path: ahead of the queue, and accepted with the link down
  // (a process that is gone or not yet ready starts at rest).
  if (cmd.stop) {
    stop();
    return Status::Ok();
  }
  if (!ready_.load(std::memory_order_acquire)) {
    MutexLock lock(rmu_);
    return Error(ErrorCode::kSafeStop, "the driver process is not ready: " + fault_, "",
                 "driver_fault");
  }
  bool pending = false;
  {
    MutexLock lock(wmu_);
    if (fd_ < 0)
      return Error(ErrorCode::kSafeStop, "the driver process is not connected", "", "driver_fault");
    if (queue_.size() >= kMaxQueuedFrames)
      return Error(ErrorCode::kSafeStop, "the driver process is not reading its commands", "",
                   "driver_fault");
    const uint64_t gen = stop_gen_.load(std::memory_order_acquire);
    queue_.push_back(Out{encode_apply(++seq_, cmd), gen, false});
    moved_since_stop_ = true;
    if (cmd.moves() && cmd.drive) {
      MutexLock rlock(rmu_);
      commanded_ = Commanded{cmd.drive->linear_mps, cmd.drive->angular_radps,
                             now_ms() + std::max<int64_t>(0, cmd.drive->duration_ms), gen};
    }
    // A stop() that could not take the lock is served first: it goes out ahead of this frame.
    if (stop_gen_.load(std::memory_order_acquire) != stop_served_gen_) serve_stop_locked();
    if (!flush_locked())
      return Error(ErrorCode::kSafeStop, "writing to the driver process failed", "",
                   "driver_fault");
    pending = !queue_.empty();
  }
  if (pending) wake();  // the I/O thread writes the rest when the socket drains
  return Status::Ok();
}

void ProcessDriver::stop() noexcept {
  stop_gen_.fetch_add(1, std::memory_order_acq_rel);
  bool served = false;
  if (wmu_.try_lock()) {
    try {
      serve_stop_locked();
      served = queue_.empty();
    } catch (...) {
      // bad_alloc: the I/O thread serves the stop.
    }
    wmu_.unlock();
  }
  if (!served) wake();
}

void ProcessDriver::serve_stop_locked() {
  const uint64_t gen = stop_gen_.load(std::memory_order_acquire);
  if (gen == stop_served_gen_) return;
  stop_served_gen_ = gen;
  if (fd_ < 0) return;  // nothing to stop: a new process starts at rest
  // Drop what was queued before this stop (a half-written frame at the front must complete).
  auto first = queue_.begin();
  if (head_off_ > 0 && first != queue_.end()) ++first;
  bool dropped_stop = false;
  for (auto it = first; it != queue_.end();) {
    if (it->stop_gen < gen) {
      dropped_stop = dropped_stop || it->is_stop;
      it = queue_.erase(it);
    } else {
      ++it;
    }
  }
  const int64_t now = now_ms();
  if (!moved_since_stop_ && !dropped_stop && now - last_stop_sent_ms_ < kRedundantStopMs) return;
  first = queue_.begin();
  if (head_off_ > 0 && first != queue_.end()) ++first;
  queue_.insert(first, Out{encode_stop(++seq_), gen, true});
  moved_since_stop_ = false;
  last_stop_sent_ms_ = now;
  (void)flush_locked();  // a write error shows on the I/O thread's next poll
}

bool ProcessDriver::flush_locked() {
  while (!queue_.empty() && fd_ >= 0) {
    Out& f = queue_.front();
    const ssize_t n = ::send(fd_, f.bytes.data() + head_off_, f.bytes.size() - head_off_,
                             MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno == EAGAIN || errno == EWOULDBLOCK;
    }
    head_off_ += static_cast<size_t>(n);
    if (head_off_ == f.bytes.size()) {
      if (f.is_stop) stop_frames_.fetch_add(1, std::memory_order_relaxed);
      queue_.pop_front();
      head_off_ = 0;
    }
  }
  return true;
}

void ProcessDriver::close_locked() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  queue_.clear();
  head_off_ = 0;
}

void ProcessDriver::step(int64_t dt_ms) {
  MutexLock lock(rmu_);
  t_ms_ += dt_ms;
}

node::RobotState ProcessDriver::state() const {
  MutexLock lock(rmu_);
  node::RobotState s = state_;
  s.t_ms = t_ms_;
  // Conservative: while a drive rcand sent is within its duration and no stop came since, the
  // robot counts as moving whatever the process reported (a process that reports nothing, or
  // late, must not look stopped to the safety core's deadman and TTL checks).
  const int64_t now = now_ms();
  if (commanded_.end_ms > now && commanded_.stop_gen == stop_gen_.load(std::memory_order_acquire)) {
    s.stopped = false;
    if (s.target_linear_mps == 0.0 && s.target_angular_radps == 0.0) {
      s.target_linear_mps = commanded_.linear_mps;
      s.target_angular_radps = commanded_.angular_radps;
      s.drive_remaining_ms = commanded_.end_ms - now;
    }
  }
  return s;
}

node::DriverHealth ProcessDriver::health() const {
  MutexLock lock(rmu_);
  if (!unreported_fault_.empty()) {
    node::DriverHealth h{false, {}};
    h.fault.swap(unreported_fault_);
    return h;
  }
  if (ready_.load(std::memory_order_acquire)) return {};
  return {false, fault_.empty() ? std::string("the driver process is not ready") : fault_};
}

// ---- the I/O thread ---------------------------------------------------------------------------

bool ProcessDriver::connect_or_spawn(int64_t now) {
  int fd = -1;
  pid_t pid = -1;
  if (!opts_.file.command.empty()) {
    int sv[2];
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) {
      fault("cannot create the driver socket: " + errno_text(errno), now);
      return false;
    }
    // Its stdout and stderr: pipes read by this thread (relay_output), fresh for each process.
    int out[2] = {-1, -1}, err[2] = {-1, -1};
    if (pipe2(out, O_CLOEXEC) != 0 || pipe2(err, O_CLOEXEC) != 0) {
      const int e = errno;
      for (int f : {out[0], out[1], err[0], err[1], sv[0], sv[1]})
        if (f >= 0) ::close(f);
      fault("cannot create the driver's output pipes: " + errno_text(e), now);
      return false;
    }
    int child_end = sv[1];
    if (child_end == 3) {  // dup2(3, 3) would keep close-on-exec set
      child_end = fcntl(sv[1], F_DUPFD_CLOEXEC, 4);
      ::close(sv[1]);
    }
    pid = child_end < 0 ? -EMFILE : spawn_driver(opts_.file.command, child_end, out[1], err[1]);
    if (child_end >= 0) ::close(child_end);
    ::close(out[1]);
    ::close(err[1]);
    if (pid < 0) {
      ::close(sv[0]);
      ::close(out[0]);
      ::close(err[0]);
      fault("cannot start the driver process " + opts_.file.command[0] + ": " + errno_text(-pid),
            now);
      return false;
    }
    for (int i = 0; i < 2; ++i) {
      Output& o = output_[i];
      if (o.fd >= 0) drain_output(i, true);  // the last process's last words, then its pipe goes
      o.fd = i == 0 ? out[0] : err[0];
      fcntl(o.fd, F_SETFL, fcntl(o.fd, F_GETFL) | O_NONBLOCK);
      o.partial.clear();
      o.skipping = false;
    }
    fd = sv[0];
    fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
    child_pid_.store(pid, std::memory_order_release);
  } else {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (opts_.file.socket.size() >= sizeof addr.sun_path) {
      fault("driver.process.socket is too long", now);
      return false;
    }
    memcpy(addr.sun_path, opts_.file.socket.data(), opts_.file.socket.size());
    fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0 || ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      const int e = errno;
      if (fd >= 0) ::close(fd);
      fault("cannot connect to the driver process at " + opts_.file.socket + ": " + errno_text(e),
            now);
      return false;
    }
  }
  decoder_ = FrameDecoder();
  described_ = heartbeat_seen_ = false;
  connected_ms_ = last_rx_ms_ = last_hb_tx_ms_ = now;
  {
    MutexLock lock(wmu_);
    fd_ = fd;
    queue_.clear();
    head_off_ = 0;
    stop_served_gen_ = stop_gen_.load(std::memory_order_acquire);
    moved_since_stop_ = false;
    queue_.push_back(
        Out{encode_describe(++seq_, opts_.file.heartbeat_ms, opts_.file.heartbeat_timeout_ms),
            stop_served_gen_, false});
    queue_.push_back(Out{encode_heartbeat(++seq_), stop_served_gen_, false});
    (void)flush_locked();
  }
  if (ever_connected_) restarts_.fetch_add(1, std::memory_order_relaxed);
  log(LogLevel::kInfo, ever_connected_ ? "driver_process_restarted" : "driver_process_started",
      json::Object{
          {"pid", static_cast<int64_t>(pid)},
          {"target", opts_.file.command.empty() ? opts_.file.socket : opts_.file.command[0]},
          {"restarts", static_cast<int64_t>(restarts_.load())}});
  ever_connected_ = true;
  return true;
}

void ProcessDriver::fault(const std::string& why, int64_t now) {
  const bool was_ready = ready_.exchange(false, std::memory_order_acq_rel);
  {
    MutexLock lock(rmu_);
    // Report every fault of a link that was up; while down, only the first (no restart spam).
    if (was_ready || fault_ != why) unreported_fault_ = why;
    fault_ = why;
    ++faults_;
    ready_cv_.notify_all();
    state_.target_linear_mps = state_.target_angular_radps = 0.0;
    state_.drive_remaining_ms = 0;
  }
  const pid_t pid = child_pid_.exchange(-1, std::memory_order_acq_rel);
  log(LogLevel::kWarn, "driver_process_fault",
      json::Object{{"fault", why}, {"pid", static_cast<int64_t>(pid)}});
  {
    MutexLock lock(wmu_);
    if (fd_ >= 0) {
      // A last stop, when the stream is at a frame boundary; then the socket goes.
      const uint64_t gen = stop_gen_.load(std::memory_order_acquire);
      if (head_off_ == 0) queue_.clear();
      queue_.push_back(Out{encode_stop(++seq_), gen, true});
      (void)flush_locked();
    }
    close_locked();
  }
  if (pid > 0) {
    ::kill(-pid, SIGTERM);
    ::kill(pid, SIGTERM);
    reaping_pid_ = pid;
    kill_at_ms_ = now + opts_.kill_grace_ms;
  }
  decoder_ = FrameDecoder();
  described_ = heartbeat_seen_ = false;
  if (healthy_since_ms_ > 0 && now - healthy_since_ms_ >= kBackoffResetMs)
    backoff_ms_ = opts_.file.restart_backoff_ms;
  healthy_since_ms_ = 0;
  next_attempt_ms_ = now + backoff_ms_;
  backoff_ms_ = std::min<uint32_t>(backoff_ms_ * 2, opts_.file.restart_backoff_max_ms);
}

void ProcessDriver::reap_child(int64_t now) {
  int status = 0;
  const pid_t live = child_pid_.load(std::memory_order_acquire);
  if (live > 0) {
    const pid_t r = ::waitpid(live, &status, WNOHANG);
    if (r == live || (r < 0 && errno == ECHILD)) {
      child_pid_.store(-1, std::memory_order_release);  // reaped: never signal that pid again
      fault("the driver process exited (" + (r == live ? exit_text(status) : "reaped") + ")", now);
    }
  }
  if (reaping_pid_ > 0) {
    const pid_t r = ::waitpid(reaping_pid_, &status, WNOHANG);
    if (r == reaping_pid_ || (r < 0 && errno == ECHILD)) {
      reaping_pid_ = -1;
    } else if (now >= kill_at_ms_) {
      ::kill(-reaping_pid_, SIGKILL);
      ::kill(reaping_pid_, SIGKILL);
      kill_at_ms_ = now + 1000;
    }
  }
}

void ProcessDriver::on_frame(const std::string& payload, int64_t now) {
  auto in = parse_incoming(payload);
  if (!in.ok()) {
    fault("the driver process sent a bad frame: " + in.error().message, now);
    return;
  }
  last_rx_ms_ = now;
  switch (in->kind) {
    case Incoming::Kind::kDescribe: {
      const node::DriverInfo& env = opts_.info;
      auto narrower = [](const std::optional<double>& hw, double cfg) {
        return hw && *hw < cfg - 1e-9;
      };
      if (narrower(in->max_linear_mps, env.max_linear_mps) ||
          narrower(in->max_angular_radps, env.max_angular_radps)) {
        fault("the driver process describes a narrower envelope (max_linear_mps " +
                  std::to_string(in->max_linear_mps.value_or(env.max_linear_mps)) +
                  ", max_angular_radps " +
                  std::to_string(in->max_angular_radps.value_or(env.max_angular_radps)) +
                  ") than driver.process allows: lower driver.process limits",
              now);
        return;
      }
      if (!described_)
        log(LogLevel::kInfo, "driver_process_described", json::Object{{"name", in->name}});
      described_ = true;
      break;
    }
    case Incoming::Kind::kHeartbeat: {
      heartbeat_seen_ = true;
      MutexLock lock(rmu_);
      if (in->fault != process_fault_ && !in->fault.empty())
        log(LogLevel::kWarn, "driver_process_reports_fault", json::Object{{"fault", in->fault}});
      process_fault_ = in->fault;
      break;
    }
    case Incoming::Kind::kState: {
      MutexLock lock(rmu_);
      state_ = in->state;
      break;
    }
  }
  // Readiness: describe answered, a heartbeat seen, no fault reported by the process.
  bool ready_now = false, became_ready = false;
  {
    MutexLock lock(rmu_);
    ready_now = described_ && heartbeat_seen_ && process_fault_.empty();
    const bool was = ready_.load(std::memory_order_acquire);
    if (ready_now && !was) {
      fault_.clear();
      healthy_since_ms_ = now;
      ready_.store(true, std::memory_order_release);
      ready_cv_.notify_all();
      became_ready = true;
    } else if (!ready_now && was) {
      fault_ = "the driver process reports: " + process_fault_;
      unreported_fault_ = fault_;
      ready_.store(false, std::memory_order_release);
    }
  }
  if (became_ready)
    log(LogLevel::kInfo, "driver_process_ready",
        json::Object{{"restarts", static_cast<int64_t>(restarts_.load())}});
}

// Why the socket closed: the process's exit status when it exits within 100 ms.
std::string ProcessDriver::closed_reason() {
  const pid_t pid = child_pid_.load(std::memory_order_acquire);
  for (int i = 0; pid > 0 && i < 20; ++i) {
    int status = 0;
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) {
      child_pid_.store(-1, std::memory_order_release);  // reaped: never signal that pid again
      return "the driver process exited (" + exit_text(status) + ")";
    }
    if (r < 0) break;
    ::usleep(5000);
  }
  return "the driver process closed the connection";
}

void ProcessDriver::drain_output(int stream, bool last) {
  Output& o = output_[stream];
  char buf[4096];
  // At most 64 KiB a turn: a driver that writes without end cannot hold the I/O thread.
  for (int turn = 0; turn < 16 && o.fd >= 0; ++turn) {
    const ssize_t got = ::read(o.fd, buf, sizeof buf);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) {
      if (got == 0 || (errno != EAGAIN && errno != EWOULDBLOCK)) last = true;
      break;
    }
    for (ssize_t i = 0; i < got; ++i) {
      const char c = buf[i];
      if (c == '\n') {
        if (!o.skipping) relay_line(stream, o.partial, false);
        o.partial.clear();
        o.skipping = false;
      } else if (!o.skipping) {
        o.partial.push_back(c);
        if (o.partial.size() >= kMaxOutputLine) {  // cut; the rest of the line is dropped
          relay_line(stream, o.partial, true);
          o.partial.clear();
          o.skipping = true;
        }
      }
    }
  }
  if (!last) return;
  if (!o.partial.empty() && !o.skipping) relay_line(stream, o.partial, false);
  o.partial.clear();
  o.skipping = false;
  if (o.fd >= 0) ::close(o.fd);
  o.fd = -1;
}

void ProcessDriver::relay_line(int stream, const std::string& line, bool cut) {
  // A token bucket per stream; what it refuses is counted and said once it refills.
  Output& o = output_[stream];
  const int64_t now = now_ms();
  o.tokens = std::min(static_cast<double>(kOutputBurst),
                      o.tokens + static_cast<double>(now - o.at_ms) * kOutputLinesPerS / 1000.0);
  o.at_ms = now;
  if (o.tokens < 1.0) {
    ++o.dropped;
    return;
  }
  o.tokens -= 1.0;
  if (o.dropped > 0) {
    log(LogLevel::kWarn, "driver_output_dropped",
        json::Object{{"stream", stream == 0 ? "stdout" : "stderr"},
                     {"lines", static_cast<int64_t>(o.dropped)},
                     {"limit_per_s", static_cast<int64_t>(kOutputLinesPerS)}});
    o.dropped = 0;
  }
  json::Object f{{"stream", stream == 0 ? "stdout" : "stderr"},
                 {"pid", static_cast<int64_t>(child_pid_.load(std::memory_order_acquire))},
                 {"line", line}};
  if (cut) f.set("truncated", true);
  log(LogLevel::kInfo, "driver_output", std::move(f));
}

void ProcessDriver::io_loop() {
  while (!quit_.load(std::memory_order_acquire)) {
    int64_t now = now_ms();
    reap_child(now);
    int fd = -1;
    bool want_out = false;
    {
      MutexLock lock(wmu_);
      fd = fd_;
      want_out = !queue_.empty();
    }
    int64_t wait = kMaxPollMs;
    if (fd < 0) {
      if (now >= next_attempt_ms_ && reaping_pid_ < 0) {
        connect_or_spawn(now);
        continue;
      }
      wait = std::min<int64_t>(wait, std::max<int64_t>(1, next_attempt_ms_ - now));
    } else if (!keep_link(now, wait, want_out)) {
      continue;
    }
    if (reaping_pid_ > 0) wait = std::min<int64_t>(wait, 20);
    // The driver's stdout and stderr (fd -1: poll ignores the entry).
    pollfd p[4] = {{wake_fd_, POLLIN, 0},
                   {fd, static_cast<short>(POLLIN | (want_out ? POLLOUT : 0)), 0},
                   {output_[0].fd, POLLIN, 0},
                   {output_[1].fd, POLLIN, 0}};
    const int n = ::poll(p, 4, static_cast<int>(wait));
    if (n < 0 && errno != EINTR) break;
    if (p[0].revents & POLLIN) {
      uint64_t v;
      [[maybe_unused]] ssize_t r = ::read(wake_fd_, &v, sizeof v);
    }
    for (int i = 0; i < 2; ++i)
      if (p[2 + i].revents & (POLLIN | POLLHUP | POLLERR)) drain_output(i, false);
    if (fd < 0) continue;
    now = now_ms();
    bool write_ok = true;
    {
      MutexLock lock(wmu_);
      if (stop_gen_.load(std::memory_order_acquire) != stop_served_gen_) serve_stop_locked();
      write_ok = flush_locked();
    }
    if (!write_ok) {
      fault("writing to the driver process failed: " + errno_text(errno), now);
      continue;
    }
    if (p[1].revents & (POLLIN | POLLHUP | POLLERR)) read_frames(fd, now);
  }
  finish_io();
}

// The link's timers: the describe (while handshaking) or heartbeat deadline, a fault when it
// passed (false); our own heartbeat queued when due; `wait` shortened to the next of them.
bool ProcessDriver::keep_link(int64_t now, int64_t& wait, bool& want_out) {
  const bool handshaking = !described_ || !heartbeat_seen_;
  const int64_t limit =
      handshaking ? opts_.file.startup_timeout_ms : opts_.file.heartbeat_timeout_ms;
  const int64_t since = now - (handshaking ? connected_ms_ : last_rx_ms_);
  if (since > limit) {
    fault(handshaking
              ? "the driver process did not answer describe within " + std::to_string(limit) + " ms"
              : "no heartbeat from the driver process for " + std::to_string(since) + " ms",
          now);
    return false;
  }
  if (now - last_hb_tx_ms_ >= opts_.file.heartbeat_ms) {
    MutexLock lock(wmu_);
    if (queue_.size() < kMaxQueuedFrames)
      queue_.push_back(
          Out{encode_heartbeat(++seq_), stop_gen_.load(std::memory_order_acquire), false});
    want_out = true;
    last_hb_tx_ms_ = now;
  }
  wait =
      std::min<int64_t>(wait, std::max<int64_t>(1, last_hb_tx_ms_ + opts_.file.heartbeat_ms - now));
  wait = std::min<int64_t>(wait, std::max<int64_t>(1, limit - since + 1));
  return true;
}

// What the socket has: each whole frame to on_frame; a closed socket, a read error or a bad
// frame is a fault.
void ProcessDriver::read_frames(int fd, int64_t now) {
  char buf[16384];
  const ssize_t got = ::recv(fd, buf, sizeof buf, MSG_DONTWAIT);
  if (got == 0) {
    fault(closed_reason(), now);
    return;
  }
  if (got < 0) {
    if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
      fault("reading from the driver process failed: " + errno_text(errno), now);
    return;
  }
  decoder_.feed(buf, static_cast<size_t>(got));
  while (true) {
    auto f = decoder_.next();
    if (!f.ok()) {
      fault("the driver process sent a bad frame: " + f.error().message, now);
      return;
    }
    if (!*f) return;
    on_frame(**f, now);
    MutexLock lock(wmu_);
    if (fd_ < 0) return;  // on_frame faulted
  }
}

// Shutting down: a last stop, the socket closed, the process terminated and reaped.
void ProcessDriver::finish_io() {
  {
    MutexLock lock(wmu_);
    if (fd_ >= 0 && head_off_ == 0) {
      queue_.clear();
      queue_.push_back(Out{encode_stop(++seq_), stop_gen_.load(), true});
      (void)flush_locked();
    }
    close_locked();
  }
  ready_.store(false, std::memory_order_release);
  for (pid_t pid : {child_pid_.exchange(-1), reaping_pid_}) {
    if (pid <= 0) continue;
    ::kill(-pid, SIGTERM);
    ::kill(pid, SIGTERM);
    const int64_t deadline = now_ms() + opts_.kill_grace_ms;
    int status = 0;
    while (::waitpid(pid, &status, WNOHANG) == 0) {
      if (now_ms() >= deadline) {
        ::kill(-pid, SIGKILL);
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &status, 0);
        break;
      }
      ::usleep(5000);
    }
  }
}

}  // namespace rcan::drivers
