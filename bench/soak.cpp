// soak — mixed traffic against a real rcand for a given time, sampled every minute, judged at
// the end (docs/SOAK.md; scripts/soak.sh runs the hour, CTest `soak_ci` five minutes).
//
// The daemon runs with a temporary data directory and the embedded configuration plus §16
// confidence gates (block / allow / escalate) and a planner brain layer (a real
// `rcand --sim-layer` process). One generator thread (Boost.Beast, C++20 coroutines) runs the
// clients, each paced at one request per --interval-ms, and checks every answer:
//
//   http_cmd  1/4 of the clients: COMMANDs (arm_move, status, gripper) over HTTP keep-alive → ACK
//   status    1/8: GET /rcan/v1/status with the token, a new connection each time → 200
//   ws        3/8: streams — CONNECT, SUBSCRIBE telemetry, COMMANDs answered on the stream;
//             each stream lives about a minute, then closes and a new one opens
//   gate      the rest: COMMANDs with an `ai` block, cycling through a chat gate miss (403
//             CONFIDENCE_GATE_FAIL confidence_below_gate), a chat pass (ACK), a teleop miss
//             that the gate lets through (ACK), a nav miss escalated to the planner (ACK with a
//             watermark) and a nav miss from the top layer (403 no_higher_layer)
//
// Every minute: rcand's VmRSS (and RssAnon), open fds (/proc/<pid>/fd) and threads — the median
// and the maximum of the per-second samples —, the audit directory's data and records, per
// traffic kind the answers, errors and latency p50/p99 within the minute, the gate outcomes and
// the telemetry frames the streams received.
//
// The judgement (all must hold; docs/SOAK.md):
//   1. no error: every answer as expected, no transport failure, rcand alive to the end; every
//      minute saw every traffic kind, every gate case and telemetry;
//   2. memory: max VmRSS of the last window ≤ max VmRSS of the early window + --rss-slack-mb,
//      where the early window is the W minutes after the first (warm-up) minute and the last
//      window the final W minutes, W = max(1, minutes / 6);
//   3. fds and threads under load: the last window's per-minute medians ≤ the early window's;
//      once the clients have gone, the idle counts equal those measured before the load began;
//   4. the audit directory grew over the run;
//   5. rcand stops cleanly on SIGTERM, `rcan audit verify --data-dir` verifies the chain, and it
//      holds at least as many records as commands were answered.
//
//   soak [--minutes 60] [--clients 64] [--interval-ms 250] [--rss-slack-mb 8] [--window-s 60]
//        [--segment-mib 8] [--only KIND] [--rcand PATH] [--rcan PATH] [--data-root /tmp] [--tsv
//        FILE]
//        [--keep]
// --window-s: the length of a sampling "minute" (shorter only to try the program out).
// Exit status 0 when every judgement holds.
// GCC 12 at -O3 reports -Wnull-dereference from inside Asio and libstdc++ once inlined here
// (middle-end false positives, as in src/transport/http_server.cpp). Off for this file only.
#pragma GCC diagnostic ignored "-Wnull-dereference"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_support.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/json.h"
#include "transport/beast.h"

namespace fs = std::filesystem;
namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = boost::beast::http;
namespace websocket = boost::beast::websocket;
using tcp = asio::ip::tcp;
using namespace rcan;
using namespace rcan::bench;

namespace {

constexpr auto kNoThrow = asio::as_tuple(asio::use_awaitable);

enum Kind { kHttpCmd = 0, kStatus, kWs, kGate, kKinds };
constexpr std::array<const char*, kKinds> kKindName{"http_cmd", "status", "ws", "gate"};

// The §16 gate cases a gate client cycles through.
enum GateCase {
  kChatBlocked = 0,
  kChatPass,
  kTeleopAllowed,
  kNavEscalated,
  kNavNoLayer,
  kGateCases
};

// What one sampling minute collected from the clients.
struct Window {
  std::array<std::vector<double>, kKinds> lat_ms;
  std::array<uint64_t, kKinds> ok{}, err{};
  std::array<uint64_t, kGateCases> gate{};
  uint64_t telemetry = 0, streams_opened = 0;
  std::vector<std::string> failures;
};

class Stats {
 public:
  void ok(Kind k, int64_t t0_us) {
    double ms = static_cast<double>(mono_us() - t0_us) / 1000.0;
    std::lock_guard<std::mutex> l(mu_);
    cur_.lat_ms[k].push_back(ms);
    ++cur_.ok[k];
    ++total_ok_[k];
  }
  void fail(Kind k, std::string why) {
    std::lock_guard<std::mutex> l(mu_);
    ++cur_.err[k];
    if (cur_.failures.size() < 5) cur_.failures.push_back(std::string(kKindName[k]) + ": " + why);
  }
  void gate(GateCase c) {
    std::lock_guard<std::mutex> l(mu_);
    ++cur_.gate[c];
  }
  void telemetry(uint64_t n) {
    std::lock_guard<std::mutex> l(mu_);
    cur_.telemetry += n;
  }
  void stream_opened() {
    std::lock_guard<std::mutex> l(mu_);
    ++cur_.streams_opened;
  }
  Window take() {
    std::lock_guard<std::mutex> l(mu_);
    return std::exchange(cur_, Window{});
  }
  uint64_t total_ok(Kind k) {
    std::lock_guard<std::mutex> l(mu_);
    return total_ok_[k];
  }

 private:
  std::mutex mu_;
  Window cur_;
  std::array<uint64_t, kKinds> total_ok_{};
};

struct Ctx {
  uint16_t port = 0;
  std::string token;
  std::string ruri;
  std::chrono::milliseconds interval{250};
  std::chrono::seconds stream_life{60};
  std::atomic<bool> stop{false};
  Stats stats;
};

std::string now_ms() { return std::to_string(wall_ms()); }

std::string command_json(const std::string& id, const std::string& action,
                         const std::string& params, const std::string& ai = "") {
  std::string s = R"({"version":"1.0.0","message_id":")" + id +
                  R"(","type":"COMMAND","timestamp_ms":)" + now_ms() + R"(,"payload":{"action":")" +
                  action + "\"" + params + "}";
  if (!ai.empty()) s += R"(,"ai":)" + ai;
  return s + "}";
}

std::string ai_json(double confidence, const std::string& layer) {
  char c[32];
  std::snprintf(c, sizeof c, "%.2f", confidence);
  return R"({"provider":"soak","model":"soak-)" + layer + R"(","confidence":)" + c +
         R"(,"layer":")" + layer + R"(","escalated":false})";
}

// The plain commands (HTTP and streams): an arm move, a status query, the gripper. None of
// them falls under a confidence gate (every drive and chat line would: a command without an
// `ai` block has no confidence, so the gates treat it as a miss — the gate clients drive).
std::string plain_command(uint64_t n, const std::string& id) {
  switch (n % 3) {
    case 0: {
      char joints[96];
      std::snprintf(joints, sizeof joints, R"(,"joints":[%.2f,0.1,0,0,0,0])",
                    0.05 * static_cast<double>(n % 10));
      return command_json(id, "arm_move", joints);
    }
    case 1:
      return command_json(id, "status", "");
    default:
      return command_json(id, n % 2 ? "gripper_open" : "gripper_close", "");
  }
}

std::string gate_command(GateCase c, const std::string& id) {
  switch (c) {
    case kChatBlocked:
      return command_json(id, "chat", R"(,"text":"soak")", ai_json(0.3, "fast"));
    case kChatPass:
      return command_json(id, "chat", R"(,"text":"soak")", ai_json(0.9, "fast"));
    case kTeleopAllowed:
      return command_json(id, "teleop", R"(,"linear":0.1,"duration_ms":100)",
                          ai_json(0.2, "reactive"));
    case kNavEscalated:
      return command_json(id, "move", R"(,"linear":0.2,"duration_ms":100,"instruction":"soak")",
                          ai_json(0.3, "fast"));
    default:
      return command_json(id, "move", R"(,"linear":0.2,"duration_ms":100)",
                          ai_json(0.1, "planner"));
  }
}

bool check_gate(GateCase c, int status, const std::string& body, const std::string& id,
                std::string& why) {
  switch (c) {
    case kChatBlocked:
      return check_node_error(status, body, id, 403, "CONFIDENCE_GATE_FAIL",
                              "confidence_below_gate", why);
    case kNavNoLayer:
      return check_node_error(status, body, id, 403, "CONFIDENCE_GATE_FAIL", "no_higher_layer",
                              why);
    case kNavEscalated:
      if (!check_node_ack(status, body, id, why)) return false;
      if (body.find("\"watermark_token\":\"rcan-wm-v1:") == std::string::npos) {
        why = "escalated command answered without a watermark: " + body.substr(0, 300);
        return false;
      }
      return true;
    default:
      return check_node_ack(status, body, id, why);
  }
}

// Sleeps until the client's next slot; a late client does not burst to catch up.
asio::awaitable<void> pace(std::chrono::steady_clock::time_point& next) {
  auto now = std::chrono::steady_clock::now();
  if (next < now) next = now;
  asio::steady_timer t(co_await asio::this_coro::executor);
  t.expires_at(next);
  co_await t.async_wait(kNoThrow);
}

std::chrono::milliseconds stagger(std::chrono::milliseconds interval) {
  thread_local std::mt19937 rng{std::random_device{}()};
  return std::chrono::milliseconds(
      std::uniform_int_distribution<int64_t>(0, interval.count())(rng));
}

// COMMANDs over one keep-alive connection (reopened after a transport error).
asio::awaitable<void> http_client(Ctx& c, Kind kind, uint64_t seq) {
  auto ex = co_await asio::this_coro::executor;
  auto next = std::chrono::steady_clock::now() + stagger(c.interval);
  std::unique_ptr<beast::tcp_stream> s;
  beast::flat_buffer buf;
  for (uint64_t n = seq; !c.stop.load(); ++n) {
    co_await pace(next);
    next += c.interval;
    if (!s) {
      s = std::make_unique<beast::tcp_stream>(ex);
      s->expires_after(std::chrono::seconds(10));
      auto [cec] = co_await s->async_connect(
          tcp::endpoint(asio::ip::make_address("127.0.0.1"), c.port), kNoThrow);
      if (cec) {
        c.stats.fail(kind, "connect: " + cec.message());
        s.reset();
        continue;
      }
      s->socket().set_option(tcp::no_delay(true));
      buf.clear();
    }
    std::string id = fast_uuid();
    GateCase gc = static_cast<GateCase>(n % kGateCases);
    http::request<http::string_body> req{http::verb::post, "/rcan/v1/command", 11};
    req.set(http::field::host, "127.0.0.1");
    req.set(http::field::authorization, "Bearer " + c.token);
    req.set(http::field::content_type, "application/json");
    req.keep_alive(true);
    req.body() = kind == kGate ? gate_command(gc, id) : plain_command(n, id);
    req.prepare_payload();
    int64_t t0 = mono_us();
    s->expires_after(std::chrono::seconds(30));
    auto [wec, wn] = co_await http::async_write(*s, req, kNoThrow);
    http::response<http::string_body> res;
    beast::error_code rec = wec;
    if (!wec) {
      auto [e2, rn] = co_await http::async_read(*s, buf, res, kNoThrow);
      rec = e2;
    }
    if (rec) {
      c.stats.fail(kind, "transport: " + rec.message());
      s.reset();
      continue;
    }
    std::string why;
    int status = static_cast<int>(res.result_int());
    bool good = kind == kGate ? check_gate(gc, status, res.body(), id, why)
                              : check_node_ack(status, res.body(), id, why);
    if (good) {
      c.stats.ok(kind, t0);
      if (kind == kGate) c.stats.gate(gc);
    } else {
      c.stats.fail(kind, why);
    }
    if (!res.keep_alive()) s.reset();
  }
  if (s) {
    beast::error_code ec;
    s->socket().shutdown(tcp::socket::shutdown_both, ec);
  }
}

// GET /rcan/v1/status with the token, one new connection per request.
asio::awaitable<void> status_client(Ctx& c) {
  auto ex = co_await asio::this_coro::executor;
  auto next = std::chrono::steady_clock::now() + stagger(c.interval);
  while (!c.stop.load()) {
    co_await pace(next);
    next += c.interval;
    int64_t t0 = mono_us();
    beast::tcp_stream s(ex);
    s.expires_after(std::chrono::seconds(30));
    auto [cec] = co_await s.async_connect(
        tcp::endpoint(asio::ip::make_address("127.0.0.1"), c.port), kNoThrow);
    if (cec) {
      c.stats.fail(kStatus, "connect: " + cec.message());
      continue;
    }
    http::request<http::empty_body> req{http::verb::get, "/rcan/v1/status", 11};
    req.set(http::field::host, "127.0.0.1");
    req.set(http::field::authorization, "Bearer " + c.token);
    req.keep_alive(false);
    auto [wec, wn] = co_await http::async_write(s, req, kNoThrow);
    beast::flat_buffer buf;
    http::response<http::string_body> res;
    beast::error_code rec = wec;
    if (!wec) {
      auto [e2, rn] = co_await http::async_read(s, buf, res, kNoThrow);
      rec = e2;
    }
    beast::error_code ec;
    s.socket().shutdown(tcp::socket::shutdown_both, ec);
    if (rec) {
      c.stats.fail(kStatus, "transport: " + rec.message());
      continue;
    }
    auto v = json::parse(res.body(), json::ParseOptions{});
    const json::Value* ruri = v.ok() && v->is_object() ? v->get("ruri") : nullptr;
    if (res.result_int() == 200 && ruri && ruri->is_string() && ruri->as_string() == c.ruri) {
      c.stats.ok(kStatus, t0);
    } else {
      c.stats.fail(kStatus,
                   "status " + std::to_string(res.result_int()) + ": " + res.body().substr(0, 300));
    }
  }
}

// Streams: CONNECT, SUBSCRIBE telemetry, paced COMMANDs; each stream lives `stream_life`
// (the first one a random part of it, so that the clients do not reconnect together).
asio::awaitable<void> ws_client(Ctx& c, uint64_t seq) {
  auto ex = co_await asio::this_coro::executor;
  auto next = std::chrono::steady_clock::now() + stagger(c.interval);
  auto life = std::chrono::duration_cast<std::chrono::milliseconds>(c.stream_life);
  auto first_life = stagger(life) + life / 4;
  uint64_t n = seq;
  for (bool first = true; !c.stop.load(); first = false) {
    co_await pace(next);
    websocket::stream<beast::tcp_stream> ws(ex);
    auto& low = beast::get_lowest_layer(ws);
    low.expires_after(std::chrono::seconds(10));
    auto [cec] = co_await low.async_connect(
        tcp::endpoint(asio::ip::make_address("127.0.0.1"), c.port), kNoThrow);
    if (!cec) {
      low.socket().set_option(tcp::no_delay(true));
      auto [hec] = co_await ws.async_handshake("127.0.0.1", "/rcan/v1/stream", kNoThrow);
      cec = hec;
    }
    beast::flat_buffer in;
    if (!cec) {
      ws.text(true);
      std::string hello = R"({"type":"CONNECT","token":")" + c.token + "\"}";
      low.expires_after(std::chrono::seconds(10));
      auto [wec, wn] = co_await ws.async_write(asio::buffer(hello), kNoThrow);
      cec = wec;
      if (!cec) {
        auto [rec, rn] = co_await ws.async_read(in, kNoThrow);
        cec = rec;
      }
    }
    if (cec) {
      c.stats.fail(kWs, "stream open: " + cec.message());
      next += c.interval;
      continue;
    }
    if (beast::buffers_to_string(in.data()).find("\"CONNECT_ACK\"") == std::string::npos) {
      c.stats.fail(kWs, "CONNECT refused: " + beast::buffers_to_string(in.data()).substr(0, 200));
      next += c.interval;
      continue;
    }
    c.stats.stream_opened();
    {
      low.expires_after(std::chrono::seconds(10));
      auto [wec, wn] = co_await ws.async_write(
          asio::buffer(std::string(R"({"type":"SUBSCRIBE","topics":["telemetry"],"hz":5})")),
          kNoThrow);
      if (wec) {
        c.stats.fail(kWs, "SUBSCRIBE: " + wec.message());
        next += c.interval;
        continue;
      }
    }
    const auto opened = std::chrono::steady_clock::now();
    const auto until = opened + (first ? first_life : life);
    uint64_t telemetry = 0;
    bool broken = false;
    while (!c.stop.load() && std::chrono::steady_clock::now() < until && !broken) {
      co_await pace(next);
      next += c.interval;
      std::string id = fast_uuid();
      std::string frame = plain_command(n++, id);
      int64_t t0 = mono_us();
      low.expires_after(std::chrono::seconds(30));
      auto [wec, wn] = co_await ws.async_write(asio::buffer(frame), kNoThrow);
      if (wec) {
        c.stats.fail(kWs, "write: " + wec.message());
        broken = true;
        break;
      }
      for (;;) {  // until the answer to this message (telemetry and events come in between)
        in.clear();
        low.expires_after(std::chrono::seconds(30));
        auto [rec, rn] = co_await ws.async_read(in, kNoThrow);
        if (rec) {
          c.stats.fail(kWs, "read: " + rec.message());
          broken = true;
          break;
        }
        std::string text = beast::buffers_to_string(in.data());
        if (text.find(R"("topic":"telemetry")") != std::string::npos) {
          ++telemetry;
          continue;
        }
        if (text.find(id) == std::string::npos) continue;  // an event
        std::string why;
        int status = text.find(R"("type":"ERROR")") != std::string::npos ? 0 : 200;
        if (check_node_ack(status, text, id, why)) {
          c.stats.ok(kWs, t0);
        } else {
          c.stats.fail(kWs, why);
        }
        break;
      }
    }
    c.stats.telemetry(telemetry);
    // 5 Hz telemetry for a few seconds must have brought some frames.
    if (!broken && std::chrono::steady_clock::now() - opened > std::chrono::seconds(5) &&
        telemetry == 0)
      c.stats.fail(kWs, "no telemetry on a stream open for more than 5 s");
    if (!broken) {
      low.expires_after(std::chrono::seconds(5));
      auto [clec] = co_await ws.async_close(websocket::close_code::normal, kNoThrow);
      // Frames in flight arrive before the close answer; async_close reads past them.
      if (clec && clec != websocket::error::closed) c.stats.fail(kWs, "close: " + clec.message());
    }
  }
}

// ---- the per-minute table ------------------------------------------------------------------

struct Row {
  int minute = 0;
  double rss_mb = 0, rss_max_mb = 0, anon_mb = 0;
  int fds = 0, fds_max = 0;
  long threads = 0, threads_max = 0;
  double audit_mb = 0;
  uint64_t audit_records = 0;
  Window w;
};

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::vector<std::string> header() {
  std::vector<std::string> h{"min",      "rss_mb",       "rss_max_mb",  "rss_anon_mb",
                             "fds_med",  "fds_max",      "threads_med", "threads_max",
                             "audit_mb", "audit_records"};
  for (const char* k : kKindName) {
    h.push_back(std::string(k) + "_n");
    h.push_back(std::string(k) + "_p50_ms");
    h.push_back(std::string(k) + "_p99_ms");
  }
  h.insert(h.end(), {"gate_blocked", "gate_passed", "gate_allowed", "gate_escalated",
                     "gate_no_layer", "telemetry", "streams", "errors"});
  return h;
}

std::vector<std::string> cells(Row& r) {
  std::vector<std::string> c{std::to_string(r.minute),  fmt("%.1f", r.rss_mb),
                             fmt("%.1f", r.rss_max_mb), fmt("%.1f", r.anon_mb),
                             std::to_string(r.fds),     std::to_string(r.fds_max),
                             std::to_string(r.threads), std::to_string(r.threads_max),
                             fmt("%.1f", r.audit_mb),   std::to_string(r.audit_records)};
  uint64_t errors = 0;
  for (int k = 0; k < kKinds; ++k) {
    auto& v = r.w.lat_ms[static_cast<size_t>(k)];
    std::sort(v.begin(), v.end());
    c.push_back(std::to_string(r.w.ok[static_cast<size_t>(k)]));
    c.push_back(fmt("%.2f", pct(v, 0.50)));
    c.push_back(fmt("%.2f", pct(v, 0.99)));
    errors += r.w.err[static_cast<size_t>(k)];
  }
  for (uint64_t g : r.w.gate) c.push_back(std::to_string(g));
  c.push_back(std::to_string(r.w.telemetry));
  c.push_back(std::to_string(r.w.streams_opened));
  c.push_back(std::to_string(errors));
  return c;
}

std::string join(const std::vector<std::string>& v, const std::string& sep,
                 const std::string& pre = "", const std::string& post = "") {
  std::string s = pre;
  for (size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
  return s + post;
}

// Audit records the node has written since it started (sum of rcan_audit_records_total).
uint64_t audit_records(uint16_t port) {
  std::string text;
  if (sync_http(port, http::verb::get, "/metrics", "", "", &text) != 200) return 0;
  std::istringstream is(text);
  std::string line;
  uint64_t n = 0;
  while (std::getline(is, line))
    if (line.rfind("rcan_audit_records_total{", 0) == 0)
      n += std::strtoull(line.c_str() + line.rfind(' ') + 1, nullptr, 10);
  return n;
}

// Runs a command, returns its exit status and its stdout + stderr.
int run_capture(const std::string& cmd, std::string& out) {
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  char b[4096];
  size_t k;
  while ((k = fread(b, 1, sizeof b, p)) > 0) out.append(b, k);
  int st = pclose(p);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char ch : s) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}

// ---- the run -------------------------------------------------------------------------------

// The command line.
struct Options {
  std::string rcand, rcan_cli;
  double minutes = 60, rss_slack_mb = 8, window_s = 60;
  int clients = 64, interval_ms = 250;
  long segment_mib = 8;
  std::string only;
  std::string data_root = "/tmp", tsv_path;
  bool keep = false;
  int n_minutes = 0;  // --minutes, rounded, at least 2
};

// False (after printing the usage or what is out of range) when the options do not fit.
bool parse_options(int argc, char** argv, Options& o) {
  fs::path self_dir = fs::path(argv[0]).parent_path();
  o.rcand = (self_dir / ".." / "bin" / "rcand").string();
  o.rcan_cli = (self_dir / ".." / "bin" / "rcan").string();
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    if (a == "--minutes")
      o.minutes = std::atof(next().c_str());
    else if (a == "--clients")
      o.clients = std::atoi(next().c_str());
    else if (a == "--interval-ms")
      o.interval_ms = std::atoi(next().c_str());
    else if (a == "--rss-slack-mb")
      o.rss_slack_mb = std::atof(next().c_str());
    else if (a == "--window-s")
      o.window_s = std::atof(next().c_str());
    else if (a == "--segment-mib")
      o.segment_mib = std::atol(next().c_str());
    else if (a == "--only")
      o.only = next();
    else if (a == "--rcand")
      o.rcand = next();
    else if (a == "--rcan")
      o.rcan_cli = next();
    else if (a == "--data-root")
      o.data_root = next();
    else if (a == "--tsv")
      o.tsv_path = next();
    else if (a == "--keep")
      o.keep = true;
    else {
      std::fprintf(
          stderr,
          "usage: soak [--minutes 60] [--clients 64] [--interval-ms 250] [--rss-slack-mb 8]\n"
          "            [--window-s 60] [--segment-mib 8] [--only KIND] [--rcand PATH] [--rcan "
          "PATH] [--data-root DIR] [--tsv FILE] [--keep]\n");
      return false;
    }
  }
  o.n_minutes = std::max(2, static_cast<int>(o.minutes + 0.5));
  const std::string& only = o.only;
  if (!only.empty() && only != "http_cmd" && only != "status" && only != "ws" && only != "gate") {
    std::fprintf(stderr, "soak: --only http_cmd|status|ws|gate\n");
    return false;
  }
  if (o.clients < 8 || o.interval_ms < 1 || o.window_s < 1 || o.segment_mib < 1 ||
      o.segment_mib > 4096) {
    std::fprintf(stderr,
                 "soak: --clients ≥ 8, --interval-ms ≥ 1, --window-s ≥ 1, --segment-mib 1–4096\n");
    return false;
  }
  return true;
}

// Removes the temporary directory when the run ends (unless --keep), however it ends.
struct Cleanup {
  std::string dir;
  bool keep;
  ~Cleanup() {
    std::error_code ec;
    if (!keep) fs::remove_all(dir, ec);
  }
};

// The run's shared state: the daemon and its planner layer, the clients' context, the figures
// measured before the load.
struct Soak {
  Options opt;
  std::string root;
  Node node;
  std::unique_ptr<Child> layer;
  pid_t pid = -1;  // rcand's, once configured
  Ctx ctx;
  ProcStat idle0;
  int idle_fds0 = 0;
  std::string idle_threads0;  // thread names before the load
  uint64_t audit0 = 0;
};

// 1. A first start creates the data directory (keys, audit secret, local issuer, device id).
bool first_start(Soak& s) {
  s.node.dir = s.root + "/node";
  if (!start_node(s.node, s.opt.rcand, {}, "")) return false;
  s.node.child->stop();
  return true;
}

// 2. The planner layer (a `rcand --sim-layer` process); returns its URL, empty when it did not
// start.
std::string start_layer(Soak& s) {
  s.layer = std::make_unique<Child>(
      std::vector<std::string>{s.opt.rcand, "--sim-layer", "--port", "0", "--layer", "planner",
                               "--confidence", "0.95"},
      "");
  Child& layer = *s.layer;
  std::string layer_url;
  for (int i = 0; i < 3000 && layer_url.empty() && layer.alive(); ++i) {
    std::string head = layer.head();
    size_t p = head.find("\"url\":\"");
    if (head.find("\"event\":\"listening\"") != std::string::npos && p != std::string::npos)
      layer_url = head.substr(p + 7, head.find('"', p + 7) - p - 7);
    else
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (layer_url.empty())
    std::fprintf(stderr, "the sim layer did not start:\n%s\n", layer.head().c_str());
  return layer_url;
}

// Replaces `block` of the embedded configuration with `with`; false (after naming what is
// missing) when the configuration has no such block.
bool replace_block(std::string& yaml, const std::string& block, const std::string& with,
                   const char* missing) {
  size_t p = yaml.find(block);
  if (p == std::string::npos) {
    std::fprintf(stderr, "soak: the embedded configuration has no %s\n", missing);
    return false;
  }
  yaml.replace(p, block.size(), with);
  return true;
}

// The §16 confidence gates and the planner layer, in place of the embedded agent block.
bool configure_gates(std::string& yaml, const std::string& layer_url) {
  const std::string agent_default =
      "agent:\n  provider: none\n  confidence_gates: []\n  hitl_gates: []\n";
  return replace_block(yaml, agent_default,
                       "agent:\n  provider: none\n  confidence_gates:\n"
                       "    - {scope: nav, min_confidence: 0.8, on_fail: escalate}\n"
                       "    - {scope: chat, min_confidence: 0.5, on_fail: block}\n"
                       "    - {scope: teleop, min_confidence: 0.6, on_fail: allow}\n"
                       "  hitl_gates: []\n  layers:\n    planner: {url: \"" +
                           layer_url + "\", timeout_ms: 5000}\n",
                       "agent block to replace");
}

// The local issuer the first start created, now as a configured issuer (a configured robot
// generates nothing and trusts only what its configuration names).
bool configure_issuer(std::string& yaml, const Soak& s) {
  std::ifstream sf(s.node.dir + "/issuer/ed25519.seed", std::ios::binary);
  std::string seed((std::istreambuf_iterator<char>(sf)), std::istreambuf_iterator<char>());
  auto pk = ed25519::public_key_from_seed(Bytes(seed.begin(), seed.end()));
  auto pem = pk.ok() ? ed25519::public_key_to_pem(*pk) : Result<std::string>(pk.error());
  const std::string jwt_default = "  jwt:\n    leeway_s: 60\n";
  size_t jp = yaml.find(jwt_default);
  if (!pem.ok() || jp == std::string::npos) {
    std::fprintf(stderr, "soak: cannot configure the local issuer\n");
    return false;
  }
  std::ofstream(s.root + "/issuer.pub.pem") << *pem;
  yaml.replace(jp, jwt_default.size(),
               jwt_default + "    issuers:\n      - {issuer: rcand-local, key_file: " + s.root +
                   "/issuer.pub.pem}\n");
  return true;
}

// Audit segments of --segment-mib: the active segment's index lives in memory until the
// segment is sealed (docs/AUDIT.md §6), so memory legitimately grows with the segment; small
// segments make several rotations happen within the run and that bound visible.
bool configure_audit(std::string& yaml, long segment_mib) {
  const std::string audit_default = "  audit:\n    sync: per_group\n";
  return replace_block(
      yaml, audit_default,
      audit_default + "    max_segment_bytes: " + std::to_string(segment_mib * 1024 * 1024) + "\n",
      "audit block to extend");
}

// The configuration with the gates: <root>/soak.rcan.yaml.
bool write_config(const Soak& s, const std::string& layer_url) {
  std::string yaml = default_yaml_for(s.node.dir);
  if (!configure_gates(yaml, layer_url) || !configure_issuer(yaml, s) ||
      !configure_audit(yaml, s.opt.segment_mib))
    return false;
  // No mDNS: the soak measures the node, not the machine's Avahi daemon.
  if (size_t mp = yaml.find("enable_mdns: true"); mp != std::string::npos)
    yaml.replace(mp, 17, "enable_mdns: false");
  {
    std::ofstream cf(s.root + "/soak.rcan.yaml");
    cf << yaml;
  }
  return true;
}

// Restarts rcand with the configuration, issues the clients' token and measures the idle node.
bool restart_configured(Soak& s) {
  Node& node = s.node;
  std::string ruri = node.ruri;
  node.ruri.clear();
  if (!start_node(node, s.opt.rcand, {"--config", s.root + "/soak.rcan.yaml"}, "")) return false;
  if (node.ruri != ruri)
    std::fprintf(stderr, "soak: note: RURI %s after restart (was %s)\n", node.ruri.c_str(),
                 ruri.c_str());
  s.pid = node.child->pid();
  const int64_t lifetime_s = static_cast<int64_t>(s.opt.n_minutes * s.opt.window_s) + 3600;
  Ctx& ctx = s.ctx;
  ctx.port = node.port;
  ctx.ruri = node.ruri;
  ctx.token =
      token_for(node.dir + "/issuer/ed25519.seed", "rcand-local", node.ruri, "soak", lifetime_s);
  ctx.interval = std::chrono::milliseconds(s.opt.interval_ms);
  ctx.stream_life =
      std::chrono::seconds(std::max<int64_t>(5, static_cast<int64_t>(s.opt.window_s)));
  if (ctx.token.empty()) {
    std::fprintf(stderr, "soak: cannot issue a token\n");
    return false;
  }
  settle(s.pid);
  s.idle0 = proc_stat(s.pid);
  s.idle_fds0 = count_fds(s.pid);
  s.idle_threads0 = thread_names(s.pid);
  s.audit0 = dir_data_bytes(node.dir + "/audit");
  return true;
}

// How many clients of each kind.
struct ClientMix {
  int n_cmd = 0, n_status = 0, n_ws = 0, n_gate = 0;
};

ClientMix client_mix(const Options& o) {
  const int clients = o.clients;
  const std::string& only = o.only;
  int n_cmd = clients / 4, n_status = clients / 8, n_ws = clients * 3 / 8;
  int n_gate = clients - n_cmd - n_status - n_ws;
  if (!only.empty()) {  // one kind only (to tell which traffic a growth comes from)
    n_cmd = only == "http_cmd" ? clients : 0;
    n_status = only == "status" ? clients : 0;
    n_ws = only == "ws" ? clients : 0;
    n_gate = only == "gate" ? clients : 0;
  }
  return ClientMix{n_cmd, n_status, n_ws, n_gate};
}

void print_intro(const Soak& s, const ClientMix& mix) {
  const Options& o = s.opt;
  std::printf(
      "soak: rcand %s (pid %d), %d minutes of %.0f s, %d clients (http_cmd %d, status %d, ws %d, "
      "gate %d), "
      "one request per %d ms each, audit segments of %ld MiB\n",
      s.node.ruri.c_str(), static_cast<int>(s.pid), o.n_minutes, o.window_s, o.clients, mix.n_cmd,
      mix.n_status, mix.n_ws, mix.n_gate, o.interval_ms, o.segment_mib);
  std::printf("  idle before load: VmRSS %.1f MB, fds %d, threads %ld; data dir %s\n",
              static_cast<double>(s.idle0.rss_kb) / 1024.0, s.idle_fds0, s.idle0.threads,
              s.node.dir.c_str());
  std::fflush(stdout);
}

// Spawns every client on `io` (run by the generator thread).
void spawn_clients(asio::io_context& io, Ctx& ctx, const ClientMix& mix) {
  auto done = [&ctx](std::exception_ptr e) {
    if (!e) return;
    try {
      std::rethrow_exception(e);
    } catch (const std::exception& ex) {
      ctx.stats.fail(kHttpCmd, std::string("a client ended on an exception: ") + ex.what());
    }
  };
  for (int i = 0; i < mix.n_cmd; ++i)
    asio::co_spawn(io, http_client(ctx, kHttpCmd, static_cast<uint64_t>(i)), done);
  for (int i = 0; i < mix.n_gate; ++i)
    asio::co_spawn(io, http_client(ctx, kGate, static_cast<uint64_t>(i)), done);
  for (int i = 0; i < mix.n_status; ++i) asio::co_spawn(io, status_client(ctx), done);
  for (int i = 0; i < mix.n_ws; ++i)
    asio::co_spawn(io, ws_client(ctx, static_cast<uint64_t>(i)), done);
}

// Minute `m`'s row: rcand sampled every second until the minute ends (`died` when it is gone),
// then what the clients collected.
Row sample_minute(Soak& s, int m, std::chrono::steady_clock::time_point t_start, bool& died) {
  const pid_t pid = s.pid;
  Row r;
  r.minute = m;
  const auto end =
      t_start + std::chrono::milliseconds(static_cast<int64_t>(m * s.opt.window_s * 1000));
  std::vector<long> fd_samples, thread_samples;
  while (std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_until(
        std::min(end, std::chrono::steady_clock::now() + std::chrono::seconds(1)));
    if (!s.node.child->alive()) {
      died = true;
      break;
    }
    ProcStat ps = proc_stat(pid);
    r.rss_max_mb = std::max(r.rss_max_mb, static_cast<double>(ps.rss_kb) / 1024.0);
    fd_samples.push_back(count_fds(pid));
    thread_samples.push_back(ps.threads);
  }
  r.w = s.ctx.stats.take();
  ProcStat ps = proc_stat(pid);
  r.rss_mb = static_cast<double>(ps.rss_kb) / 1024.0;
  r.anon_mb = static_cast<double>(ps.rss_anon_kb) / 1024.0;
  r.rss_max_mb = std::max(r.rss_max_mb, r.rss_mb);
  fd_samples.push_back(count_fds(pid));
  thread_samples.push_back(ps.threads);
  // The median of the per-second samples (what stays open) and their maximum (transients:
  // a status client's connection in flight, a stream reconnecting, a segment being sealed).
  auto median_max = [](std::vector<long>& v, long& median, long& mx) {
    std::sort(v.begin(), v.end());
    median = v[v.size() / 2];
    mx = v.back();
  };
  long fmed = 0, fmax = 0;
  median_max(fd_samples, fmed, fmax);
  r.fds = static_cast<int>(fmed);
  r.fds_max = static_cast<int>(fmax);
  median_max(thread_samples, r.threads, r.threads_max);
  r.audit_mb = static_cast<double>(dir_data_bytes(s.node.dir + "/audit")) / (1024.0 * 1024.0);
  r.audit_records = audit_records(s.node.port);
  return r;
}

// The minutes, each printed (and written to --tsv) as it ends; true when rcand died.
bool sample_minutes(Soak& s, std::vector<Row>& rows) {
  std::ofstream tsv;
  if (!s.opt.tsv_path.empty()) {
    tsv.open(s.opt.tsv_path);
    tsv << join(header(), "\t") << "\n" << std::flush;
  }
  std::printf("%s\n", join(header(), "\t").c_str());
  bool died = false;
  const auto t_start = std::chrono::steady_clock::now();
  for (int m = 1; m <= s.opt.n_minutes && !died; ++m) {
    Row r = sample_minute(s, m, t_start, died);
    auto c = cells(r);
    std::printf("%s\n", join(c, "\t").c_str());
    for (auto& f : r.w.failures) std::printf("  failure: %s\n", f.c_str());
    std::fflush(stdout);
    if (tsv.is_open()) tsv << join(c, "\t") << "\n" << std::flush;
    rows.push_back(std::move(r));
  }
  return died;
}

// ---- the judgement ----------------------------------------------------------------------

// Each judgement: whether it holds, and what it says.
struct Verdicts {
  std::vector<std::pair<bool, std::string>> list;
  void judge(bool ok, std::string what) { list.emplace_back(ok, std::move(what)); }
};

// 1. No error, and every minute saw every traffic kind; returns the commands answered.
uint64_t judge_errors(Soak& s, const std::vector<Row>& rows, bool died, Verdicts& v) {
  Window tail = s.ctx.stats.take();  // answers that came in after the last sample
  uint64_t tail_errors = 0;
  for (auto e : tail.err) tail_errors += e;
  char line[512];

  uint64_t errors = tail_errors, answered = 0, commands = 0;
  for (auto& r : rows)
    for (int k = 0; k < kKinds; ++k) errors += r.w.err[static_cast<size_t>(k)];
  for (int k = 0; k < kKinds; ++k) {
    uint64_t t = s.ctx.stats.total_ok(static_cast<Kind>(k));
    answered += t;
    if (k != kStatus) commands += t;
  }
  for (auto& f : tail.failures) std::printf("  failure (after the last sample): %s\n", f.c_str());
  std::snprintf(line, sizeof line, "no error: %llu answers checked, %llu errors%s",
                static_cast<unsigned long long>(answered), static_cast<unsigned long long>(errors),
                died ? "; rcand DIED during the run" : "");
  v.judge(errors == 0 && !died && answered > 0, line);
  bool every_kind = true;
  for (auto& r : rows)
    for (int k = 0; k < kKinds; ++k) every_kind = every_kind && r.w.ok[static_cast<size_t>(k)] > 0;
  for (auto& r : rows)
    for (int g = 0; g < kGateCases; ++g)
      every_kind = every_kind && r.w.gate[static_cast<size_t>(g)] > 0;
  for (auto& r : rows) every_kind = every_kind && r.w.telemetry > 0;
  if (s.opt.only.empty())
    v.judge(every_kind && !rows.empty(),
            "every minute answered every traffic kind and every gate case, and the streams "
            "received telemetry");
  return commands;
}

// 2.–3. Memory, fds and threads under load: the last window against the early one.
void judge_growth(const Soak& s, const std::vector<Row>& rows, bool died, Verdicts& v) {
  const int n_minutes = s.opt.n_minutes;
  char line[512];
  const int W = std::max(1, n_minutes / 6);
  auto window_max = [&](int from, int to, auto get) {  // minutes [from, to], 1-based
    double mx = 0;
    for (auto& r : rows)
      if (r.minute >= from && r.minute <= to) mx = std::max(mx, static_cast<double>(get(r)));
    return mx;
  };
  const int early_from = 2, early_to = 1 + W, last_from = n_minutes - W + 1, last_to = n_minutes;
  if (!died && static_cast<int>(rows.size()) == n_minutes) {
    double rss_e = window_max(early_from, early_to, [](const Row& r) { return r.rss_max_mb; });
    double rss_l = window_max(last_from, last_to, [](const Row& r) { return r.rss_max_mb; });
    std::snprintf(
        line, sizeof line,
        "memory: max VmRSS minutes %d-%d = %.1f MB ≤ max VmRSS minutes %d-%d (%.1f MB) + %.0f MB",
        last_from, last_to, rss_l, early_from, early_to, rss_e, s.opt.rss_slack_mb);
    v.judge(rss_l <= rss_e + s.opt.rss_slack_mb, line);
    double fd_e = window_max(early_from, early_to, [](const Row& r) { return r.fds; });
    double fd_l = window_max(last_from, last_to, [](const Row& r) { return r.fds; });
    std::snprintf(line, sizeof line,
                  "fds under load: median minutes %d-%d = %.0f ≤ median minutes %d-%d = %.0f",
                  last_from, last_to, fd_l, early_from, early_to, fd_e);
    v.judge(fd_l <= fd_e, line);
    double th_e = window_max(early_from, early_to, [](const Row& r) { return r.threads; });
    double th_l = window_max(last_from, last_to, [](const Row& r) { return r.threads; });
    std::snprintf(line, sizeof line,
                  "threads under load: median minutes %d-%d = %.0f ≤ median minutes %d-%d = %.0f",
                  last_from, last_to, th_l, early_from, early_to, th_e);
    v.judge(th_l <= th_e, line);
  } else {
    v.judge(false, "memory, fds, threads: the run did not complete");
  }
}

// 3.–4. Idle again with the counts from before the load; the audit directory grew.
void judge_idle_and_audit(const Soak& s, Verdicts& v) {
  const pid_t pid = s.pid;
  const int idle_fds0 = s.idle_fds0;
  const ProcStat& idle0 = s.idle0;
  char line[512];
  // Idle again: the clients have closed their connections.
  int idle_fds1 = -1;
  ProcStat idle1;
  for (int i = 0; i < 50 && s.node.child->alive(); ++i) {  // closes finish within a moment
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    idle_fds1 = count_fds(pid);
    idle1 = proc_stat(pid);
    if (idle_fds1 == idle_fds0 && idle1.threads == idle0.threads) break;
  }
  std::snprintf(line, sizeof line,
                "idle after the load: fds %d (before: %d), threads %ld (before: %ld), VmRSS %.1f "
                "MB (before: %.1f MB)",
                idle_fds1, idle_fds0, idle1.threads, idle0.threads,
                static_cast<double>(idle1.rss_kb) / 1024.0,
                static_cast<double>(idle0.rss_kb) / 1024.0);
  std::string what = line;
  if (idle1.threads != idle0.threads)  // say which thread came or went
    what += "\n      threads before: " + s.idle_threads0 +
            "\n      threads after:  " + thread_names(pid);
  v.judge(idle_fds1 == idle_fds0 && idle1.threads == idle0.threads, what);
  const uint64_t audit1 = dir_data_bytes(s.node.dir + "/audit");
  std::snprintf(line, sizeof line, "audit grows: %.1f MB → %.1f MB",
                static_cast<double>(s.audit0) / 1048576.0, static_cast<double>(audit1) / 1048576.0);
  v.judge(audit1 > s.audit0, line);
}

// 5. rcand stops cleanly and `rcan audit verify` verifies at least `commands` records.
void judge_shutdown(Soak& s, uint64_t commands, Verdicts& v) {
  char line[512];
  int st = s.node.child->stop();
  v.judge(WIFEXITED(st) && WEXITSTATUS(st) == 0, "rcand stopped cleanly on SIGTERM (exit 0)");
  s.layer->stop();
  std::string vout;
  int vrc = run_capture(shell_quote(s.opt.rcan_cli) + " audit verify --data-dir " +
                            shell_quote(s.node.dir) + " --secret-file " +
                            shell_quote(s.node.dir + "/audit.secret"),
                        vout);
  while (!vout.empty() && vout.back() == '\n') vout.pop_back();
  unsigned long long records = 0;
  if (size_t p = vout.find("ok: "); p != std::string::npos)
    records = std::strtoull(vout.c_str() + p + 4, nullptr, 10);
  std::snprintf(
      line, sizeof line,
      "audit chain: `rcan audit verify` exit %d (%s); %llu records ≥ %llu commands answered", vrc,
      vout.substr(0, 200).c_str(), records, static_cast<unsigned long long>(commands));
  v.judge(vrc == 0 && records >= commands, line);
}

// The quotable table and the verdicts; true when every judgement holds.
bool print_results(const Soak& s, std::vector<Row>& rows, const Verdicts& v) {
  std::printf("\n%s\n", join(header(), " | ", "| ", " |").c_str());
  std::vector<std::string> sep(header().size(), "---:");
  std::printf("%s\n", join(sep, "|", "|", "|").c_str());
  for (auto& r : rows) std::printf("%s\n", join(cells(r), " | ", "| ", " |").c_str());
  std::printf(
      "\nlatency in ms (client round trip, per request kind, within the minute); sizes in MiB\n\n");
  bool all = true;
  for (auto& [ok, what] : v.list) {
    std::printf("%s  %s\n", ok ? "PASS" : "FAIL", what.c_str());
    all = all && ok;
  }
  std::printf("\nsoak: %s\n", all ? "PASS" : "FAIL");
  if (s.opt.keep) std::printf("data kept in %s\n", s.root.c_str());
  return all;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (!parse_options(argc, argv, opt)) return 2;
  signal(SIGPIPE, SIG_IGN);
  std::string tmpl_s = opt.data_root + "/rcan-soak-XXXXXX";
  std::vector<char> tmpl(tmpl_s.begin(), tmpl_s.end());
  tmpl.push_back('\0');
  const char* made = mkdtemp(tmpl.data());
  if (!made) {
    std::perror("soak: mkdtemp");
    return 1;
  }
  Cleanup cleanup{made, opt.keep};
  Soak s;
  s.opt = opt;
  s.root = made;

  if (!first_start(s)) return 1;
  const std::string layer_url = start_layer(s);
  if (layer_url.empty() || !write_config(s, layer_url) || !restart_configured(s)) return 1;
  const ClientMix mix = client_mix(opt);
  print_intro(s, mix);

  asio::io_context io{1};
  spawn_clients(io, s.ctx, mix);
  std::thread gen([&] { io.run(); });
  std::vector<Row> rows;
  const bool died = sample_minutes(s, rows);
  s.ctx.stop = true;
  gen.join();

  Verdicts verdicts;
  const uint64_t commands = judge_errors(s, rows, died, verdicts);
  judge_growth(s, rows, died, verdicts);
  judge_idle_and_audit(s, verdicts);
  judge_shutdown(s, commands, verdicts);
  return print_results(s, rows, verdicts) ? 0 : 1;
}
