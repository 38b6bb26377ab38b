// rcand under systemd's Type=notify, with the socket systemd would give it: READY=1 once it
// serves (with a STATUS line), WATCHDOG=1 at half of WATCHDOG_USEC while the safety loop turns,
// STOPPING=1 on SIGTERM; and nothing is sent for another process's WATCHDOG_PID.
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <optional>
#include <string>

#include "test_support.h"

namespace rcan {
namespace {

// The datagram socket systemd listens on ($NOTIFY_SOCKET).
class NotifySocket {
 public:
  explicit NotifySocket(const std::string& path) : path_(path) {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strncpy(a.sun_path, path.c_str(), sizeof a.sun_path - 1);
    EXPECT_EQ(::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0) << std::strerror(errno);
  }
  ~NotifySocket() {
    ::close(fd_);
    ::unlink(path_.c_str());
  }
  std::optional<std::string> next(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) != 1) return std::nullopt;
    char buf[4096];
    ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
    if (n < 0) return std::nullopt;
    return std::string(buf, static_cast<size_t>(n));
  }
  // The next datagram containing `what`, within `timeout_ms`.
  std::optional<std::string> wait_for(const std::string& what, int timeout_ms) {
    auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < end) {
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                      end - std::chrono::steady_clock::now())
                      .count();
      auto m = next(static_cast<int>(std::max<int64_t>(1, left)));
      if (m && m->find(what) != std::string::npos) return m;
    }
    return std::nullopt;
  }

 private:
  std::string path_;
  int fd_ = -1;
};

TEST(SystemdNotify, ReadyThenWatchdogFeedsWhileTheSafetyLoopTurnsThenStopping) {
  test::TempDir tmp;
  NotifySocket sock(tmp.file("notify.sock"));
  test::Process node;
  ASSERT_TRUE(node.start({RCAND_PATH, "--data-dir", tmp.file("data"), "--port", "0"},
                         {"NOTIFY_SOCKET=" + tmp.file("notify.sock"), "WATCHDOG_USEC=400000"}));
  auto ready = sock.wait_for("READY=1", 20000);
  ASSERT_TRUE(ready.has_value()) << node.err();
  EXPECT_NE(ready->find("STATUS=serving rcan://"), std::string::npos) << *ready;
  ASSERT_TRUE(node.wait_for_line("\"listening\"", 5000).has_value());
  // Half of 400 ms: about ten feeds in two seconds; at least five.
  int feeds = 0;
  auto end = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (std::chrono::steady_clock::now() < end)
    if (auto m = sock.next(500); m && *m == "WATCHDOG=1") ++feeds;
  EXPECT_GE(feeds, 5);
  EXPECT_LE(feeds, 14);
  ASSERT_EQ(::kill(node.pid(), SIGTERM), 0);
  EXPECT_TRUE(sock.wait_for("STOPPING=1", 10000).has_value());
  EXPECT_EQ(node.stop(SIGTERM, 10000), 0) << node.err();
}

TEST(SystemdNotify, AWatchdogMeantForAnotherProcessIsNotFed) {
  test::TempDir tmp;
  NotifySocket sock(tmp.file("notify.sock"));
  test::Process node;
  ASSERT_TRUE(node.start(
      {RCAND_PATH, "--data-dir", tmp.file("data"), "--port", "0"},
      {"NOTIFY_SOCKET=" + tmp.file("notify.sock"), "WATCHDOG_USEC=200000", "WATCHDOG_PID=1"}));
  ASSERT_TRUE(sock.wait_for("READY=1", 20000).has_value()) << node.err();
  EXPECT_FALSE(sock.wait_for("WATCHDOG=1", 1000).has_value());
  EXPECT_EQ(node.stop(SIGTERM, 10000), 0) << node.err();
}

}  // namespace
}  // namespace rcan
