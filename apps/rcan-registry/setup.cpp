#include "setup.h"

#include <fcntl.h>
#include <pwd.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <vector>

#include "rcan/audit/secret.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/keys.h"
#include "registry/api/address.h"
#include "runtime/data_dir.h"

namespace rcan::registry_app {
namespace fs = std::filesystem;

namespace {

constexpr const char* kUsage =
    "usage: rcan-registry [--config FILE] [--port N] [--bind ADDR] [--data-dir DIR]\n"
    "                     [--database SPEC]\n"
    "                     [--public-url URL] [--host NAME] [--prefix P] [--operator NAME]\n"
    "                     [--contact EMAIL] [--write-rate R] [--write-burst B]\n"
    "                     [--address-write-rate R] [--anonymous-rate R] [--read-rate R]\n"
    "                     [--trusted-proxy CIDR]… [--io-threads N]\n"
    "                     [--key-overlap S] [--key-lifetime S] [--max-token-ttl S]\n"
    "                     [--device-code-ttl S] [--webhook-backoff-ms MS]\n"
    "                     [--webhook-timeout-ms MS] [--sync-from URL]… [--sync-delegations]\n"
    "                     [--sync-interval S]\n"
    "                     [--allow-http-node-urls] [--allow-private-webhooks]\n"
    "                     [--open-registration]\n"
    "\n"
    "An RCAN robot registry (docs/REGISTRY.md): robots and their RRNs, resolve, federation\n"
    "nodes and the signed node manifest, compatible with rcan.dev and the official SDKs.\n"
    "\n"
    "  --config FILE       a YAML file whose keys are these flags' names without the\n"
    "                      dashes (port: 8090, data-dir: /var/lib/rcan-registry,\n"
    "                      sync-from: [URL, …], allow-http-node-urls: true); flags given\n"
    "                      on the command line win; relative paths are the file's\n"
    "  --port N            TCP port (default 8090; 0 = any free port)\n"
    "  --bind ADDR         listen address (default 127.0.0.1)\n"
    "  --data-dir DIR      keys, audit log and the SQLite database (default\n"
    "                      $RCAN_REGISTRY_DATA_DIR, else ~/.local/share/rcan-registry)\n"
    "  --database SPEC     postgresql://… or a SQLite path (default <data-dir>/registry.db);\n"
    "                      never a password here (argv is visible to every local user):\n"
    "                      PostgreSQL reads it from PGPASSFILE or ~/.pgpass (0600)\n"
    "  --public-url URL    the URL clients use (manifest api_base; default http://ADDR:PORT)\n"
    "  --host NAME         registry host in rcan:// URIs (default: the public URL's host)\n"
    "  --prefix P          authoritative for the delegated prefix P: RRNs are RRN-P-…\n"
    "  --write-rate R      writes per second per API key (default 10, burst --write-burst 20)\n"
    "  --address-write-rate R  writes per second per client address by callers with a valid\n"
    "                      API key or client credentials (default 50)\n"
    "  --anonymous-rate R  writes per second per client address without one: challenges,\n"
    "                      token requests that prove no client (default 20; burst twice\n"
    "                      that, at least 2)\n"
    "  --trusted-proxy CIDR  a proxy in front of the registry (repeatable): from these peers\n"
    "                      only, X-Forwarded-For names the client the rate limits count\n"
    "  --read-rate R       reads per second per client address (default 2000; 0 = unlimited)\n"
    "  --key-overlap S     token authority: a new signing key is published S seconds before\n"
    "                      it signs (default 600)\n"
    "  --key-lifetime S    a signing key is replaced after S seconds (default 2592000)\n"
    "  --max-token-ttl S   cap on issued tokens' lifetime (default 3600)\n"
    "  --device-code-ttl S how long a device-flow code waits for approval (default 600)\n"
    "  --webhook-backoff-ms MS  wait before a webhook delivery's 2nd attempt, doubled after\n"
    "                      (default 1000; 5 attempts)\n"
    "  --webhook-timeout-ms MS  one webhook delivery attempt's limit (default 5000)\n"
    "  --sync-from URL     pull the robots of the authoritative node at URL (repeatable);\n"
    "                      only those of prefixes delegated to that URL are taken\n"
    "  --sync-delegations  pull every delegation's node_url too\n"
    "  --sync-interval S   seconds between sync pulls (default 60)\n"
    "  --allow-http-node-urls  accept http:// node, webhook and sync URLs (local tests only)\n"
    "  --allow-private-webhooks  deliver webhooks to loopback, private and link-local\n"
    "                      addresses too (by default only to public ones)\n"
    "  --open-registration  register robots without an API key too (as rcan.dev): at the\n"
    "                      community tier, five an address, then one a minute\n"
    "\n"
    "The first start creates, in the data directory, an admin API key (admin.key, mode 0600;\n"
    "only when the database has no live admin key: once per database),\n"
    "the node's Ed25519 key (node-ed25519.seed) and the audit chain secret (audit.secret).\n"
    "SIGTERM or Ctrl-C stops it gracefully.\n";

bool parse_number(const std::string& s, double& out) {
  char* end = nullptr;
  out = std::strtod(s.c_str(), &end);
  return !s.empty() && end == s.c_str() + s.size() && out >= 0;
}

std::optional<Flags> parse_args(const std::vector<std::string>& args, int& exit_code);

constexpr const char* kPasswordAlternatives =
    "give PostgreSQL the password in PGPASSFILE or ~/.pgpass (mode 0600), or put the URL in a "
    "--config file of mode 0600";

// Whether a PostgreSQL connection URI carries a password: postgresql://user:password@… or a
// password= parameter.
bool database_has_password(std::string_view spec) {
  if (spec.rfind("postgresql://", 0) != 0 && spec.rfind("postgres://", 0) != 0) return false;
  std::string_view rest = spec.substr(spec.find("://") + 3);
  const size_t end = rest.find_first_of("/?");
  const std::string_view authority = rest.substr(0, end);
  const size_t at = authority.rfind('@');
  if (at != std::string_view::npos && authority.substr(0, at).find(':') != std::string_view::npos)
    return true;
  const size_t q = spec.find('?');
  if (q == std::string_view::npos) return false;
  std::string_view query = spec.substr(q + 1);
  while (!query.empty()) {
    const size_t amp = query.find('&');
    if (query.substr(0, amp).rfind("password=", 0) == 0) return true;
    if (amp == std::string_view::npos) break;
    query.remove_prefix(amp + 1);
  }
  return false;
}

// Flags that take no value (true in a config file).
bool is_switch(const std::string& flag) {
  return flag == "--allow-http-node-urls" || flag == "--sync-delegations" ||
         flag == "--allow-private-webhooks" || flag == "--open-registration";
}

// A YAML scalar as the flag's value; a relative path (data-dir, a SQLite database) is the
// config file's.
std::string config_value(const std::string& key, const std::string& v, const fs::path& dir) {
  const bool path = key == "data-dir" || (key == "database" && v.rfind("postgresql://", 0) != 0 &&
                                          v.rfind("postgres://", 0) != 0);
  if (path && !v.empty() && fs::path(v).is_relative()) return (dir / v).lexically_normal().string();
  return v;
}

// --config FILE: the file's keys become flags (before the command line's, which win). Errors
// name the file and the key.
Result<std::vector<std::string>> config_args(const std::string& file) {
  auto bad = [&](const std::string& what) {
    return Error(ErrorCode::kSchemaValidationFailed, file + ": " + what);
  };
  YAML::Node root;
  try {
    root = YAML::LoadFile(file);
  } catch (const YAML::BadFile&) {
    return bad("cannot be read");
  } catch (const YAML::Exception& e) {
    return bad(std::string("not valid YAML (") + e.what() + ")");
  }
  std::vector<std::string> out;
  if (root.IsNull()) return out;
  if (!root.IsMap()) return bad("must be a mapping of flag names to values");
  const fs::path dir = fs::absolute(fs::path(file)).parent_path();
  for (const auto& kv : root) {
    if (!kv.first.IsScalar()) return bad("keys must be flag names");
    const std::string key = kv.first.Scalar();
    const std::string flag = "--" + key;
    if (key == "config" || key == "help" || key.empty() ||
        key.find_first_of(" =") != std::string::npos)
      return bad("'" + key + "' is not a setting");
    const YAML::Node& v = kv.second;
    if (is_switch(flag)) {
      if (!v.IsScalar() || (v.Scalar() != "true" && v.Scalar() != "false"))
        return bad("'" + key + "' must be true or false");
      if (v.Scalar() == "true") out.push_back(flag);
    } else if (v.IsSequence() && (key == "sync-from" || key == "trusted-proxy")) {
      for (const auto& item : v) {
        if (!item.IsScalar()) return bad("'" + key + "' must be a list");
        out.push_back(flag);
        out.push_back(item.Scalar());
      }
    } else if (v.IsScalar()) {
      // Read by the registry's user alone, a password there stays off the command line.
      struct stat st {};
      if (key == "database" && database_has_password(v.Scalar()) &&
          (::stat(file.c_str(), &st) != 0 || (st.st_mode & 077) != 0))
        return bad(
            "'database' carries a password: the file must be mode 0600 (or give PostgreSQL the "
            "password in PGPASSFILE or ~/.pgpass, mode 0600)");
      out.push_back(flag);
      out.push_back(config_value(key, v.Scalar(), dir));
    } else {
      return bad("'" + key + "' must be a single value");
    }
  }
  return out;
}

}  // namespace

std::optional<Flags> parse_flags(int argc, char** argv, int& exit_code) {
  exit_code = 2;
  std::vector<std::string> args;
  std::vector<std::string> given(argv + 1, argv + argc);
  for (size_t i = 0; i < given.size(); ++i) {
    if (given[i] != "--config") continue;
    if (i + 1 >= given.size()) {
      std::fprintf(stderr, "rcan-registry: --config needs a value\n");
      return std::nullopt;
    }
    auto from_file = config_args(given[i + 1]);
    if (!from_file.ok()) {
      std::fprintf(stderr, "rcan-registry: %s\n", from_file.error().message.c_str());
      return std::nullopt;
    }
    args.insert(args.end(), from_file->begin(), from_file->end());
    given.erase(given.begin() + static_cast<std::ptrdiff_t>(i),
                given.begin() + static_cast<std::ptrdiff_t>(i) + 2);
    --i;
  }
  // A password on the command line is in every local user's `ps` and /proc/<pid>/cmdline.
  for (size_t i = 0; i + 1 < given.size(); ++i)
    if (given[i] == "--database" && database_has_password(given[i + 1])) {
      std::fprintf(stderr,
                   "rcan-registry: --database must not carry a password (the command line is "
                   "visible to every local user): %s\n",
                   kPasswordAlternatives);
      return std::nullopt;
    }
  args.insert(args.end(), given.begin(), given.end());
  return parse_args(args, exit_code);
}

namespace {

std::optional<Flags> parse_args(const std::vector<std::string>& args, int& exit_code) {
  Flags f;
  const size_t argc = args.size();
  for (size_t i = 0; i < argc; ++i) {
    std::string s = args[i];
    auto value = [&](std::string& out) {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "rcan-registry: %s needs a value\n", s.c_str());
        return false;
      }
      out = args[++i];
      return true;
    };
    std::string v;
    double d = 0;
    if (s == "--help" || s == "-h") {
      std::fputs(kUsage, stdout);
      exit_code = 0;
      return std::nullopt;
    } else if (s == "--port") {
      if (!value(v)) return std::nullopt;
      unsigned p = 0;
      auto [ptr, ec] = std::from_chars(v.data(), v.data() + v.size(), p);
      if (ec != std::errc() || ptr != v.data() + v.size() || p > 65535) {
        std::fprintf(stderr, "rcan-registry: --port must be 0..65535\n");
        return std::nullopt;
      }
      f.port = static_cast<uint16_t>(p);
    } else if (s == "--bind") {
      if (!value(f.bind)) return std::nullopt;
    } else if (s == "--data-dir") {
      if (!value(f.data_dir)) return std::nullopt;
    } else if (s == "--database") {
      if (!value(f.database)) return std::nullopt;
    } else if (s == "--public-url") {
      if (!value(f.public_url)) return std::nullopt;
    } else if (s == "--host") {
      if (!value(f.host)) return std::nullopt;
    } else if (s == "--allow-http-node-urls") {
      f.allow_http_node_urls = true;
    } else if (s == "--sync-delegations") {
      f.sync_delegations = true;
    } else if (s == "--allow-private-webhooks") {
      f.allow_private_webhooks = true;
    } else if (s == "--open-registration") {
      f.open_registration = true;
    } else if (s == "--trusted-proxy") {
      if (!value(v)) return std::nullopt;
      if (auto c = registry::api::parse_cidr(v); !c.ok()) {
        std::fprintf(stderr, "rcan-registry: --trusted-proxy: %s\n", c.error().message.c_str());
        return std::nullopt;
      }
      f.trusted_proxies.push_back(v);
    } else if (s == "--sync-from") {
      if (!value(v)) return std::nullopt;
      f.sync_from.push_back(v);
    } else if (s == "--prefix") {
      if (!value(f.prefix)) return std::nullopt;
    } else if (s == "--operator") {
      if (!value(f.operator_name)) return std::nullopt;
    } else if (s == "--contact") {
      if (!value(f.contact)) return std::nullopt;
    } else if (s == "--write-rate" || s == "--write-burst" || s == "--address-write-rate" ||
               s == "--anonymous-rate" || s == "--read-rate" || s == "--io-threads" ||
               s == "--key-overlap" || s == "--key-lifetime" || s == "--max-token-ttl" ||
               s == "--device-code-ttl" || s == "--webhook-backoff-ms" ||
               s == "--webhook-timeout-ms" || s == "--sync-interval") {
      if (!value(v)) return std::nullopt;
      if (!parse_number(v, d)) {
        std::fprintf(stderr, "rcan-registry: %s must be a number ≥ 0\n", s.c_str());
        return std::nullopt;
      }
      if (s == "--write-rate") f.write_rate = d;
      if (s == "--write-burst") f.write_burst = d;
      if (s == "--address-write-rate") f.addr_write_rate = d;
      if (s == "--anonymous-rate") f.anon_rate = d;
      if (s == "--read-rate") f.read_rate = d;
      if (s == "--io-threads") f.io_threads = std::max(1, static_cast<int>(d));
      if (s == "--key-overlap") f.key_overlap_s = static_cast<int64_t>(d);
      if (s == "--key-lifetime") f.key_lifetime_s = std::max<int64_t>(60, static_cast<int64_t>(d));
      if (s == "--device-code-ttl") f.device_ttl_s = std::max<int64_t>(1, static_cast<int64_t>(d));
      if (s == "--webhook-backoff-ms")
        f.webhook_backoff_ms = std::clamp(static_cast<int>(d), 1, 600000);
      if (s == "--webhook-timeout-ms")
        f.webhook_timeout_ms = std::clamp(static_cast<int>(d), 100, 60000);
      if (s == "--sync-interval") f.sync_interval_s = std::clamp(d, 0.1, 86400.0);
      if (s == "--max-token-ttl") f.max_token_ttl_s = std::max<int64_t>(1, static_cast<int64_t>(d));
    } else {
      std::fprintf(stderr, "rcan-registry: unknown argument '%s'\n%s", s.c_str(), kUsage);
      return std::nullopt;
    }
  }
  return f;
}

}  // namespace

Result<std::string> default_data_dir() {
  return user_data_dir("rcan-registry", "RCAN_REGISTRY_DATA_DIR");
}

Status make_private_dir(const std::string& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) {
    fs::create_directories(dir, ec);
    if (ec) return Error(ErrorCode::kInternal, "cannot create " + dir + ": " + ec.message());
    ::chmod(dir.c_str(), 0700);
  }
  return Status::Ok();
}

Result<Bytes> node_seed(const std::string& dir, bool& created) {
  std::string path = dir + "/node-ed25519.seed";
  created = false;
  if (!fs::exists(path)) {
    Bytes seed = ed25519::random_seed();
    if (Status s = keys::write_new_file(path, seed, 0600); !s.ok()) return s.error();
    created = true;
  }
  auto seed = keys::read_secret_file(path, ed25519::kSeedBytes);
  if (!seed.ok()) return seed.error();
  return Bytes(seed->data(), seed->data() + seed->size());
}

Result<std::string> audit_secret(const std::string& dir) {
  std::string path = dir + "/audit.secret";
  if (!fs::exists(path)) {
    if (Status s = audit::create_secret_file(path); !s.ok()) return s.error();
  }
  return audit::read_secret_file(path);
}

Status write_private_file(const std::string& path, const std::string& text) {
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0)
    return Error(ErrorCode::kInternal, "cannot create " + path + ": " + std::strerror(errno));
  bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  ok = ::fsync(fd) == 0 && ok;
  ::close(fd);
  if (!ok) return Error(ErrorCode::kInternal, "cannot write " + path);
  return Status::Ok();
}

}  // namespace rcan::registry_app
