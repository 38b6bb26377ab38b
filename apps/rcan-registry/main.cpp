// rcan-registry — the RCAN robot registry daemon (docs/REGISTRY.md).
//
//   rcan-registry                  the embedded default: SQLite in the data directory, port
//                                  8090 on 127.0.0.1; the first start creates an admin key
//   rcan-registry --help           the flags
#include <signal.h>

#include <cstdio>
#include <string>

#include "daemon.h"
#include "runtime/log.h"
#include "setup.h"

using namespace rcan;

namespace {

int fail(const std::string& msg) {
  std::fprintf(stderr, "rcan-registry: %s\n", msg.c_str());
  return 1;
}

sigset_t block_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  signal(SIGPIPE, SIG_IGN);
  return set;
}

}  // namespace

int main(int argc, char** argv) {
  int exit_code = 2;
  auto flags = registry_app::parse_flags(argc, argv, exit_code);
  if (!flags) return exit_code;
  sigset_t signals = block_signals();

  registry_app::Daemon daemon;
  if (Status s = daemon.start(*flags); !s.ok()) return fail(s.error().message);

  // Run until SIGTERM / SIGINT.
  int sig = 0;
  sigwait(&signals, &sig);
  log(LogLevel::kInfo, "shutting_down",
      json::Object{{"signal", sig == SIGTERM ? "SIGTERM" : "SIGINT"}});
  daemon.stop(2000);
  log(LogLevel::kInfo, "stopped");
  return 0;
}
