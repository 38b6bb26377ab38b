// libFuzzer: HTTP requests through the node's real handler — the bytes of one or more
// pipelined requests are parsed by the transport's own parser (transport/http_parse.h, the
// code http_server.cpp runs) and each request goes to Node::handle(), the router rcand serves
// (routes, pipeline, safety core, audit, §16, control sessions). A WebSocket upgrade goes to
// Node::open() instead. Tokens and fresh ids come from placeholders in the path, header values,
// query values and the body (fuzz/node_harness.h), expanded after parsing.
//
// Invariants: nothing crashes; every request is answered exactly once, within 10 s; every
// status is 1xx..5xx and never 500; a JSON answer parses; an error answer (≥ 400) with a JSON
// body is the profile's error body (type ERROR, payload.error_code; the watermark lookup's
// {"error", "code"} as the seed shows). RCAN_FUZZ_VERBOSE=1 prints every exchange.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>

#include "node_harness.h"
#include "transport/http_parse.h"

namespace {

[[noreturn]] void fail(const std::string& what, const rcan::transport::HttpResponse* r = nullptr) {
  std::fprintf(stderr, "http_handler_fuzz: %s\n", what.c_str());
  if (r)
    std::fprintf(stderr, "  status %d, content-type %s, body: %.2000s\n", r->status,
                 r->content_type.c_str(), r->body.c_str());
  std::abort();
}

bool verbose() {
  static const bool v = std::getenv("RCAN_FUZZ_VERBOSE") != nullptr;
  return v;
}

struct Answer {
  std::mutex mu;
  std::condition_variable cv;
  int calls = 0;
  rcan::transport::HttpResponse response;
};

void check_response(const rcan::transport::HttpResponse& r) {
  if (r.status < 100 || r.status > 599) fail("status out of range", &r);
  if (r.status == 500) fail("500 on input", &r);
  if (r.content_type.rfind("application/json", 0) != 0) return;
  auto v = rcan::json::parse(r.body, {.max_depth = 256, .max_bytes = 1u << 30});
  if (!v.ok()) fail("JSON answer does not parse", &r);
  if (r.status < 400) return;
  const rcan::json::Value* type = v->is_object() ? v->get("type") : nullptr;
  const rcan::json::Value* payload = v->is_object() ? v->get("payload") : nullptr;
  const rcan::json::Value* code =
      payload && payload->is_object() ? payload->get("error_code") : nullptr;
  const bool profile = type && type->is_string() && type->as_string() == "ERROR" && code &&
                       code->is_string() && !code->as_string().empty();
  // The §16.6 watermark lookup answers in the seed's own shape ({"error", "code"}).
  const rcan::json::Value* err = v->is_object() ? v->get("error") : nullptr;
  const bool seed_shape = err && err->is_string() && !err->as_string().empty();
  if (!profile && !seed_shape) fail("error answer is not an error body", &r);
}

// A sink for an upgrade the node accepts: the fuzz input carries no frames (ws_stream_fuzz
// does), so the stream is closed at once.
struct NullSink final : rcan::transport::StreamSink {
  bool send_text(std::string) override { return true; }
  void close(uint16_t, std::string) override {}
  const std::string& remote_addr() const override { return addr; }
  std::string addr = "127.0.0.1:40001";
};

void handle_one(rcan::transport::HttpRequest req, bool websocket) {
  auto& h = rcan::fuzz::NodeHarness::get();
  if (websocket) {
    rcan::transport::HttpResponse refusal;
    auto session = h.node().open(req, std::make_shared<NullSink>(), refusal);
    if (session) {
      session->on_closed();
    } else {
      check_response(refusal);
      if (refusal.status < 400) fail("refused upgrade without an error status", &refusal);
    }
    return;
  }
  const std::string method = req.method, target = req.target;
  auto answer = std::make_shared<Answer>();
  h.node().handle(std::move(req), [answer](rcan::transport::HttpResponse r) {
    std::lock_guard<std::mutex> lock(answer->mu);
    if (++answer->calls > 1) fail("respond called twice", &r);
    answer->response = std::move(r);
    answer->cv.notify_all();
  });
  std::unique_lock<std::mutex> lock(answer->mu);
  if (!answer->cv.wait_for(lock, std::chrono::seconds(10), [&] { return answer->calls > 0; }))
    fail("no answer within 10 s");
  if (verbose())
    std::fprintf(stderr, "  %s %s -> %d %.300s\n", method.c_str(), target.c_str(),
                 answer->response.status, answer->response.body.c_str());
  check_response(answer->response);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using rcan::transport::detail::ParseOutcome;
  auto& h = rcan::fuzz::NodeHarness::get();
  h.reset();
  std::string_view rest(reinterpret_cast<const char*>(data), size);
  for (int n = 0; n < 8 && !rest.empty(); ++n) {  // keep-alive: up to 8 requests per input
    ParseOutcome out = rcan::transport::detail::parse_request_bytes(rest, 8 * 1024, 64 * 1024);
    if (out.kind != ParseOutcome::Kind::kRequest || out.consumed == 0 || out.consumed > rest.size())
      break;
    // Placeholders are expanded after parsing, so that Content-Length counts the input's bytes.
    out.request.path = h.expand(out.request.path);
    out.request.target = h.expand(out.request.target);
    for (auto& hv : out.request.headers) hv.second = h.expand(hv.second);
    for (auto& qv : out.request.query) qv.second = h.expand(qv.second);
    out.request.body = h.expand(out.request.body);
    out.request.remote_addr = "127.0.0.1:40000";
    out.request.received_mono_us = std::chrono::duration_cast<std::chrono::microseconds>(
                                       std::chrono::steady_clock::now().time_since_epoch())
                                       .count();
    handle_one(std::move(out.request), out.websocket);
    rest.remove_prefix(out.consumed);
  }
  return 0;
}
