// rcan-registry's start and stop paths (daemon.h).
#include "daemon.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "rcan/errors.h"
#include "runtime/log.h"

namespace fs = std::filesystem;

namespace rcan::registry_app {
namespace {

// An error whose message is `context` followed by the cause's message.
Error failed(const std::string& context, const Error& cause) {
  return Error(ErrorCode::kInternal, context + cause.message);
}

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

}  // namespace

void ApiForward::handle(transport::HttpRequest req, Respond respond) {
  if (auto* a = api.load()) return a->handle(std::move(req), std::move(respond));
  transport::HttpResponse r;
  r.status = 503;
  r.body = R"({"error":"starting"})";
  respond(std::move(r));
}

std::unique_ptr<transport::StreamReceiver> NoStreams::open(const transport::HttpRequest&,
                                                           std::shared_ptr<transport::StreamSink>,
                                                           transport::HttpResponse& refusal) {
  refusal.status = 404;
  refusal.body = R"({"error":"Not found"})";
  return nullptr;
}

Daemon::~Daemon() { stop(0); }

void Daemon::stop(int drain_ms) {
  if (server_) server_->stop(drain_ms);
  forward_.api.store(nullptr);
}

Status Daemon::start(const Flags& flags) {
  if (Status s = open_data_dir(flags); !s.ok()) return s;
  if (Status s = open_store(flags); !s.ok()) return s;
  if (Status s = open_audit_log(); !s.ok()) return s;
  if (Status s = load_node_key(); !s.ok()) return s;
  if (Status s = start_server(flags); !s.ok()) return s;
  build_api(flags);
  if (Status s = create_first_admin_key(); !s.ok()) return s;
  serve();
  return Status::Ok();
}

Status Daemon::open_data_dir(const Flags& flags) {
  dir_ = flags.data_dir;
  if (dir_.empty()) {
    auto d = default_data_dir();
    if (!d.ok()) return d.error();
    dir_ = *d;
  }
  dir_ = fs::absolute(dir_).lexically_normal().string();
  return make_private_dir(dir_);
}

Status Daemon::open_store(const Flags& flags) {
  registry::StoreOptions so;
  so.rrn_prefix = flags.prefix;
  std::string spec = flags.database.empty() ? dir_ + "/registry.db" : flags.database;
  auto store = registry::open_store(spec, so);
  if (!store.ok()) return failed("database: ", store.error());
  store_ = std::move(*store);
  return Status::Ok();
}

Status Daemon::open_audit_log() {
  auto secret = audit_secret(dir_);
  if (!secret.ok()) return failed("audit secret: ", secret.error());
  audit::AuditOptions ao;
  ao.secret = *secret;
  ao.robot_ruri = "rcan://local.rcan/registry/rcan-registry/node";
  ao.system_principal = "system:rcan-registry";
  auto audit_log = audit::AuditLog::open(dir_ + "/audit", ao);
  if (!audit_log.ok()) return failed("audit log: ", audit_log.error());
  audit_ = std::move(*audit_log);
  return Status::Ok();
}

Status Daemon::load_node_key() {
  auto seed = node_seed(dir_, seed_created_);
  if (!seed.ok()) return failed("node key: ", seed.error());
  seed_ = std::move(*seed);
  return Status::Ok();
}

Status Daemon::start_server(const Flags& flags) {
  transport::ServerOptions sopt;
  sopt.bind_address = flags.bind;
  sopt.port = flags.port;
  sopt.io_threads = flags.io_threads;
  sopt.max_body_bytes = 64 * 1024;
  server_ = std::make_unique<transport::HttpServer>(sopt, forward_, no_streams_);
  auto port = server_->start();
  if (!port.ok()) return failed("listen on " + flags.bind + ": ", port.error());
  std::string shown = flags.bind == "0.0.0.0" || flags.bind == "::" ? "127.0.0.1" : flags.bind;
  if (shown.find(':') != std::string::npos) shown = "[" + shown + "]";
  url_ = "http://" + shown + ":" + std::to_string(*port);
  return Status::Ok();
}

void Daemon::build_api(const Flags& flags) {
  registry::api::ApiOptions opts;
  opts.public_url = flags.public_url.empty() ? url_ : flags.public_url;
  opts.host = flags.host.empty() ? host_of(opts.public_url) : flags.host;
  opts.prefix = flags.prefix;
  opts.node_seed = seed_;
  if (!flags.operator_name.empty()) opts.operator_name = flags.operator_name;
  opts.contact = flags.contact;
  opts.allow_http_node_urls = flags.allow_http_node_urls;
  opts.write_per_key = {flags.write_rate, flags.write_burst};
  opts.write_per_address = {flags.addr_write_rate, flags.addr_write_rate * 2};
  opts.anonymous_per_address = {flags.anon_rate, std::max(2.0, flags.anon_rate * 2)};
  opts.read_per_address = {flags.read_rate, flags.read_rate * 2};
  for (const std::string& c : flags.trusted_proxies)
    opts.trusted_proxies.push_back(*registry::api::parse_cidr(c));
  opts.webhooks.allow_private = flags.allow_private_webhooks;
  opts.open_registration = flags.open_registration;
  opts.key_overlap_s = flags.key_overlap_s;
  opts.key_lifetime_s = flags.key_lifetime_s;
  opts.max_token_ttl_s = flags.max_token_ttl_s;
  opts.device_ttl_s = flags.device_ttl_s;
  opts.webhooks.backoff_ms = flags.webhook_backoff_ms;
  opts.webhooks.timeout_ms = flags.webhook_timeout_ms;
  opts.sync_from = flags.sync_from;
  opts.sync_delegations = flags.sync_delegations;
  opts.sync_interval_ms = static_cast<int>(flags.sync_interval_s * 1000);
  public_url_ = opts.public_url;
  prefix_ = opts.prefix;
  api_ = std::make_unique<registry::api::RegistryApi>(*store_, audit_.get(), std::move(opts));
}

Status Daemon::create_first_admin_key() {
  std::string key_file = dir_ + "/admin.key";
  if (fs::exists(key_file)) return Status::Ok();
  // Made once per database: a database with a live admin key (restored without admin.key, the
  // key kept elsewhere, another instance's) gets none, and no file is written.
  auto key = api_->create_first_admin_key();
  if (!key.ok()) return failed("admin key: ", key.error());
  if (!key->has_value()) {
    log(LogLevel::kInfo, "admin_key_exists",
        json::Object{{"admin_key_file", key_file},
                     {"message",
                      "no admin.key here and the database has admin keys: using those (no new "
                      "admin key is made)"}});
    return Status::Ok();
  }
  if (Status s = write_private_file(key_file, **key); !s.ok()) return s;
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
               key_file.c_str(), url_.c_str(), key_file.c_str());
  return Status::Ok();
}

void Daemon::serve() {
  forward_.api.store(api_.get());
  log(LogLevel::kInfo, "listening",
      json::Object{{"url", url_},
                   {"public_url", public_url_},
                   {"data_dir", dir_},
                   {"backend", std::string(store_->backend())},
                   {"prefix", prefix_},
                   {"node_key_created", seed_created_}});
}

}  // namespace rcan::registry_app
