// `rcand init`: a configured robot in one command — its robot.rcan.yaml, robot keys, audit
// chain secret, a local token issuer and an OWNER token — idempotent: an existing file is kept,
// never replaced (an OWNER token only once it has expired). docs/NODE.md, "A configured robot".
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "base/clock.h"
#include "config/config.h"
#include "identity.h"
#include "rcan/audit/env.h"
#include "rcan/audit/secret.h"
#include "rcan/crypto/keys.h"
#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace fs = std::filesystem;
using namespace rcan;

namespace {

constexpr const char* kInitUsage =
    "usage: rcand init [--dir D] [--name NAME] [--manufacturer M] [--model M] [--type TYPE]\n"
    "                  [--registry R] [--driver sim|ros2|process] [--port N] [--bind ADDR] "
    "[--issuer NAME]\n"
    "                  [--config FILE] [--join URL --registry-key FILE [--endpoint URL]] [--yes]\n"
    "\n"
    "Creates a configured robot in D (default: the data directory rcand uses, $RCAND_DATA_DIR,\n"
    "else ~/.local/share/rcand): D/robot.rcan.yaml (commented; its data directory is D), robot\n"
    "keys in D/keys, the audit chain secret D/audit.secret, a local token issuer in D/issuer and\n"
    "an OWNER token D/owner.token (secrets 0600 in 0700 directories). Run it again at any time:\n"
    "it keeps every file that exists (a new OWNER token only replaces an expired one), and on a\n"
    "robot.rcan.yaml of your own it creates the identity files that file names.\n"
    "--config FILE writes (or reads) the configuration there instead of D/robot.rcan.yaml, its\n"
    "data directory naming D (a packaged install: --dir /var/lib/rcand --config\n"
    "/etc/rcan/robot.rcan.yaml).\n"
    "--join URL writes a `registry` block: at its first start the robot registers with the\n"
    "rcan-registry at URL using the registrant API key in --registry-key FILE (mode 0600),\n"
    "publishes --endpoint URL as where it answers, and trusts the registry's tokens\n"
    "(docs/REGISTRY.md).\n"
    "On a terminal it asks for the robot's name, manufacturer and model; --yes takes the\n"
    "defaults and the flags. Then: rcand --config D/robot.rcan.yaml\n";

struct InitOptions {
  std::string dir;
  std::string name = "my-robot";
  std::string manufacturer = "acme";
  std::string model = "rover";
  std::string type = "mobile_differential_with_arm";
  std::string registry = "local.rcan";
  std::string driver = "sim";
  std::string bind = "127.0.0.1";
  std::string issuer = "rcand-local";
  std::string config;  // the robot.rcan.yaml to write or read; default <dir>/robot.rcan.yaml
  std::string join, registry_key, endpoint;  // --join: the registry block
  int port = 8080;
  bool yes = false;
  std::vector<std::string> given;  // the flags named on the command line
};

bool given(const InitOptions& o, const std::string& flag) {
  for (const auto& g : o.given)
    if (g == flag) return true;
  return false;
}

// A name segment of a RURI: lower-case letters, digits and '-', 1–64 characters.
bool segment_ok(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  for (char c : s)
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-')) return false;
  return true;
}

// A registry: a host name (lower-case letters, digits, '-' and '.'), 1–253 characters.
bool registry_ok(const std::string& s) {
  if (s.empty() || s.size() > 253 || s.front() == '.' || s.back() == '.') return false;
  for (char c : s)
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '.')) return false;
  return true;
}

std::optional<InitOptions> parse(int argc, char** argv, int& code) {
  InitOptions o;
  code = 2;
  for (int i = 2; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(kInitUsage, stdout);
      code = 0;
      return std::nullopt;
    }
    if (a == "--yes" || a == "-y") {
      o.yes = true;
      continue;
    }
    std::string* target = a == "--dir"            ? &o.dir
                          : a == "--name"         ? &o.name
                          : a == "--manufacturer" ? &o.manufacturer
                          : a == "--model"        ? &o.model
                          : a == "--type"         ? &o.type
                          : a == "--registry"     ? &o.registry
                          : a == "--driver"       ? &o.driver
                          : a == "--bind"         ? &o.bind
                          : a == "--issuer"       ? &o.issuer
                          : a == "--config"       ? &o.config
                          : a == "--join"         ? &o.join
                          : a == "--registry-key" ? &o.registry_key
                          : a == "--endpoint"     ? &o.endpoint
                                                  : nullptr;
    if (!target && a != "--port") {
      std::fprintf(stderr, "rcand init: unknown argument '%s'\n%s", a.c_str(), kInitUsage);
      return std::nullopt;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "rcand init: %s needs a value\n", a.c_str());
      return std::nullopt;
    }
    std::string v = argv[++i];
    o.given.push_back(a);
    if (target) {
      *target = v;
      continue;
    }
    char* end = nullptr;
    long p = std::strtol(v.c_str(), &end, 10);
    if (!end || *end || p < 1 || p > 65535) {
      std::fprintf(stderr, "rcand init: --port must be 1..65535\n");
      return std::nullopt;
    }
    o.port = static_cast<int>(p);
  }
  return o;
}

// On a terminal, asks for what the flags did not give.
void ask(InitOptions& o) {
  if (o.yes || !::isatty(STDIN_FILENO)) return;
  auto prompt = [](const char* what, std::string& value) {
    std::cout << what << " [" << value << "]: " << std::flush;
    std::string line;
    if (std::getline(std::cin, line) && !line.empty()) value = line;
  };
  if (!given(o, "--name")) prompt("Robot name", o.name);
  if (!given(o, "--manufacturer")) prompt("Manufacturer (lower case, a-z 0-9 -)", o.manufacturer);
  if (!given(o, "--model")) prompt("Model (lower case, a-z 0-9 -)", o.model);
}

std::string yaml_quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

std::string template_yaml(const InitOptions& o, const std::string& ruri,
                          const std::string& yaml_path) {
  std::time_t t = static_cast<std::time_t>(unix_seconds());
  char date[32];
  std::strftime(date, sizeof date, "%Y-%m-%d", std::gmtime(&t));
  std::string y;
  y += "# robot.rcan.yaml — written by `rcand init` on " + std::string(date) + ".\n";
  y += "#\n#   rcand --config " + yaml_path + "\n#\n";
  y += "# Every key, its type and default: docs/CONFIG.md; a fuller commented example:\n";
  y += "# examples/sim-robot.rcan.yaml. Loading is strict (an unknown or misspelt key stops\n";
  y += "# start-up, naming it). Relative paths resolve against this file's directory.\n\n";
  y += "rcan_version: \"1.2\"\n\n";
  y += "# The robot's identity: rcan://<registry>/<manufacturer>/<model>/<device-id>.\n";
  y += "ruri: " + ruri + "\n\n";
  y += "robot:\n";
  y += "  name: " + yaml_quote(o.name) + "         # mDNS instance and the dashboard's title\n";
  y += "  manufacturer: " + o.manufacturer + "\n";
  y += "  model: " + o.model + "\n";
  y += "  type: " + o.type + "   # the protocol capabilities follow from it\n\n";
  y += "node:\n";
  // Paths relative to this file when it lives in the data directory, else absolute.
  const bool beside = fs::path(yaml_path).parent_path() == fs::path(o.dir);
  const std::string in_dir = beside ? std::string() : o.dir + "/";
  y += "  data_dir: " + (beside ? std::string(".") : yaml_quote(o.dir)) +
       "        # keys/, audit/, audit.secret, issuer/ and owner.token live here\n";
  y += "  log_level: info\n\n";
  y += "server:\n";
  y += "  port: " + std::to_string(o.port) + "\n";
  y += "  # 127.0.0.1 keeps the robot private to this machine. To reach it from elsewhere:\n";
  y += "  # bind: 0.0.0.0 with tls: {enabled: true, cert_file: …, key_file: …}\n";
  y += "  bind: " + o.bind + "\n\n";
  y += "security:\n";
  y += "  jwt:\n";
  y += "    # JWTs are always required. The local issuer `rcand init` made; mint tokens with\n";
  y += "    #   rcan token issue --key " + in_dir + "issuer/ed25519.seed --iss " + o.issuer +
       " --aud <ruri> --sub …\n";
  y += "    # Add your organisation's issuer beside it ({issuer, key_file: PEM, JWK or JWKS}).\n";
  y += "    issuers:\n";
  y += "      - {issuer: " + yaml_quote(o.issuer) +
       ", key_file: " + yaml_quote(in_dir + "issuer/ed25519.pub.pem") + "}\n";
  y += "  audit:\n";
  y += "    sync: per_group\n";
  y += "    # Segments of max_segment_bytes, the next one preallocated; retention bounds the\n";
  y += "    # total. Small disks: lower both.\n";
  y += "    # max_segment_bytes: 16777216\n";
  y += "    # retention: {max_bytes: 0, max_age_days: 0}   # 0 = unlimited\n\n";
  y += "safety:\n";
  y += "  local_safety_wins: true         # must be true\n";
  y += "  max_linear_speed_mps: 0.5\n";
  y += "  max_angular_speed_radps: 1.0\n";
  y += "  workspace: {x_min: -5.0, x_max: 5.0, y_min: -5.0, y_max: 5.0}   # metres\n";
  y += "  limit_policy: {speed: clamp, joints: reject, workspace: reject}\n";
  y += "  heartbeat_timeout_ms: 2000      # the deadman of a control session\n\n";
  y += "watchdog:\n  enabled: true\n  timeout_s: 10\n\n";
  if (!o.join.empty()) {
    y += "# The registry this robot joins (docs/REGISTRY.md): it registers at its first start\n";
    y += "# (proving it holds its keys), takes the registry's RRN, keeps its endpoint fresh, and\n";
    y += "# accepts the tokens the registry issues for it.\n";
    y += "registry:\n";
    y += "  registry_url: " + yaml_quote(o.join) + "\n";
    y += "  key_file: " + yaml_quote(o.registry_key) + "   # a registrant API key, mode 0600\n";
    if (!o.endpoint.empty()) y += "  endpoint: " + yaml_quote(o.endpoint) + "\n";
    y += "  trust_tokens: true\n\n";
  } else {
    y += "# To join a registry (docs/REGISTRY.md):\n";
    y += "# registry: {registry_url: https://registry.example.com, key_file: registrant.key,\n";
    y += "#            endpoint: https://this-robot.example.com:8080, trust_tokens: true}\n\n";
  }
  y += "driver:\n";
  if (o.driver == "ros2") {
    y += "  type: ros2   # a ROS 2 robot over DDS, no ROS installation needed (docs/DRIVERS.md)\n";
    y += "  ros2:\n";
    y += "    domain_id: 0          # the robot's ROS_DOMAIN_ID\n";
    y += "    namespace: \"\"         # e.g. /robot1\n";
    y += "    cmd_vel_topic: cmd_vel            # geometry_msgs/msg/Twist, out\n";
    y += "    odom_topic: odom                  # nav_msgs/msg/Odometry, in\n";
    y += "    joint_states_topic: joint_states  # sensor_msgs/msg/JointState, in\n";
    y += "    cmd_rate_hz: 20       # Twists (and zero Twists while stopped) per second\n";
    y += "    odom_timeout_ms: 1000 # no odometry this long: a driver fault, the robot stops\n";
    y += "    max_linear_mps: 0.5   # the base's own limits (safety.* may only lower them)\n";
    y += "    max_angular_radps: 1.0\n";
    y += "    # arm_topic: arm_controller/joint_trajectory   # "
         "trajectory_msgs/msg/JointTrajectory\n";
    y += "    # arm_joints: [joint1, joint2, joint3, joint4, joint5, joint6]\n";
    y += "    # Keep DDS off other networks: CYCLONEDDS_URI in the service's environment.\n";
  } else if (o.driver == "process") {
    y += "  type: process   # a driver process on a Unix socket, in any language "
         "(docs/DRIVERS.md)\n";
    y += "  process:\n";
    y += "    # The reference driver: a serial differential base (examples/drivers/).\n";
    y += "    command: [/usr/bin/python3, /usr/share/rcan/examples/drivers/serial_diffbase.py,\n";
    y += "              --port, /dev/ttyUSB0]\n";
    y += "    heartbeat_ms: 100\n";
    y += "    heartbeat_timeout_ms: 500   # silence this long: a driver fault, the robot stops\n";
    y += "    max_linear_mps: 0.5         # the base's own limits (safety.* may only lower them)\n";
    y += "    max_angular_radps: 1.0\n";
  } else {
    y += "  type: " + o.driver + "   # the simulated robot (docs/CONFIG.md, `driver`)\n";
  }
  return y;
}

std::string join(const std::string& dir, const std::string& name) {
  return (fs::path(dir) / name).lexically_normal().string();
}

void line(const char* what, const std::string& path, bool created) {
  std::printf("  %-8s %-13s %s\n", created ? "created" : "kept", what, path.c_str());
}

// The options of a robot that has no configuration yet, asked for when not given; 0, or the
// exit code after saying what is wrong.
int settle_new_robot_options(InitOptions& o) {
  ask(o);
  if (o.driver != "sim" && o.driver != "ros2" && o.driver != "process") {
    std::fprintf(stderr, "rcand init: --driver is sim, ros2 or process (not %s)\n",
                 o.driver.c_str());
    return 2;
  }
  if (!o.join.empty() && (o.registry_key.empty() ||
                          (o.join.rfind("http://", 0) != 0 && o.join.rfind("https://", 0) != 0) ||
                          (!o.endpoint.empty() && o.endpoint.rfind("http://", 0) != 0 &&
                           o.endpoint.rfind("https://", 0) != 0))) {
    std::fprintf(stderr,
                 "rcand init: --join needs an http(s) URL and --registry-key FILE; --endpoint "
                 "an http(s) URL\n");
    return 2;
  }
  if (!o.registry_key.empty()) o.registry_key = fs::absolute(o.registry_key).string();
  if (!segment_ok(o.manufacturer) || !segment_ok(o.model) || !registry_ok(o.registry)) {
    std::fprintf(stderr,
                 "rcand init: --manufacturer and --model are RURI segments (lower-case letters, "
                 "digits and '-', 1-64 characters); --registry a host name\n");
    return 2;
  }
  return 0;
}

// A new robot's configuration file, with a RURI of its own (a random device id).
int write_new_config(const InitOptions& o, const std::string& yaml_path) {
  uint8_t b[4];
  if (!random_bytes(b, sizeof b)) {
    std::fprintf(stderr, "rcand init: no randomness\n");
    return 1;
  }
  std::string ruri =
      "rcan://" + o.registry + "/" + o.manufacturer + "/" + o.model + "/" + to_hex(b, sizeof b);
  std::string text = template_yaml(o, ruri, yaml_path);
  std::error_code ec;
  fs::create_directories(fs::path(yaml_path).parent_path(), ec);
  if (Status s = keys::write_new_file(
          yaml_path, {reinterpret_cast<const uint8_t*>(text.data()), text.size()}, 0644);
      !s.ok()) {
    std::fprintf(stderr, "rcand init: %s\n", s.error().message.c_str());
    return 1;
  }
  return 0;
}

// The identity files the configuration names: the robot's keys, the audit chain secret, the
// local token issuer and the OWNER token (each created when missing, the token when expired).
int make_identity_files(const InitOptions& o, const config::NodeConfig& cfg,
                        rcand::LocalIdentity& id) {
  const std::string key_dir = cfg.security.key_dir;
  const bool have_keys = fs::exists(key_dir + "/" + std::string(keys::kMldsaSeedFile));
  auto k = rcand::robot_keys(cfg, /*create=*/true);
  if (!k.ok()) {
    std::fprintf(stderr, "rcand init: %s\n", k.error().message.c_str());
    return 1;
  }
  line("robot keys", key_dir + " (kid " + k->pub.kid() + ")", !have_keys);
  const std::string& secret_file = cfg.security.audit.chain_secret_file;
  const bool have_secret = fs::exists(secret_file);
  if (auto s = rcand::chain_secret(cfg, /*create=*/true); !s.ok()) {
    std::fprintf(stderr, "rcand init: %s\n", s.error().message.c_str());
    return 1;
  }
  line("chain secret", secret_file, !have_secret);
  id.issuer = o.issuer;
  id.issuer_seed_file = join(cfg.data_dir, "issuer/" + std::string(keys::kIssuerSeedFile));
  id.owner_token_file = join(cfg.data_dir, "owner.token");
  const bool have_issuer = fs::exists(id.issuer_seed_file);
  const bool had_token = fs::exists(id.owner_token_file);
  jwt::TrustStore trust;
  bool token_created = false;
  if (Status s = rcand::ensure_issuer_and_token(id, cfg.ruri, trust, token_created); !s.ok()) {
    std::fprintf(stderr, "rcand init: %s\n", s.error().message.c_str());
    return 1;
  }
  line("token issuer", join(cfg.data_dir, "issuer") + " (" + o.issuer + ")", !have_issuer);
  line("OWNER token",
       id.owner_token_file + (token_created && had_token ? " (expired: renewed)" : ""),
       token_created);
  return 0;
}

// What init leaves to the user: a warning when the file does not trust the local issuer, the
// audit log's first segment, and the commands to run next.
void print_next_steps(const InitOptions& o, const config::NodeConfig& cfg,
                      const std::string& yaml_path, const rcand::LocalIdentity& id) {
  const std::string pub = join(cfg.data_dir, "issuer/" + std::string(keys::kIssuerPubFile));
  bool trusted = false;
  for (const auto& i : cfg.security.jwt.issuers)
    if (i.issuer == o.issuer && fs::equivalent(i.key_file, pub)) trusted = true;
  if (!trusted)
    std::printf(
        "\n  warning: %s does not trust the local issuer; add under security.jwt.issuers:\n"
        "    - {issuer: %s, key_file: %s}\n",
        yaml_path.c_str(), o.issuer.c_str(), pub.c_str());
  const uint64_t seg = cfg.security.audit.max_segment_bytes;
  std::printf(
      "\nThe audit log (%s) starts as one zero-filled segment of %llu MiB; the next is prepared\n"
      "once it is half full, so it holds at most %llu MiB before the first rotation\n"
      "(security.audit.max_segment_bytes; retention bounds the total).\n",
      cfg.security.audit.dir.c_str(), static_cast<unsigned long long>(seg >> 20),
      static_cast<unsigned long long>((2 * seg) >> 20));
  std::printf(
      "\nNext:\n"
      "  rcand --config %s\n"
      "  export RCAN_URL=http://%s:%d RCAN_TOKEN_FILE=%s\n"
      "  rcan status        # then: rcan claim, rcan command move --linear 0.3, rcan estop\n"
      "The OWNER token is valid 24 h: `rcand init --dir %s` again replaces it once it has\n"
      "expired (and changes nothing else); tokens for others: rcan token issue --key %s --iss %s\n"
      "  --aud %s --sub NAME --role user --scope status,control\n",
      yaml_path.c_str(),
      cfg.server.bind_address == "0.0.0.0" ? "127.0.0.1" : cfg.server.bind_address.c_str(),
      cfg.server.port, id.owner_token_file.c_str(), o.dir.c_str(), id.issuer_seed_file.c_str(),
      o.issuer.c_str(), cfg.ruri.c_str());
}

int init(InitOptions o) {
  if (o.dir.empty()) {
    auto d = config::default_data_dir();
    if (!d.ok()) {
      std::fprintf(stderr, "rcand init: %s (give --dir D)\n", d.error().message.c_str());
      return 1;
    }
    o.dir = *d;
  }
  o.dir = fs::absolute(o.dir).lexically_normal().string();
  if (!o.dir.empty() && o.dir.size() > 1 && o.dir.back() == '/') o.dir.pop_back();
  const std::string yaml_path = o.config.empty()
                                    ? o.dir + "/robot.rcan.yaml"
                                    : fs::absolute(o.config).lexically_normal().string();
  const bool have_yaml = fs::exists(yaml_path);
  if (!have_yaml)
    if (int rc = settle_new_robot_options(o); rc != 0) return rc;
  if (Status s = rcand::make_private_dir(o.dir); !s.ok()) {
    std::fprintf(stderr, "rcand init: %s\n", s.error().message.c_str());
    return 1;
  }
  std::printf("rcand init: a configured robot in %s\n", o.dir.c_str());
  if (!have_yaml)
    if (int rc = write_new_config(o, yaml_path); rc != 0) return rc;
  line("config", yaml_path, !have_yaml);
  auto cfg = config::load_config(yaml_path);
  if (!cfg.ok()) {
    const Error& e = cfg.error();
    std::fprintf(stderr, "rcand init: %s: %s%s\n", yaml_path.c_str(),
                 e.field.empty() ? "" : (e.field + ": ").c_str(), e.message.c_str());
    return 1;
  }
  rcand::LocalIdentity id;
  if (int rc = make_identity_files(o, *cfg, id); rc != 0) return rc;
  print_next_steps(o, *cfg, yaml_path, id);
  return 0;
}

}  // namespace

int init_main(int argc, char** argv) {
  int code = 2;
  auto o = parse(argc, argv, code);
  if (!o) return code;
  return init(std::move(*o));
}
