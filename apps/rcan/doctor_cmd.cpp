// rcan doctor — checks a robot's installation the way a support engineer would, and says what
// to fix: the configuration, the key and secret files' modes, the clock, the disk under the
// audit log, Avahi, the MQTT broker and the issuer URL, the node answering and its ESTOP.
#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <sys/timex.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "cli.h"
#include "config/config.h"
#include "node_http.h"
#include "rcan/client.h"
#include "transport/mqtt_client.h"

namespace rcan::cli {
namespace {

namespace fs = std::filesystem;

constexpr const char* kHelp =
    "usage: rcan doctor [--config FILE] [--url URL] [--token-file F] [--json]\n"
    "  Checks this machine's robot installation and prints one line per check: ok, warn or\n"
    "  FAIL, with what to do about it. The configuration is --config, else\n"
    "  /etc/rcan/robot.rcan.yaml when it exists; the node is --url (default: the configured\n"
    "  bind address and port, else $RCAN_URL or http://127.0.0.1:8080).\n"
    "  Checks: the configuration loads; robot keys, chain secret, issuer key and OWNER token\n"
    "  are 0600 in 0700 directories and owned by the node's user; the clock is synchronised;\n"
    "  the disk under the audit log has room; Avahi runs (when mDNS is on); the MQTT broker and\n"
    "  the issuer URL are reachable (when configured); the node answers, its audit log is\n"
    "  available and no ESTOP is latched.\n"
    "  Exit: 0 no FAIL, 1 at least one FAIL, 2 usage.\n";

enum class Level { kOk, kWarn, kFail };

struct Finding {
  Level level;
  std::string check;
  std::string detail;
  std::string fix;
};

class Report {
 public:
  void add(Level l, std::string check, std::string detail, std::string fix = {}) {
    items_.push_back({l, std::move(check), std::move(detail), std::move(fix)});
  }
  int print(bool as_json) const {
    bool failed = false;
    json::Array arr;
    for (const auto& f : items_) {
      failed = failed || f.level == Level::kFail;
      const char* name = f.level == Level::kOk ? "ok" : f.level == Level::kWarn ? "warn" : "FAIL";
      if (as_json) {
        json::Object o{{"level", name}, {"check", f.check}, {"detail", f.detail}};
        if (!f.fix.empty()) o.set("fix", f.fix);
        arr.emplace_back(std::move(o));
        continue;
      }
      std::printf("%-5s %-22s %s\n", name, f.check.c_str(), f.detail.c_str());
      if (!f.fix.empty()) std::printf("      %-22s → %s\n", "", f.fix.c_str());
    }
    if (as_json)
      std::printf("%s\n",
                  json::dump(json::Value(json::Object{{"ok", !failed}, {"checks", arr}})).c_str());
    return failed ? 1 : 0;
  }

 private:
  std::vector<Finding> items_;
};

std::string octal(unsigned mode) {
  char b[8];
  std::snprintf(b, sizeof b, "%04o", mode & 07777);
  return b;
}

// A secret file: regular, 0600 or stricter, owned by `uid`; its directory not group/world
// accessible.
void check_secret(Report& r, const std::string& what, const std::string& path, uid_t uid) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    r.add(Level::kFail, what, path + " is missing", "rcand init --dir <data dir> creates it");
    return;
  }
  if (!S_ISREG(st.st_mode)) {
    r.add(Level::kFail, what, path + " is not a regular file", "replace it with the file itself");
    return;
  }
  if (st.st_mode & 077) {
    r.add(Level::kFail, what, path + " is mode " + octal(st.st_mode) + " (others can read it)",
          "chmod 600 " + path);
    return;
  }
  if (st.st_uid != uid) {
    r.add(Level::kWarn, what,
          path + " is owned by uid " + std::to_string(st.st_uid) +
              ", the node's directory by uid " + std::to_string(uid),
          "chown " + std::to_string(uid) + " " + path);
    return;
  }
  const std::string dir = fs::path(path).parent_path().string();
  struct stat ds {};
  if (::stat(dir.c_str(), &ds) == 0 && (ds.st_mode & 077)) {
    r.add(Level::kWarn, what, path + " 0600, but its directory is " + octal(ds.st_mode),
          "chmod 700 " + dir);
    return;
  }
  r.add(Level::kOk, what, path + " 0600");
}

// TCP connect within `timeout_ms`.
bool reachable(const std::string& host, const std::string& port, int timeout_ms, std::string& why) {
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (int e = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &res); e != 0) {
    why = std::string("cannot resolve ") + host + ": " + gai_strerror(e);
    return false;
  }
  bool ok = false;
  for (addrinfo* a = res; a && !ok; a = a->ai_next) {
    int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) continue;
    if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) {
      ok = true;
    } else if (errno == EINPROGRESS) {
      pollfd p{fd, POLLOUT, 0};
      int err = 0;
      socklen_t len = sizeof err;
      ok = ::poll(&p, 1, timeout_ms) == 1 &&
           ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0;
    }
    ::close(fd);
  }
  ::freeaddrinfo(res);
  if (!ok && why.empty()) why = "no answer from " + host + ":" + port;
  return ok;
}

// Whether the host and port of a URL accept a TCP connection: `parse` is the project's own
// parser for that kind of URL (the MQTT client's broker URLs, the client library's endpoints).
template <typename Parse>
bool url_reachable(const std::string& url, Parse parse, std::string& why) {
  auto u = parse(url);
  if (!u.ok()) {
    why = u.error().message;
    return false;
  }
  return reachable(u->host, std::to_string(u->port), 3000, why);
}

void check_clock(Report& r) {
  timex tx{};
  const int state = ::adjtimex(&tx);
  if (state == TIME_ERROR || (tx.status & STA_UNSYNC))
    r.add(Level::kWarn, "clock", "not synchronised (adjtimex: unsynchronised)",
          "enable NTP (systemctl enable --now systemd-timesyncd, or chrony): tokens and "
          "replay windows depend on the time");
  else
    r.add(Level::kOk, "clock",
          "synchronised (estimated error " + std::to_string(tx.esterror / 1000) + " ms)");
}

void check_disk(Report& r, const config::NodeConfig& cfg) {
  std::string dir = cfg.security.audit.dir;
  while (!dir.empty() && !fs::exists(dir)) dir = fs::path(dir).parent_path().string();
  struct statvfs v {};
  if (dir.empty() || ::statvfs(dir.c_str(), &v) != 0) {
    r.add(Level::kWarn, "disk", "cannot read the free space under " + cfg.security.audit.dir);
    return;
  }
  const uint64_t free_b = uint64_t{v.f_bavail} * v.f_frsize;
  const uint64_t seg = cfg.security.audit.max_segment_bytes;
  const std::string text = std::to_string(free_b >> 20) + " MiB free under " + dir +
                           " (audit segments of " + std::to_string(seg >> 20) + " MiB)";
  if (free_b < 2 * seg)
    r.add(Level::kFail, "disk", text, "free space, or lower security.audit.max_segment_bytes");
  else if (free_b < 16 * seg)
    r.add(Level::kWarn, "disk", text,
          "set security.audit.retention.max_bytes so the log cannot fill the disk");
  else
    r.add(Level::kOk, "disk", text);
}

void check_node(Report& r, const std::string& url, const std::string& token) {
  client::ClientOptions co;
  co.url = url;
  co.token = token;
  co.timeout_ms = 3000;
  client::Client c(co);
  auto s = c.status();
  if (!s.ok()) {
    r.add(Level::kFail, "node", "no answer at " + url + ": " + s.error().message,
          "systemctl status rcand; journalctl -u rcand");
    return;
  }
  r.add(Level::kOk, "node", url + " answers: " + s->ruri);
  if (!s->audit_available)
    r.add(Level::kFail, "audit log", "unavailable: the node refuses commands",
          "check the disk under the audit directory (docs/NODE.md §Faults)");
  else
    r.add(Level::kOk, "audit log", "available");
  if (s->estop_active)
    r.add(Level::kWarn, "ESTOP", "latched: nothing moves", "rcan resume (LEASEE or above)");
  else
    r.add(Level::kOk, "ESTOP", "clear");
}

int doctor_main(const Args& args) {
  Options o(args, {"json"}, {"config", "url", "token-file"});
  if (!o.ok()) return usage_error("doctor", o.error());
  if (!o.positional().empty()) return usage_error("doctor", "unexpected " + o.positional()[0]);
  Report r;
  std::string cfg_path = o.get("config");
  if (cfg_path.empty() && fs::exists("/etc/rcan/robot.rcan.yaml"))
    cfg_path = "/etc/rcan/robot.rcan.yaml";
  std::optional<config::NodeConfig> cfg;
  if (cfg_path.empty()) {
    r.add(Level::kWarn, "configuration", "none given (--config) and no /etc/rcan/robot.rcan.yaml",
          "rcand init --dir D creates one; the embedded simulator needs none");
  } else if (auto c = config::load_config(cfg_path); !c.ok()) {
    r.add(Level::kFail, "configuration",
          // The loader's message names the file, the key, the line and the column.
          c.error().message.find(cfg_path) == std::string::npos
              ? cfg_path + ": " + c.error().message
              : c.error().message,
          "fix the key it names (docs/CONFIG.md)");
  } else {
    cfg = std::move(c).value();
    r.add(Level::kOk, "configuration", cfg_path + " loads (" + cfg->ruri + ")");
  }
  if (cfg) {
    struct stat ds {};
    const uid_t uid = ::stat(cfg->data_dir.c_str(), &ds) == 0 ? ds.st_uid : ::getuid();
    check_secret(r, "robot key (ML-DSA-65)", cfg->security.key_dir + "/mldsa65.seed", uid);
    check_secret(r, "robot key (Ed25519)", cfg->security.key_dir + "/ed25519.seed", uid);
    check_secret(r, "chain secret", cfg->security.audit.chain_secret_file, uid);
    const std::string issuer = (fs::path(cfg->data_dir) / "issuer/ed25519.seed").string();
    if (fs::exists(issuer)) check_secret(r, "token issuer key", issuer, uid);
    const std::string owner = (fs::path(cfg->data_dir) / "owner.token").string();
    if (fs::exists(owner)) check_secret(r, "OWNER token", owner, uid);
    check_disk(r, *cfg);
    if (cfg->server.enable_mdns) {
      if (fs::exists("/run/avahi-daemon/socket"))
        r.add(Level::kOk, "mDNS", "avahi-daemon runs");
      else
        r.add(Level::kWarn, "mDNS", "server.enable_mdns is on but avahi-daemon does not run",
              "apt install avahi-daemon; systemctl enable --now avahi-daemon");
    }
    if (cfg->mqtt.enabled) {
      // Every node of the list: a failover target that is down is found now, not in an outage.
      for (const std::string& broker : cfg->mqtt.broker_urls()) {
        std::string why;
        if (url_reachable(broker, transport::parse_broker_url, why))
          r.add(Level::kOk, "MQTT broker", broker + " accepts connections");
        else
          r.add(Level::kFail, "MQTT broker", broker + ": " + why,
                "start the broker or fix mqtt.broker; the fleet channel is down");
      }
    }
    if (!cfg->offline.issuer_url.empty()) {
      std::string why;
      if (url_reachable(cfg->offline.issuer_url, client::parse_endpoint, why))
        r.add(Level::kOk, "token issuer URL", cfg->offline.issuer_url + " reachable");
      else
        r.add(Level::kWarn, "token issuer URL", cfg->offline.issuer_url + ": " + why,
              "the robot runs OFFLINE_AUTONOMOUS until it is back (docs/SESSIONS.md)");
    }
  }
  check_clock(r);
  std::string url = o.get("url");
  if (url.empty() && cfg) {
    const std::string host =
        cfg->server.bind_address == "0.0.0.0" || cfg->server.bind_address.empty()
            ? "127.0.0.1"
            : cfg->server.bind_address;
    url = std::string(cfg->server.tls.enabled ? "https://" : "http://") + host + ":" +
          std::to_string(cfg->server.port);
  }
  if (url.empty()) url = node_url(o);
  std::string err;
  const std::string token = token_from(o, false, err);
  check_node(r, url, token);
  return r.print(o.has("json"));
}

int doctor_entry(const Args& args) {
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  return doctor_main(args);
}

const Registration kReg{"doctor", "check a robot's installation and say what to fix",
                        &doctor_entry};

}  // namespace
}  // namespace rcan::cli
