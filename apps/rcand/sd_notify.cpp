// systemd notifications and the watchdog fed by the safety loop (sd_notify.h).
#include "sd_notify.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>

#include "base/clock.h"
#include "runtime/log.h"

namespace rcan::rcand {

SystemdNotifier::SystemdNotifier() {
  const char* sock = std::getenv("NOTIFY_SOCKET");
  if (sock && *sock && (sock[0] == '/' || sock[0] == '@') &&
      std::strlen(sock) < sizeof(sockaddr_un::sun_path))
    socket_path_ = sock;
  const char* usec = std::getenv("WATCHDOG_USEC");
  const char* pid = std::getenv("WATCHDOG_PID");
  if (usec && *usec && (!pid || !*pid || std::strtoll(pid, nullptr, 10) == ::getpid())) {
    char* end = nullptr;
    long long v = std::strtoll(usec, &end, 10);
    if (end && !*end && v > 0) watchdog_usec_ = v;
  }
}

SystemdNotifier::~SystemdNotifier() { stop_watchdog(); }

bool SystemdNotifier::notify(const std::string& text) const {
  if (socket_path_.empty()) return false;
  int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, socket_path_.data(), socket_path_.size());
  if (addr.sun_path[0] == '@') addr.sun_path[0] = '\0';  // abstract namespace
  const socklen_t len =
      static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + socket_path_.size());
  ssize_t n = ::sendto(fd, text.data(), text.size(), MSG_NOSIGNAL,
                       reinterpret_cast<const sockaddr*>(&addr), len);
  ::close(fd);
  return n == static_cast<ssize_t>(text.size());
}

void SystemdNotifier::start_watchdog(std::function<uint64_t()> loop_count,
                                     std::function<void()> on_stall) {
  if (watchdog_usec_ <= 0 || socket_path_.empty() || feeder_.joinable()) return;
  const auto period = std::chrono::microseconds(watchdog_usec_ / 2);
  feeder_ = std::thread(
      [this, period, loop_count = std::move(loop_count), on_stall = std::move(on_stall)] {
        pthread_setname_np(pthread_self(), "sd-watchdog");
        // The safety loop turns at least once a second, so it is hung only when it has not turned
        // for max(2 s, half the watchdog period).
        const auto stall = std::max<std::chrono::microseconds>(period, std::chrono::seconds(2));
        uint64_t last = loop_count();
        auto last_turn = steady_now();
        (void)notify("WATCHDOG=1");
        for (;;) {
          {
            MutexLock lock(mu_);
            auto until = steady_now() + period;
            while (!stop_)
              if (cv_.wait_until(mu_, until) == std::cv_status::timeout) break;
            if (stop_) return;
          }
          const uint64_t now = loop_count();
          const auto t = steady_now();
          if (now != last) last_turn = t;
          if (now == last && t - last_turn >= stall) {
            // A hung node. Latch an ESTOP (it may block on the hang: its own thread) and let
            // systemd's watchdog restart the service.
            log(LogLevel::kError, "safety_loop_stalled",
                json::Object{{"watchdog_usec", watchdog_usec_},
                             {"action", "ESTOP, watchdog no longer fed"}});
            std::thread(on_stall).detach();
            return;
          }
          last = now;  // it turned within the stall time: alive
          (void)notify("WATCHDOG=1");
        }
      });
}

void SystemdNotifier::stop_watchdog() {
  {
    MutexLock lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (feeder_.joinable()) feeder_.join();
}

}  // namespace rcan::rcand
