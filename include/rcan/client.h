// rcan::client — talk to RCAN nodes: discover, status, claim/release/handoff, commands over
// HTTP and over a reconnecting WebSocket stream, ESTOP/RESUME, §16 pending/authorize, audit
// export, thought lookup and watermark verification.
//
// Every call returns a client::Result<T>: the typed answer, or a ClientError carrying the
// profile's error code exactly as the node sent it (`payload.error_code` of the error body,
// docs/PROTOCOL.md §Errors; the §16.6 verify endpoint's `code`, e.g. "HTTP_404"), the HTTP
// status and the whole body. Failures before any HTTP answer carry http_status 0 and one of
// the client's own codes: CONNECTION_FAILED, TLS_FAILED, TIMEOUT, BAD_RESPONSE, BAD_URL.
//
// URLs: http://host[:port] and https://host[:port] (TLS: the system's trust store, or
// `ca_file`; the host name is verified unless `insecure`). A path prefix is kept.
// Calls are blocking and a Client is not thread-safe; use one per thread. Stream is
// thread-safe for send()/stop().
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "rcan/error_code.h"
#include "rcan/json.h"
#include "rcan/mdns_txt.h"
#include "rcan/result.h"

namespace rcan::client {

struct ClientError {
  std::string code;           // profile error code ("CONTROL_CONFLICT") or a client code (above)
  int http_status = 0;        // 0 when no HTTP answer arrived
  std::string message;        // human-readable (the body's `error`, or what failed)
  std::string reason;         // payload.detail.reason or payload.reason when present
  int64_t retry_after_s = 0;  // from Retry-After on 429
  json::Value body;           // the parsed body when it was JSON
  // The code as the library's enum when it is one of the profile's.
  std::optional<ErrorCode> known() const { return error_from_name(code); }
  bool unreachable() const { return http_status == 0; }
};

template <typename T>
using Result = rcan::Result<T, ClientError>;

// ---------------------------------------------------------------------------------------
// Addresses

struct Endpoint {
  bool tls = false;
  std::string host;  // name or address (IPv6 without brackets)
  uint16_t port = 0;
  std::string base_path;    // "" or "/prefix" (no trailing slash)
  std::string url() const;  // scheme://host:port[/prefix]
};
// http[s]://host[:port][/prefix]; a bare "host[:port]" means http. Default ports 80/443.
Result<Endpoint> parse_endpoint(std::string_view url);

// ---------------------------------------------------------------------------------------
// Typed answers

struct SessionInfo {
  std::string session_id;
  std::string role;
  std::string principal;
  int64_t expires_in_s = -1;  // -1 = no expiry
};

struct RobotStatus {
  std::string ruri;
  std::string rrn;
  std::string name;
  std::string rcan_version;
  std::vector<std::string> extensions;
  std::vector<std::string> capabilities;
  bool estop_active = false;
  std::string mode;
  bool audit_available = true;
  int64_t active_sessions = 0;
  std::vector<SessionInfo> sessions;
  json::Value robot;  // the safety core's state (only with a token)
  json::Value raw;
};
// Parses a GET /rcan/v1/status body. SCHEMA_VALIDATION_FAILED when it is not one.
Result<RobotStatus> parse_status(std::string_view body);

struct Grant {  // GRANTED from POST /rcan/v1/auth/claim
  std::string session_id;
  std::string role;
  std::vector<std::string> capabilities;
  int64_t heartbeat_timeout_ms = 0;
  int64_t expires_in_s = -1;
  json::Value raw;
};

struct Reply {  // any RCAN message the node answered with (ACK, RELEASED, AVAILABLE, …)
  int http_status = 200;
  std::string type;  // "ACK", "PENDING_AUTH", …
  std::string message_id;
  std::string reply_to;
  json::Value payload;
  json::Value raw;
  bool pending() const { return http_status == 202 || type == "PENDING_AUTH"; }
};

struct PendingAuth {
  std::string message_id;
  std::string action_type;
  std::string description;
  std::string principal;
  int64_t auth_timeout_ms = 0;
  int64_t expires_at_ms = 0;
  json::Value raw;
};

struct AuditPage {
  std::vector<json::Value> entries;
  int64_t last_seq = 0;
  // Records in the range the node could not show (they failed their check): their seqs.
  std::vector<int64_t> unreadable;
};

struct Thought {
  std::string id;
  int64_t timestamp_ms = 0;
  std::string provider, model, layer, instruction;
  std::optional<double> confidence;
  std::optional<std::string> reasoning;  // present only for callers with `config` scope
  json::Value action;
  json::Value raw;
};

struct WatermarkVerdict {
  bool valid = false;
  std::string rrn;
  std::string watermark_token;
  json::Value audit_entry;
};

// A command to send: `action` plus parameters, wrapped in a seed-shape COMMAND.
struct Command {
  std::string action;
  json::Object params;
  std::string priority;              // "" = node default; LOW|NORMAL|HIGH|SAFETY
  int64_t ttl_ms = 0;                // 0 = none
  std::optional<double> confidence;  // §16 ai.confidence
  std::string scope;                 // "" = not stated
};
// The message a Command becomes (fresh message_id and timestamp_ms).
json::Value command_message(const Command& c, int64_t now_ms);

// ---------------------------------------------------------------------------------------
// HTTP client

struct ClientOptions {
  std::string url = "http://127.0.0.1:8080";
  std::string token;       // bearer token ("" = anonymous)
  int timeout_ms = 10000;  // connect + answer
  std::string ca_file;     // PEM trust anchors for https/wss ("" = system store)
  bool insecure = false;   // skip certificate verification (testing only)
};

struct RawResponse {
  int status = 0;
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-cased
  std::string body;
  std::string header(std::string_view name) const;
};

class Client {
 public:
  explicit Client(ClientOptions options);
  const ClientOptions& options() const { return opts_; }

  Result<RobotStatus> status();
  Result<Grant> claim(const std::string& role = "");
  Result<Reply> release(const std::string& session_id = "");
  Result<Reply> handoff(const std::string& session_id, const std::string& target_user_id,
                        const std::string& target_role = "", const std::string& reason = "");
  Result<Reply> command(const Command& c);
  // Any message (seed or rcan-py shape) as given.
  Result<Reply> send(const json::Value& message);
  Result<Reply> estop(const std::string& reason = "");
  Result<Reply> resume(const std::string& reason = "");
  Result<Reply> heartbeat();
  // §16 (PROFILE §8): GET /rcan/v1/pending and POST /rcan/v1/authorize.
  Result<std::vector<PendingAuth>> pending();
  Result<Reply> authorize(const std::string& message_id, bool approve,
                          const std::string& reason = "");
  // GET /api/audit?limit= (latest records).
  Result<AuditPage> audit_recent(int limit = 50);
  // GET /api/v1/audit?from=&to=&format=jsonl (OWNER + config): JSONL, verifiable offline.
  Result<std::string> audit_export(std::optional<int64_t> from_ms = {},
                                   std::optional<int64_t> to_ms = {});
  Result<Thought> thought(const std::string& id);
  // Public: no token is sent.
  Result<WatermarkVerdict> watermark_verify(const std::string& token, const std::string& rrn = "");
  // One raw request relative to the endpoint (path starts with '/').
  Result<RawResponse> request(const std::string& method, const std::string& path,
                              const std::string& body = {}, bool with_token = true);

 private:
  Result<json::Value> call_json(const std::string& method, const std::string& path,
                                const std::string& body, bool with_token, int* status = nullptr);
  ClientOptions opts_;
};

// Turns an HTTP answer into an error (non-2xx) using the profile's body when present.
ClientError error_from_response(int status, std::string_view body,
                                std::string_view retry_after = {});

// ---------------------------------------------------------------------------------------
// WebSocket stream (spec Appendix B) with reconnect and backoff

// Reconnect delay before attempt `attempt` (0-based): 1, 2, 4, 8, 16, 30, 30, … s,
// each ±500 ms of jitter, never below 0.
std::chrono::milliseconds backoff_delay(int attempt, std::mt19937_64& rng);

struct StreamOptions {
  ClientOptions client;
  double telemetry_hz = 0;       // > 0: SUBSCRIBE to telemetry after CONNECT_ACK
  int ping_interval_ms = 30000;  // app PING after this long without sending
  int pong_timeout_ms = 5000;    // no PONG in time → reconnect
  int max_attempts = -1;         // connection attempts in a row before giving up; -1 = forever
  std::function<void(const json::Value&)> on_message;  // every frame after CONNECT_ACK
  // Connection state changes: "connecting", "connected", "disconnected: <why>",
  // "retrying in <ms> ms", "refused: <why>" (CONNECT refused: no retry), "stopped".
  std::function<void(const std::string&)> on_state;
};

class Stream {
 public:
  explicit Stream(StreamOptions options);
  ~Stream();
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;

  // Runs until stop(), a refused CONNECT, or max_attempts failures in a row. Returns the
  // reason it ended ("stopped", or the last error).
  ClientError run();
  // Queues a frame for the live connection (or the next one). Thread-safe.
  void send(const json::Value& message);
  // Sends a COMMAND and returns its message_id (answers arrive through on_message with
  // reply_to set to it).
  std::string send_command(const Command& c);
  void stop();
  bool connected() const { return connected_.load(); }
  std::string session_id() const;

 private:
  class Connection;  // one connection's life (stream.cpp)

  StreamOptions opts_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> connected_{false};
  mutable std::mutex mu_;
  std::vector<std::string> outbox_;
  std::string session_id_;
  int wake_fd_[2] = {-1, -1};
};

// ---------------------------------------------------------------------------------------
// Discovery

struct DiscoveredRobot {
  std::string source;  // "mdns" or "probe"
  std::string name;    // mDNS instance name or the host probed
  std::string url;     // where the node answers (scheme://address:port)
  std::string host;    // address used
  uint16_t port = 0;
  std::string interface;                          // mDNS: interface name
  std::map<std::string, std::string> txt;         // mDNS TXT (keys lower-cased)
  std::string ruri, model, version, status_word;  // from TXT or the status answer
  bool reachable = false;                         // GET /rcan/v1/status answered 200
  std::optional<RobotStatus> status;
};

struct DiscoverOptions {
  int timeout_ms = 2000;  // mDNS browse window; per-probe timeout
  bool mdns = true;
  std::vector<std::string> hosts;  // probe these: host, host:port or URLs (default port 8080)
  bool probe_mdns_results = true;  // confirm each mDNS result with GET /rcan/v1/status
  std::string ca_file;
  bool insecure = false;
};

struct DiscoverReport {
  std::vector<DiscoveredRobot> robots;
  std::string mdns_error;  // why mDNS browsing was not possible ("" when it ran)
};

DiscoverReport discover(const DiscoverOptions& options);
// GET /rcan/v1/status on one host (host, host:port or URL).
Result<DiscoveredRobot> probe(const std::string& host, const DiscoverOptions& options);

// One resolved _rcan._tcp service as mDNS reported it.
struct MdnsService {
  std::string name, interface, address, hostname;
  uint16_t port = 0;
  bool local = false;            // published by this host
  std::vector<std::string> txt;  // raw "key=value" items
};
// Browses _rcan._tcp through the Avahi daemon for `timeout_ms`. Error (code
// MDNS_UNAVAILABLE) when no daemon can be reached.
Result<std::vector<MdnsService>> browse_mdns(int timeout_ms);

// TXT items → map (rcan/mdns_txt.h: lower-cased keys, the first of duplicates wins).
using rcan::parse_txt;

}  // namespace rcan::client
