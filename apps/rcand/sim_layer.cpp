// `rcand --sim-layer`: the built-in simulated brain layer (docs/AI.md §Brain layers). An
// HTTP server that answers the node's escalation requests with the command it was given,
// an ai block (provider "sim", model "sim-<layer>", the configured confidence) and a thought.
// It serves the demo and the tests; a real deployment points agent.layers at its own models.
#include <signal.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "node/ai/brain_layers.h"
#include "runtime/log.h"
#include "transport/http_server.h"

using namespace rcan;

namespace {

class NoStreams final : public transport::StreamHandler {
 public:
  std::unique_ptr<transport::StreamReceiver> open(const transport::HttpRequest&,
                                                  std::shared_ptr<transport::StreamSink>,
                                                  transport::HttpResponse& refusal) override {
    refusal.status = 404;
    refusal.body = R"({"error":"a brain layer has no streams"})";
    return nullptr;
  }
};

}  // namespace

int sim_layer_main(int argc, char** argv) {
  node::SimLayerOptions o;
  int port = 0;
  std::string bind = "127.0.0.1";
  for (int i = 2; i < argc; ++i) {
    std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "rcand --sim-layer: %s needs a value\n", a.c_str());
      return 2;
    }
    std::string v = argv[++i];
    char* end = nullptr;
    if (a == "--port") {
      long p = std::strtol(v.c_str(), &end, 10);
      if (!end || *end || p < 0 || p > 65535)
        return std::fprintf(stderr, "rcand --sim-layer: bad --port\n"), 2;
      port = static_cast<int>(p);
    } else if (a == "--layer") {
      if (node::layer_rank(v) < 0)
        return std::fprintf(stderr, "rcand --sim-layer: --layer reactive|fast|planner\n"), 2;
      o.layer = v;
    } else if (a == "--confidence") {
      double c = std::strtod(v.c_str(), &end);
      if (!end || *end || !(c >= 0 && c <= 1))
        return std::fprintf(stderr, "rcand --sim-layer: --confidence 0..1\n"), 2;
      o.confidence = c;
    } else if (a == "--delay-ms") {
      long d = std::strtol(v.c_str(), &end, 10);
      if (!end || *end || d < 0 || d > 600000)
        return std::fprintf(stderr, "rcand --sim-layer: bad --delay-ms\n"), 2;
      o.delay_ms = static_cast<int>(d);
    } else if (a == "--bind") {
      bind = v;
    } else {
      std::fprintf(stderr, "rcand --sim-layer: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  signal(SIGPIPE, SIG_IGN);
  node::SimLayer layer(o);
  NoStreams streams;
  transport::ServerOptions so;
  so.bind_address = bind;
  so.port = static_cast<uint16_t>(port);
  so.io_threads = 1;
  transport::HttpServer server(so, layer, streams);
  auto bound = server.start();
  if (!bound.ok()) {
    std::fprintf(stderr, "rcand --sim-layer: cannot listen: %s\n", bound.error().message.c_str());
    return 1;
  }
  rcan::log(rcan::LogLevel::kInfo, "listening",
            json::Object{{"url", "http://" + bind + ":" + std::to_string(*bound)},
                         {"sim_layer", o.layer},
                         {"confidence", o.confidence}});
  int sig = 0;
  sigwait(&set, &sig);
  server.stop(500);
  return 0;
}
