// A PostgreSQL server for tests: a fresh cluster (initdb) in a temporary directory, the server
// on a free loopback port, trust authentication for the user "rcan". PostgreSQL refuses to run
// as root: under root the server runs as the `postgres` system user (setpriv).
#pragma once

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "test_support.h"

namespace rcan::test {

class Postgres {
 public:
  Postgres() : port_(free_loopback_port()) {
    namespace fs = std::filesystem;
    std::vector<char> tmpl{'/', 't', 'm', 'p', '/', 'r', 'c', 'a', 'n', '-',
                           'p', 'g', '-', 'X', 'X', 'X', 'X', 'X', 'X', '\0'};
    dir_ = ::mkdtemp(tmpl.data());
    std::error_code ec;
    for (const auto& e : fs::directory_iterator("/usr/lib/postgresql", ec))
      if (fs::exists(e.path() / "bin/postgres")) bin_ = (e.path() / "bin").string();
    EXPECT_FALSE(bin_.empty()) << "PostgreSQL is not installed (scripts/install-deps.sh)";
    if (::getuid() == 0) {
      struct passwd* pw = ::getpwnam("postgres");
      EXPECT_NE(pw, nullptr);
      if (pw != nullptr) {
        EXPECT_EQ(::chown(dir_.c_str(), pw->pw_uid, pw->pw_gid), 0);
        as_ = {"/usr/bin/setpriv", "--reuid=postgres", "--regid=postgres", "--init-groups"};
      }
    }
    auto init = run(with_user({bin_ + "/initdb", "-D", dir_ + "/data", "-A", "trust", "-U", "rcan",
                               "--no-sync", "-E", "UTF8"}));
    EXPECT_EQ(init.exit_code, 0) << init.out << init.err;
    EXPECT_TRUE(proc_.start(
        with_user({bin_ + "/postgres", "-D", dir_ + "/data", "-p", std::to_string(port_), "-k",
                   dir_, "-c", "listen_addresses=127.0.0.1", "-c", "fsync=off"})));
    EXPECT_TRUE(proc_.wait_for_line("ready to accept connections", 30000)) << proc_.err();
  }
  ~Postgres() {
    if (proc_.running()) proc_.stop(SIGTERM, 15000);
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  Postgres(const Postgres&) = delete;
  Postgres& operator=(const Postgres&) = delete;

  uint16_t port() const { return port_; }
  std::string conninfo(const std::string& dbname = "postgres") const {
    return "host=127.0.0.1 port=" + std::to_string(port_) + " user=rcan dbname=" + dbname;
  }
  // postgresql://rcan@127.0.0.1:<port>/<dbname>
  std::string url(const std::string& dbname = "postgres") const {
    return "postgresql://rcan@127.0.0.1:" + std::to_string(port_) + "/" + dbname;
  }
  RunResult sql(const std::string& statement, const std::string& dbname = "postgres") const {
    return run({bin_ + "/psql", conninfo(dbname), "-v", "ON_ERROR_STOP=1", "-At", "-c", statement});
  }

 private:
  static uint16_t free_loopback_port() {
    int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    ::close(fd);
    return ntohs(a.sin_port);
  }
  std::vector<std::string> with_user(std::vector<std::string> argv) const {
    argv.insert(argv.begin(), as_.begin(), as_.end());
    return argv;
  }
  uint16_t port_;
  std::string dir_, bin_;
  std::vector<std::string> as_;
  Process proc_;
};

}  // namespace rcan::test
