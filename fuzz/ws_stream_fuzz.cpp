// libFuzzer: WebSocket text frames into the node's real stream handler (Node::open() and the
// StreamReceiver it returns — CONNECT, PING, SUBSCRIBE, AUTHORIZE and every RCAN message
// through the pipeline), as the Beast transport delivers them after its own frame decoding.
//
// Input: lines. The first line is the upgrade target ("/rcan/v1/stream", "/ws/telemetry?token=…",
// optionally followed by a TAB and an Authorization header value); every following line is one
// text frame, except that a line starting with byte 0x02 is a binary frame. Placeholders
// (@OWNER@, @UUID@, @NOW@, …) are expanded (fuzz/node_harness.h).
//
// Invariants: nothing crashes; every frame the node sends is one JSON object with a string
// type; a close code is a valid one (1000..4999, not 1004-1006/1015); every frame fed to an
// open stream is answered (a frame or a close) within 10 s. RCAN_FUZZ_VERBOSE=1 prints the
// frames sent.
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

[[noreturn]] void fail(const std::string& what, std::string_view frame = {}) {
  std::fprintf(stderr, "ws_stream_fuzz: %s\n", what.c_str());
  if (!frame.empty()) std::fprintf(stderr, "  frame: %.2000s\n", std::string(frame).c_str());
  std::abort();
}

class Sink final : public rcan::transport::StreamSink {
 public:
  bool send_text(std::string text) override {
    if (std::getenv("RCAN_FUZZ_VERBOSE")) std::fprintf(stderr, "  <- %.300s\n", text.c_str());
    auto v = rcan::json::parse(text, {.max_depth = 256, .max_bytes = 1u << 30});
    const rcan::json::Value* type = v.ok() && v->is_object() ? v->get("type") : nullptr;
    if (!type || !type->is_string() || type->as_string().empty())
      fail("a frame is not a typed JSON object", text);
    std::lock_guard<std::mutex> lock(mu_);
    if (closed_) return false;  // like the transport: calls after close are ignored
    // Telemetry and broadcast events arrive on their own; they answer nothing.
    const std::string& t = type->as_string();
    if (t != "STREAM" && t != "EVENT") ++answers_;
    cv_.notify_all();
    return true;
  }
  void close(uint16_t code, std::string reason) override {
    if (code < 1000 || code > 4999 || code == 1004 || code == 1005 || code == 1006 || code == 1015)
      fail("invalid close code " + std::to_string(code), reason);
    if (reason.size() > 123) fail("close reason longer than a control frame allows", reason);
    if (std::getenv("RCAN_FUZZ_VERBOSE"))
      std::fprintf(stderr, "  <- close %u %s\n", code, reason.c_str());
    std::lock_guard<std::mutex> lock(mu_);
    closed_ = true;
    cv_.notify_all();
  }
  const std::string& remote_addr() const override { return addr_; }

  int answers() {
    std::lock_guard<std::mutex> lock(mu_);
    return answers_;
  }
  bool closed() {
    std::lock_guard<std::mutex> lock(mu_);
    return closed_;
  }
  // Waits until more than `seen` answers were sent or the stream closed.
  bool wait_answer(int seen) {
    std::unique_lock<std::mutex> lock(mu_);
    return cv_.wait_for(lock, std::chrono::seconds(10), [&] { return closed_ || answers_ > seen; });
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  int answers_ = 0;
  bool closed_ = false;
  std::string addr_ = "127.0.0.1:40002";
};

std::string_view next_line(std::string_view& s) {
  size_t nl = s.find('\n');
  std::string_view line = s.substr(0, nl);
  s = nl == std::string_view::npos ? std::string_view() : s.substr(nl + 1);
  return line;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto& h = rcan::fuzz::NodeHarness::get();
  h.reset();
  const std::string text = h.expand(std::string_view(reinterpret_cast<const char*>(data), size));
  std::string_view rest(text);
  std::string_view first = next_line(rest);
  std::string_view authorization;
  if (size_t tab = first.find('\t'); tab != std::string_view::npos) {
    authorization = first.substr(tab + 1);
    first = first.substr(0, tab);
  }
  rcan::transport::HttpRequest up;
  up.method = "GET";
  up.target = std::string(first.empty() ? "/rcan/v1/stream" : first);
  if (rcan::transport::detail::split_target(up.target, up.path, up.query))
    return 0;  // the transport answers 400
  up.headers = {{"upgrade", "websocket"}, {"connection", "Upgrade"}};
  if (!authorization.empty()) up.headers.emplace_back("authorization", std::string(authorization));
  up.remote_addr = "127.0.0.1:40002";
  auto sink = std::make_shared<Sink>();
  rcan::transport::HttpResponse refusal;
  auto session = h.node().open(up, sink, refusal);
  if (!session) {
    if (refusal.status < 400 || refusal.status > 499)
      fail("refusal status " + std::to_string(refusal.status), refusal.body);
    return 0;
  }
  for (int n = 0; n < 32 && !rest.empty() && !sink->closed(); ++n) {
    std::string_view frame = next_line(rest);
    int seen = sink->answers();
    if (!frame.empty() && frame[0] == '\x02') {
      session->on_binary();
      if (!sink->closed()) fail("a binary frame did not close the stream");
      break;
    }
    session->on_text(std::string(frame));
    if (!sink->wait_answer(seen)) fail("a frame got no answer within 10 s", frame);
  }
  session->on_closed();
  return 0;
}
