// systemd's service notification protocol (sd_notify(3)) without libsystemd: datagrams to the
// socket named by $NOTIFY_SOCKET. Under `Type=notify` rcand says READY=1 once it serves,
// STOPPING=1 when it shuts down, and, when the unit sets WatchdogSec (WATCHDOG_USEC in the
// environment), WATCHDOG=1 at half that period — but only while the safety core's control loop
// keeps turning. A loop that has not moved for a period is a hung node: rcand latches an ESTOP
// (from a thread of its own, in case the hang holds a lock) and stops feeding, so systemd
// restarts it and the robot comes back latched (docs/PACKAGING.md).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>

#include "base/thread_annotations.h"

namespace rcan::rcand {

class SystemdNotifier {
 public:
  // Reads NOTIFY_SOCKET, WATCHDOG_USEC and WATCHDOG_PID; does nothing when not under systemd.
  SystemdNotifier();
  ~SystemdNotifier();
  SystemdNotifier(const SystemdNotifier&) = delete;
  SystemdNotifier& operator=(const SystemdNotifier&) = delete;

  bool enabled() const { return !socket_path_.empty(); }
  int64_t watchdog_usec() const { return watchdog_usec_; }
  // Sends one notification ("READY=1\nSTATUS=…"); false when it could not be sent.
  bool notify(const std::string& text) const;

  // Feeds the watchdog every watchdog_usec/2 while `loop_count` advances between feeds;
  // the first time it does not, calls `on_stall` once (on a thread of its own) and stops
  // feeding. No-op without WATCHDOG_USEC.
  void start_watchdog(std::function<uint64_t()> loop_count, std::function<void()> on_stall);
  void stop_watchdog();

 private:
  std::string socket_path_;
  int64_t watchdog_usec_ = 0;
  std::thread feeder_;
  Mutex mu_;
  CondVar cv_;
  bool stop_ GUARDED_BY(mu_) = false;
};

}  // namespace rcan::rcand
