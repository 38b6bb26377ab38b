// Daemon — rcan-registry's parts, started in one order and stopped in the reverse one.
//
//   Daemon d;
//   if (Status s = d.start(flags); !s.ok()) return fail(s);   // what started is stopped again
//   wait_for_signal();
//   d.stop(2000);
//
// start() runs its steps in the order the members are declared below — the data directory,
// the store, the audit log, the node key, the HTTP server (answering 503 until the API is
// built, since the API's URLs name the port it got), the API, the first start's admin key —
// and then hands requests to the API. stop() drains the server and unhooks the API; the
// destructor calls stop(0), and the members go newest first.
#pragma once

#include <atomic>
#include <memory>
#include <string>

#include "rcan/audit/audit_log.h"
#include "rcan/encoding.h"
#include "rcan/result.h"
#include "registry/api/registry_api.h"
#include "registry/store.h"
#include "setup.h"
#include "transport/http_api.h"
#include "transport/http_server.h"

namespace rcan::registry_app {

// Hands requests to the API once it is built; until then: 503.
class ApiForward : public transport::HttpHandler {
 public:
  std::atomic<registry::api::RegistryApi*> api{nullptr};
  void handle(transport::HttpRequest req, Respond respond) override;
};

// The registry serves no WebSocket: every upgrade is a 404.
class NoStreams : public transport::StreamHandler {
 public:
  std::unique_ptr<transport::StreamReceiver> open(const transport::HttpRequest&,
                                                  std::shared_ptr<transport::StreamSink>,
                                                  transport::HttpResponse& refusal) override;
};

class Daemon {
 public:
  Daemon() = default;
  ~Daemon();  // stop(0)
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Starts every part; the error's message says which step failed and why.
  Status start(const Flags& flags);
  // Drains the server for up to `drain_ms` and unhooks the API. Idempotent.
  void stop(int drain_ms);

 private:
  // The steps of start(), in order.
  Status open_data_dir(const Flags& flags);
  Status open_store(const Flags& flags);
  Status open_audit_log();
  Status load_node_key();
  Status start_server(const Flags& flags);
  void build_api(const Flags& flags);
  Status create_first_admin_key();
  void serve();

  std::string dir_;
  std::unique_ptr<registry::Store> store_;
  std::unique_ptr<audit::AuditLog> audit_;
  Bytes seed_;
  bool seed_created_ = false;
  ApiForward forward_;
  NoStreams no_streams_;
  std::unique_ptr<transport::HttpServer> server_;
  std::string url_;         // where the server listens
  std::string public_url_;  // the API's base URL (--public-url, else url_)
  std::string prefix_;      // --prefix
  std::unique_ptr<registry::api::RegistryApi> api_;
};

}  // namespace rcan::registry_app
