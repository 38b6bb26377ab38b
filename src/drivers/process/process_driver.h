// ProcessDriver — `driver.type: process`: the robot's hardware is driven by a separate driver
// process (any language) that speaks the frame protocol of frame.h over a Unix stream socket
// (docs/DRIVERS.md §Driver processes). The SafetyCore stays in rcand: the process only ever
// receives what apply() is given, which the core has already validated and limited.
//
// Connection: with `command`, rcand starts the process itself (its own process group, an
// empty signal mask, stdin /dev/null, stdout and stderr pipes whose lines rcand relays as
// "driver_output" log lines) and hands it one end of a socketpair as file descriptor 3
// (RCAN_DRIVER_FD=3 in its environment); with `socket`, rcand connects to a process already
// listening on that path. Either way rcand sends `describe` first; the link is healthy once the
// process has answered `describe` and sent a heartbeat.
//
// Threads: one I/O thread per driver polls the socket (reads, heartbeats, liveness, restarts).
// apply() queues its frame and writes it at once with a non-blocking send (never waits on the
// socket; a full queue refuses the command; a stop command takes stop()'s path). stop() is
// lock-free for the caller: it bumps a
// stop generation, then either writes the stop frame itself (when it gets the writer lock
// without waiting) or wakes the I/O thread through an eventfd. Either way every frame queued
// before the stop is dropped unsent and the stop frame goes out before anything queued after
// it; only a frame already half written completes first (the stream must stay framed).
//
// Faults (health() false): no describe answer within startup_timeout_ms, nothing received for
// heartbeat_timeout_ms, the socket closed (the process died), a malformed frame (zero or
// oversize length, not JSON, unknown type, a member of the wrong type), a describe whose
// hardware envelope is narrower than the configured one, or a heartbeat carrying the process's
// own "fault". rcand then sends a last stop frame, closes the socket, terminates the process
// (SIGTERM, SIGKILL after kill_grace_ms) and restarts it after restart_backoff_ms, doubling up
// to restart_backoff_max_ms (the back-off resets once a process stayed healthy for 10 s). A
// fault is reported by health() at least once even if the restart heals it before the core's
// next tick.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <deque>
#include <string>
#include <thread>
#include <vector>

#include "base/thread_annotations.h"
#include "config/driver_config.h"
#include "drivers/process/frame.h"
#include "node/safety/driver.h"

namespace rcan::drivers {

struct ProcessDriverOptions {
  // driver.process as the file gives it: the command or socket, heartbeats, start-up and
  // restart back-off (config/driver_config.h). Its envelope keys reach the core through `info`.
  config::ProcessDriverConfig file;
  uint32_t kill_grace_ms = 500;
  // The hardware envelope describe() reports (the core uses min(config, these)).
  node::DriverInfo info;
};

class ProcessDriver final : public node::Driver {
 public:
  explicit ProcessDriver(ProcessDriverOptions opts);
  ~ProcessDriver() override;

  // Starts the I/O thread and waits up to startup_timeout_ms for the first process to become
  // healthy (or to fail). An error only when the driver has nothing to start or connect to;
  // a process that fails to start or dies is retried by the I/O thread with back-off.
  Status start();

  node::DriverInfo describe() const override { return opts_.info; }
  Status apply(const node::ActuatorCommand& cmd) override;
  void stop() noexcept override;
  void step(int64_t dt_ms) override;
  node::RobotState state() const override;
  node::DriverHealth health() const override;

  // For tests and benchmarks.
  pid_t child_pid() const { return child_pid_.load(std::memory_order_acquire); }
  uint64_t restarts() const { return restarts_.load(std::memory_order_relaxed); }
  uint64_t stop_frames_sent() const { return stop_frames_.load(std::memory_order_relaxed); }
  bool healthy() const { return ready_.load(std::memory_order_acquire); }

 private:
  struct Out {
    std::string bytes;
    uint64_t stop_gen = 0;  // the stop generation when it was queued
    bool is_stop = false;
  };

  void io_loop();
  // The steps of io_loop (process_driver.cpp); they run on its thread only.
  bool keep_link(int64_t now, int64_t& wait, bool& want_out);
  void read_frames(int fd, int64_t now);
  void finish_io();
  // Reads what the driver wrote to its stdout (0) or stderr (1) and relays it line by line as
  // rcand's own "driver_output" log lines (its text escaped as a field, never a line of
  // rcand's log itself), cut at kMaxOutputLine bytes, at most kOutputLinesPerS lines a second
  // per stream (each its own bucket: chatter on stdout never silences what the driver says on
  // stderr); `last`: the pipe goes (a partial line is relayed).
  void drain_output(int stream, bool last);
  void relay_line(int stream, const std::string& line, bool cut);
  bool connect_or_spawn(int64_t now_ms);
  void on_frame(const std::string& payload, int64_t now_ms);
  void fault(const std::string& why, int64_t now_ms);
  void reap_child(int64_t now_ms);
  std::string closed_reason();
  void wake() noexcept;
  // Drops every frame queued before the current stop generation and queues one stop frame
  // ahead of the rest (after a half-written frame); then writes what the socket takes.
  void serve_stop_locked() REQUIRES(wmu_);
  // Writes queued frames until the socket would block. False on a write error.
  bool flush_locked() REQUIRES(wmu_);
  void close_locked() REQUIRES(wmu_);

  const ProcessDriverOptions opts_;
  int wake_fd_ = -1;  // eventfd: stop(), apply() and the destructor wake the I/O thread
  std::thread io_;
  std::atomic<bool> quit_{false};

  // Writer side: the socket and the outgoing queue.
  mutable Mutex wmu_;
  int fd_ GUARDED_BY(wmu_) = -1;
  std::deque<Out> queue_ GUARDED_BY(wmu_);
  size_t head_off_ GUARDED_BY(wmu_) = 0;  // bytes of queue_.front() already written
  uint64_t seq_ GUARDED_BY(wmu_) = 0;
  uint64_t stop_served_gen_ GUARDED_BY(wmu_) = 0;
  bool moved_since_stop_ GUARDED_BY(wmu_) = true;  // an apply went out after the last stop
  int64_t last_stop_sent_ms_ GUARDED_BY(wmu_) = 0;
  std::atomic<uint64_t> stop_gen_{0};

  // Reader side: what the process reported, and the link's health.
  mutable Mutex rmu_;
  node::RobotState state_ GUARDED_BY(rmu_);
  std::string fault_ GUARDED_BY(rmu_) = "the driver process has not started yet";
  mutable std::string unreported_fault_ GUARDED_BY(rmu_);  // shown once by health()
  std::string process_fault_ GUARDED_BY(rmu_);             // the process's own heartbeat fault
  // The last drive sent: the robot counts as moving until its end unless a stop came since.
  struct Commanded {
    double linear_mps = 0.0;
    double angular_radps = 0.0;
    int64_t end_ms = 0;
    uint64_t stop_gen = 0;
  };
  Commanded commanded_ GUARDED_BY(rmu_);
  CondVar ready_cv_;
  uint64_t faults_ GUARDED_BY(rmu_) = 0;
  int64_t t_ms_ GUARDED_BY(rmu_) = 0;

  std::atomic<bool> ready_{false};  // describe answered + heartbeat received, no fault
  std::atomic<pid_t> child_pid_{-1};
  std::atomic<uint64_t> restarts_{0};
  std::atomic<uint64_t> stop_frames_{0};

  // I/O thread only.
  FrameDecoder decoder_;
  bool described_ = false;
  bool heartbeat_seen_ = false;
  int64_t connected_ms_ = 0;
  int64_t last_rx_ms_ = 0;
  int64_t last_hb_tx_ms_ = 0;
  int64_t next_attempt_ms_ = 0;
  int64_t healthy_since_ms_ = 0;
  uint32_t backoff_ms_ = 0;
  pid_t reaping_pid_ = -1;  // a process being terminated
  int64_t kill_at_ms_ = 0;  // SIGKILL when it has not exited by then
  bool ever_connected_ = false;
  // The driver's stdout and stderr, relayed (drain_output).
  static constexpr size_t kMaxOutputLine = 1024;
  static constexpr int kOutputLinesPerS = 50, kOutputBurst = 200;
  struct Output {
    int fd = -1;
    std::string partial;           // a line not yet ended
    bool skipping = false;         // a cut line's rest, dropped up to its newline
    double tokens = kOutputBurst;  // the stream's own bucket of lines
    int64_t at_ms = 0;
    uint64_t dropped = 0;  // refused since the last line relayed
  };
  Output output_[2];
};

}  // namespace rcan::drivers
