// rcand — the RCAN robot node.
//
//   rcand                         the simulated robot with a generated identity in the default
//                                 data directory (first run creates keys, the audit chain
//                                 secret, a local token issuer and an OWNER token)
//   rcand --config FILE           a configured robot (.rcan.yaml, docs/CONFIG.md)
//   rcand … --port N --data-dir D overrides
#include <signal.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#include "daemon.h"
#include "rcan/json.h"
#include "rcan/version.h"
#include "runtime/log.h"
#include "sd_notify.h"

// Read by jemalloc, which rcand links (CMakeLists.txt), when it starts: a background thread
// hands freed pages back to the system once they have been unused for the decay time, also
// while the node is idle. Without it, memory a burst freed stays resident until the next
// allocations (the start-up scan of the audit segment alone reads 4 MiB at a time).
// One such thread serves every arena: by default jemalloc starts one more each time
// another arena is first used, so the node's thread count grew under load and stayed.
// Ignored where rcand runs on the C library's malloc.
extern "C" {
const char* malloc_conf = "background_thread:true,max_background_threads:1";
}

using namespace rcan;

int sim_layer_main(int argc, char** argv);   // sim_layer.cpp: `rcand --sim-layer …`
int init_main(int argc, char** argv);        // init.cpp: `rcand init …`
int config_doc_main(int argc, char** argv);  // config_doc.cpp: `rcand config-doc …`

namespace {

constexpr const char* kUsage =
    "usage: rcand [--config FILE] [--port N] [--bind ADDR] [--data-dir DIR] [--log-level "
    "debug|info|warn|error]\n"
    "       rcand init [--dir D] [--name NAME] … (a configured robot; rcand init --help)\n"
    "       rcand config-doc KEYS… | --check FILE | --write FILE (docs/CONFIG.md's key tables)\n"
    "       rcand --sim-layer [--port N] [--layer reactive|fast|planner] [--confidence C] "
    "[--delay-ms D]\n"
    "\n"
    "Without --config, rcand runs the embedded simulated robot. On its first run it creates, in\n"
    "the data directory (default $RCAND_DATA_DIR, else ~/.local/share/rcand): robot keys, the\n"
    "audit chain secret, a local token issuer and an OWNER token (owner.token, mode 0600).\n"
    "With --config, the robot's identity files must exist: `rcand init --dir D` creates them\n"
    "and a commented robot.rcan.yaml. SIGTERM or Ctrl-C stops it gracefully (drains requests,\n"
    "flushes the audit log).\n";

int fail(const std::string& what) {
  log(LogLevel::kError, "startup_failed", json::Object{{"error", what}});
  std::fprintf(stderr, "rcand: %s\n", what.c_str());
  return 1;
}

std::optional<rcand::DaemonOptions> parse_args(int argc, char** argv,
                                               std::optional<std::string>& log_level,
                                               int& exit_code) {
  rcand::DaemonOptions a;
  for (int i = 1; i < argc; ++i) {
    std::string s = argv[i];
    auto value = [&](const char* name) -> std::optional<std::string> {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "rcand: %s needs a value\n", name);
        return std::nullopt;
      }
      return std::string(argv[++i]);
    };
    if (s == "--help" || s == "-h") {
      std::fputs(kUsage, stdout);
      exit_code = 0;
      return std::nullopt;
    } else if (s == "--version") {
      std::printf("rcand %s (RCAN protocol 1.0.0)\n", std::string(kSoftwareVersion).c_str());
      exit_code = 0;
      return std::nullopt;
    } else if (s == "--config") {
      if (!(a.config = value("--config"))) return std::nullopt;
    } else if (s == "--data-dir") {
      if (!(a.data_dir = value("--data-dir"))) return std::nullopt;
    } else if (s == "--bind") {
      if (!(a.bind = value("--bind"))) return std::nullopt;
    } else if (s == "--log-level") {
      if (!(log_level = value("--log-level"))) return std::nullopt;
      a.log_level_given = true;
    } else if (s == "--port") {
      auto v = value("--port");
      if (!v) return std::nullopt;
      char* end = nullptr;
      long p = std::strtol(v->c_str(), &end, 10);
      if (!end || *end || p < 0 || p > 65535) {
        std::fprintf(stderr, "rcand: --port must be 0..65535\n");
        return std::nullopt;
      }
      a.port = static_cast<int>(p);
    } else {
      std::fprintf(stderr, "rcand: unknown argument '%s'\n%s", s.c_str(), kUsage);
      return std::nullopt;
    }
  }
  return a;
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
  if (argc > 1 && std::strcmp(argv[1], "--sim-layer") == 0) return sim_layer_main(argc, argv);
  if (argc > 1 && std::strcmp(argv[1], "init") == 0) return init_main(argc, argv);
  if (argc > 1 && std::strcmp(argv[1], "config-doc") == 0) return config_doc_main(argc, argv);
  int exit_code = 2;
  std::optional<std::string> log_level;
  auto options = parse_args(argc, argv, log_level, exit_code);
  if (!options) return exit_code;
  if (log_level) {
    auto lvl = parse_log_level(*log_level);
    if (!lvl) return fail("--log-level must be debug, info, warn or error");
    set_log_level(*lvl);
  }
  sigset_t signals = block_signals();

  rcand::Daemon daemon;
  if (Status s = daemon.start(*options); !s.ok()) return fail(s.error().message);
  const rcand::ServingInfo& info = daemon.info();
  if (info.local) {
    std::fprintf(
        stderr,
        "\nrcand is serving the simulated robot %s at %s\n"
        "%s token: %s (mode 0600, valid 24 h; a fresh one is written at the next start once\n"
        "  it has expired, and `rcan token issue --key <data dir>/issuer/ed25519.seed --iss\n"
        "  rcand-local --sub local-owner --role owner --aud RURI` mints more)\n"
        "Use it from another terminal:\n"
        "  export RCAN_URL=%s RCAN_TOKEN_FILE=%s\n"
        "  rcan status        # then: rcan claim, rcan command move --linear 0.3, rcan estop\n"
        "Dashboard: %s/ (sign in with the token in that file; docs/DASHBOARD.md)\n\n",
        info.ruri.c_str(), info.url.c_str(), info.token_created ? "New OWNER" : "OWNER",
        info.identity.owner_token_file.c_str(), info.url.c_str(),
        info.identity.owner_token_file.c_str(), info.url.c_str());
  }

  // Under systemd (Type=notify): ready now; the watchdog is fed while the safety loop turns.
  rcand::SystemdNotifier systemd;
  if (systemd.enabled()) {
    systemd.notify("READY=1\nSTATUS=serving " + info.ruri + " at " + info.url);
    systemd.start_watchdog(
        [&daemon] { return daemon.safety_loop_count(); },
        [&daemon] { daemon.safety_estop("safety loop stalled (systemd watchdog)"); });
  }

  // Run until SIGTERM / SIGINT.
  int sig = 0;
  sigwait(&signals, &sig);
  systemd.stop_watchdog();
  systemd.notify("STOPPING=1");
  log(LogLevel::kInfo, "shutting_down",
      json::Object{{"signal", sig == SIGTERM ? "SIGTERM" : "SIGINT"}});
  daemon.stop(2000);
  log(LogLevel::kInfo, "stopped",
      json::Object{{"audit_last_seq", static_cast<int64_t>(daemon.audit_last_seq())}});
  return 0;
}
