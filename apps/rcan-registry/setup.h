// rcan-registry's start-up: flags, the data directory and what the first start creates there.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rcan/encoding.h"
#include "rcan/result.h"

namespace rcan::registry_app {

struct Flags {
  uint16_t port = 8090;
  std::string bind = "127.0.0.1";
  std::string data_dir;  // empty: default_data_dir()
  std::string database;  // empty: <data_dir>/registry.db
  std::string public_url, host, prefix, operator_name, contact;
  double write_rate = 10, write_burst = 20, addr_write_rate = 50, anon_rate = 20, read_rate = 2000;
  std::vector<std::string> trusted_proxies;  // --trusted-proxy CIDR, repeatable (checked)
  bool allow_private_webhooks = false;
  bool open_registration = false;  // --open-registration: anonymous POST /api/v1/robots
  int io_threads = 2;
  int64_t key_overlap_s = 600, key_lifetime_s = 2592000, max_token_ttl_s = 3600;
  int64_t device_ttl_s = 600;
  int webhook_backoff_ms = 1000, webhook_timeout_ms = 5000;
  std::vector<std::string> sync_from;  // --sync-from, repeatable
  bool sync_delegations = false;
  double sync_interval_s = 60;
  bool allow_http_node_urls = false;
};

// nullopt: exit with `exit_code` (0 after --help, 2 on a bad flag; the message is printed).
std::optional<Flags> parse_flags(int argc, char** argv, int& exit_code);

// $RCAN_REGISTRY_DATA_DIR, else $XDG_DATA_HOME/rcan-registry, else
// ~/.local/share/rcan-registry (as rcand picks its own).
Result<std::string> default_data_dir();

// Creates `dir` (0700) when missing.
Status make_private_dir(const std::string& dir);

// The node's Ed25519 seed in <dir>/node-ed25519.seed (0600), created when missing.
Result<Bytes> node_seed(const std::string& dir, bool& created);

// The audit chain secret in <dir>/audit.secret (0600), created when missing.
Result<std::string> audit_secret(const std::string& dir);

// Writes `text` to a new file with mode 0600 (refuses to replace one).
Status write_private_file(const std::string& path, const std::string& text);

}  // namespace rcan::registry_app
