// A pseudo-terminal that plays a serial-port robot base in the driver tests: the driver under
// test opens slave_path() as its serial port; the test reads the lines it writes and answers
// on the master side. The test keeps a slave descriptor open itself, so that the master reads
// nothing (instead of EIO) while the driver has the port closed (between restarts).
// Header-only.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>

namespace rcan::test {

class PtyBase {
 public:
  PtyBase() {
    master_ = posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (master_ < 0 || grantpt(master_) != 0 || unlockpt(master_) != 0) return;
    const char* name = ptsname(master_);
    if (!name) return;
    slave_path_ = name;
    hold_ = ::open(name, O_RDWR | O_NOCTTY | O_CLOEXEC);
    termios t{};
    if (hold_ >= 0 && tcgetattr(hold_, &t) == 0) {
      cfmakeraw(&t);
      tcsetattr(hold_, TCSANOW, &t);
    }
  }
  ~PtyBase() {
    if (hold_ >= 0) ::close(hold_);
    if (master_ >= 0) ::close(master_);
  }
  PtyBase(const PtyBase&) = delete;
  PtyBase& operator=(const PtyBase&) = delete;

  bool ok() const { return master_ >= 0 && hold_ >= 0; }
  const std::string& slave_path() const { return slave_path_; }

  // The next line the driver wrote (without '\n'), or nullopt after `timeout_ms`.
  std::optional<std::string> line(int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (true) {
      const size_t nl = buf_.find('\n');
      if (nl != std::string::npos) {
        std::string l = buf_.substr(0, nl);
        buf_.erase(0, nl + 1);
        if (!l.empty() && l.back() == '\r') l.pop_back();
        return l;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                            deadline - std::chrono::steady_clock::now())
                            .count();
      if (left <= 0) return std::nullopt;
      pollfd p{master_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left)) <= 0) continue;
      char b[512];
      const ssize_t n = ::read(master_, b, sizeof b);
      if (n > 0) buf_.append(b, static_cast<size_t>(n));
    }
  }
  // The first line starting with `prefix` within `timeout_ms` (other lines are skipped).
  std::optional<std::string> line_starting(const std::string& prefix, int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                            deadline - std::chrono::steady_clock::now())
                            .count();
      if (left <= 0) return std::nullopt;
      auto l = line(static_cast<int>(left));
      if (!l) return std::nullopt;
      if (l->rfind(prefix, 0) == 0) return l;
    }
  }
  // Everything the driver wrote so far is dropped.
  void drain() {
    while (line(20)) {
    }
    buf_.clear();
  }
  // Writes a line from the base to the driver.
  void say(const std::string& l) {
    const std::string s = l + "\n";
    [[maybe_unused]] ssize_t n = ::write(master_, s.data(), s.size());
  }

 private:
  int master_ = -1;
  int hold_ = -1;
  std::string slave_path_;
  std::string buf_;
};

}  // namespace rcan::test
