// rcan-registry — the RCAN robot registry daemon (docs/REGISTRY.md).
//
//   rcan-registry                  the embedded default: SQLite in the data directory, port
//                                  8090 on 127.0.0.1; the first start creates an admin key
//   rcan-registry --help           the flags
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "rcan/audit/audit_log.h"
#include "registry/api/registry_api.h"
#include "registry/store.h"
#include "runtime/log.h"
#include "setup.h"
#include "transport/http_server.h"

using namespace rcan;
namespace fs = std::filesystem;

namespace {

int fail(const std::string& msg) {
  std::fprintf(stderr, "rcan-registry: %s\n", msg.c_str());
  return 1;
}

// The API is built once the port is known (its URLs name it); until then: 503.
class Forward : public transport::HttpHandler {
 public:
  std::atomic<registry::api::RegistryApi*> api{nullptr};
  void handle(transport::HttpRequest req, Respond respond) override {
    if (auto* a = api.load()) return a->handle(std::move(req), std::move(respond));
    transport::HttpResponse r;
    r.status = 503;
    r.body = R"({"error":"starting"})";
    respond(std::move(r));
  }
};

class NoStreams : public transport::StreamHandler {
 public:
  std::unique_ptr<transport::StreamReceiver> open(const transport::HttpRequest&,
                                                  std::shared_ptr<transport::StreamSink>,
                                                  transport::HttpResponse& refusal) override {
    refusal.status = 404;
    refusal.body = R"({"error":"Not found"})";
    return nullptr;
  }
};

std::string host_of(const std::string& url) {
  size_t start = url.find("://");
  start = start == std::string::npos ? 0 : start + 3;
  size_t end = url.find_first_of("/?#", start);
  std::string authority =
      url.substr(start, end == std::string::npos ? std::string::npos : end - start);
  if (!authority.empty() && authority[0] == '[')
    return authority.substr(0, authority.find(']') + 1);
  return authority.substr(0, authority.find(':'));
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

  std::string dir = flags->data_dir;
  if (dir.empty()) {
    auto d = registry_app::default_data_dir();
    if (!d.ok()) return fail(d.error().message);
    dir = *d;
  }
  dir = fs::absolute(dir).lexically_normal().string();
  if (Status s = registry_app::make_private_dir(dir); !s.ok()) return fail(s.error().message);

  registry::StoreOptions so;
  so.rrn_prefix = flags->prefix;
  std::string spec = flags->database.empty() ? dir + "/registry.db" : flags->database;
  auto store = registry::open_store(spec, so);
  if (!store.ok()) return fail("database: " + store.error().message);

  auto secret = registry_app::audit_secret(dir);
  if (!secret.ok()) return fail("audit secret: " + secret.error().message);
  audit::AuditOptions ao;
  ao.secret = *secret;
  ao.robot_ruri = "rcan://local.rcan/registry/rcan-registry/node";
  ao.system_principal = "system:rcan-registry";
  auto audit_log = audit::AuditLog::open(dir + "/audit", ao);
  if (!audit_log.ok()) return fail("audit log: " + audit_log.error().message);

  bool seed_created = false;
  auto seed = registry_app::node_seed(dir, seed_created);
  if (!seed.ok()) return fail("node key: " + seed.error().message);

  Forward forward;
  NoStreams no_streams;
  transport::ServerOptions sopt;
  sopt.bind_address = flags->bind;
  sopt.port = flags->port;
  sopt.io_threads = flags->io_threads;
  sopt.max_body_bytes = 64 * 1024;
  transport::HttpServer server(sopt, forward, no_streams);
  auto port = server.start();
  if (!port.ok()) return fail("listen on " + flags->bind + ": " + port.error().message);

  std::string shown = flags->bind == "0.0.0.0" || flags->bind == "::" ? "127.0.0.1" : flags->bind;
  if (shown.find(':') != std::string::npos) shown = "[" + shown + "]";
  std::string url = "http://" + shown + ":" + std::to_string(*port);
  registry::api::ApiOptions opts;
  opts.public_url = flags->public_url.empty() ? url : flags->public_url;
  opts.host = flags->host.empty() ? host_of(opts.public_url) : flags->host;
  opts.prefix = flags->prefix;
  opts.node_seed = *seed;
  if (!flags->operator_name.empty()) opts.operator_name = flags->operator_name;
  opts.contact = flags->contact;
  opts.allow_http_node_urls = flags->allow_http_node_urls;
  opts.write_per_key = {flags->write_rate, flags->write_burst};
  opts.write_per_address = {flags->addr_write_rate, flags->addr_write_rate * 2};
  opts.anonymous_per_address = {flags->anon_rate, std::max(2.0, flags->anon_rate * 2)};
  opts.read_per_address = {flags->read_rate, flags->read_rate * 2};
  for (const std::string& c : flags->trusted_proxies)
    opts.trusted_proxies.push_back(*registry::api::parse_cidr(c));
  opts.webhooks.allow_private = flags->allow_private_webhooks;
  opts.key_overlap_s = flags->key_overlap_s;
  opts.key_lifetime_s = flags->key_lifetime_s;
  opts.max_token_ttl_s = flags->max_token_ttl_s;
  opts.device_ttl_s = flags->device_ttl_s;
  opts.webhooks.backoff_ms = flags->webhook_backoff_ms;
  opts.webhooks.timeout_ms = flags->webhook_timeout_ms;
  opts.sync_from = flags->sync_from;
  opts.sync_delegations = flags->sync_delegations;
  opts.sync_interval_ms = static_cast<int>(flags->sync_interval_s * 1000);
  registry::api::RegistryApi api(**store, audit_log->get(), opts);

  std::string key_file = dir + "/admin.key";
  if (!fs::exists(key_file)) {
    auto key = api.create_key("admin", "", "first start", "system:first-start");
    if (!key.ok()) return fail("admin key: " + key.error().message);
    if (Status s = registry_app::write_private_file(key_file, *key); !s.ok())
      return fail(s.error().message);
    // The key stays in its file: a command line is visible to every local user (ps).
    std::fprintf(stderr,
                 "\nrcan-registry: a new admin API key is in %s (mode 0600; shown only there).\n"
                 "Register a robot with it (the CLI reads the key from the file, never from a "
                 "command line):\n"
                 "  RCAN_REGISTRY=%s RCAN_REGISTRY_KEY_FILE=%s \\\n"
                 "  rcan registry register --manufacturer acme --model arm --version v1 "
                 "--device-id unit-1\n"
                 "More keys: rcan registry keys create --role registrant --save FILE (the same "
                 "variables).\n"
                 "With curl: a file of mode 0600 holding the line 'Authorization: Bearer <key>', "
                 "given as -H @FILE.\n\n",
                 key_file.c_str(), url.c_str(), key_file.c_str());
  }
  forward.api.store(&api);
  log(LogLevel::kInfo, "listening",
      json::Object{{"url", url},
                   {"public_url", opts.public_url},
                   {"data_dir", dir},
                   {"backend", std::string((*store)->backend())},
                   {"prefix", opts.prefix},
                   {"node_key_created", seed_created}});

  int sig = 0;
  sigwait(&signals, &sig);
  log(LogLevel::kInfo, "shutting_down",
      json::Object{{"signal", sig == SIGTERM ? "SIGTERM" : "SIGINT"}});
  server.stop(2000);
  forward.api.store(nullptr);
  log(LogLevel::kInfo, "stopped");
  return 0;
}
