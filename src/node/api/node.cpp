// Node: HTTP routes and the WebSocket stream binding over the one pipeline.
#include "node/api/node.h"

#include <pthread.h>

#include <chrono>
#include <cstdlib>

#include "base/clock.h"
#include "node/api/ai_routes.h"
#include "node/api/stage_order.h"
#include "node/api/web_assets.h"
#include "node/discovery/mdns.h"
#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {

// ---------------------------------------------------------------------------------------------
// Streams (spec-digest Appendix B): CONNECT → CONNECT_ACK, PING/PONG, SUBSCRIBE, messages in,
// ACK/ERROR/events/telemetry out, one JSON message per text frame.

struct StreamState {
  // Set by Node::open() before the stream is shared.
  std::shared_ptr<transport::StreamSink> sink;
  std::string upgrade_token;  // from the upgrade request, if any
  std::string stream_id;
  int64_t opened_mono = 0;
  bool reserve = false;  // opened over the connection limit: SAFETY messages only
  // The ESTOP epoch this stream is armed at (Ingress::armed_epoch), set at CONNECT.
  std::shared_ptr<std::atomic<uint64_t>> armed_epoch = std::make_shared<std::atomic<uint64_t>>(0);

  Mutex mu;
  bool connected GUARDED_BY(mu) = false;
  std::optional<Principal> principal GUARDED_BY(mu);
  bool telemetry GUARDED_BY(mu) = false;
  int64_t telemetry_period_ms GUARDED_BY(mu) = 200;
  int64_t next_telemetry_mono GUARDED_BY(mu) = 0;
  bool closed GUARDED_BY(mu) = false;
};

struct NodeStream final : public transport::StreamReceiver {
  NodeStream(Node& n, std::shared_ptr<StreamState> s) : node(n), st(std::move(s)) {}
  void on_text(std::string text) override;
  // The frames on_text answers itself (node.cpp).
  void connect(const json::Value& v);
  void subscribe(bool on, const json::Value& v);
  void pong(const json::Value& v);
  void submit(json::Value message, int64_t received_us);
  void on_binary() override { st->sink->close(1003, "binary frames are not supported"); }
  void on_closed() override {
    {
      MutexLock lock(st->mu);
      st->closed = true;
    }
    node.unregister_stream(st);
  }
  void refuse_connect(const std::string& why) {
    json::Object err{
        {"type", "ERROR"}, {"code", 8001}, {"name", "ConnectionRefused"}, {"message", why}};
    st->sink->send_text(json::dump(json::Value(err)));
    st->sink->close(4001, "connection refused");
  }
  Node& node;
  std::shared_ptr<StreamState> st;
};

void NodeStream::on_text(std::string text) {
  const int64_t received_us = steady_us();
  NodeServices& svc = node.svc_;
  json::ParseOptions po;
  po.max_bytes = svc.settings.codec.max_body_bytes;
  po.max_depth = 32;
  auto v = json::parse(text, po);
  bool connected;
  {
    MutexLock lock(st->mu);
    connected = st->connected;
  }
  if (!v.ok() || !v->is_object()) {
    if (!connected) {
      st->sink->close(1002, "the first frame must be a CONNECT message");
      return;
    }
    Error e = v.ok()
                  ? Error(ErrorCode::kSchemaValidationFailed, "a frame must hold one JSON object")
                  : v.error();
    st->sink->send_text(json::dump(svc.error(e)));
    return;
  }
  const json::Value* type = v->get("type");
  std::string t = type && type->is_string() ? type->as_string() : "";
  if (!connected) {
    if (t != "CONNECT") {
      st->sink->close(1002, "the first frame must be a CONNECT message");
      return;
    }
    connect(*v);
    return;
  }
  std::optional<Principal> who;
  {
    MutexLock lock(st->mu);
    if (st->closed) return;  // closed on revocation: the close is on its way
    who = st->principal;
  }
  if (who && !svc.check_revoked(*who).ok()) {
    node.close_revoked_streams();
    return;
  }
  if (t == "PING") {
    pong(*v);
    return;
  }
  if (t == "SUBSCRIBE" || t == "UNSUBSCRIBE") {
    subscribe(t == "SUBSCRIBE", *v);
    return;
  }
  if (t == "AUTHORIZE") {  // §16.4, answered on this stream (ai_routes.cpp)
    auto state = st;
    ai_stream_message(svc, t, *v, who,
                      [state](std::string s) { state->sink->send_text(std::move(s)); });
    return;
  }
  if (st->reserve && t != "SAFETY") {  // a reserve connection is there for a stop only
    st->sink->send_text(json::dump(svc.error(
        Error(ErrorCode::kRateLimited,
              "the node is at its connection limit: this stream carries only SAFETY messages",
              "type", "reserve_for_stop_only"))));
    st->sink->close(1008, "reserved connection: SAFETY messages only");
    return;
  }
  submit(std::move(v).value(), received_us);
}

// The first frame, CONNECT: its token (else the upgrade's) verified, or the stream refused
// (4001, STREAM_REFUSED recorded unless coalesced); then CONNECT_ACK and STREAM_OPEN.
void NodeStream::connect(const json::Value& v) {
  NodeServices& svc = node.svc_;
  std::string token = st->upgrade_token;
  for (const char* k : {"token", "auth_token"}) {
    const json::Value* tk = v.get(k);
    if (tk && tk->is_string() && !tk->as_string().empty()) token = tk->as_string();
  }
  const std::string source = RefusalLedger::source_of(st->sink->remote_addr());
  auto p = svc.authenticate(token, source);
  if (!p.ok()) {
    if (svc.trail.record_refusal(source, "STREAM_REFUSED", p.error().code, "/ws"))
      svc.trail.record("STREAM_REFUSED", "blocked")
          .reason(std::string(error_name(p.error().code)))
          .detail("transport", "ws")
          .write();
    refuse_connect(p.error().message);
    return;
  }
  {
    MutexLock lock(st->mu);
    st->connected = true;
    st->principal = *p;
  }
  st->armed_epoch->store(svc.act.estop_epoch());
  svc.trail.record("STREAM_OPEN").by(*p).message(st->stream_id).detail("transport", "ws").write();
  json::Object ack{{"type", "CONNECT_ACK"},
                   {"session_id", st->stream_id},
                   {"server_version", svc.settings.rcan_version},
                   {"ruri", svc.settings.ruri},
                   {"role", std::string(role_name(p->role))}};
  st->sink->send_text(json::dump(json::Value(ack)));
}

// SUBSCRIBE / UNSUBSCRIBE to telemetry at `hz` (0.2..50, else the node's rate), ACKed.
void NodeStream::subscribe(bool on, const json::Value& v) {
  NodeServices& svc = node.svc_;
  double hz = svc.settings.telemetry_hz;
  if (const json::Value* h = v.get("hz"); h && h->is_number()) hz = h->to_double();
  if (!(hz >= 0.2 && hz <= 50)) {
    st->sink->send_text(json::dump(
        svc.error(Error(ErrorCode::kSchemaValidationFailed, "hz must be within 0.2..50", "hz"))));
    return;
  }
  {
    MutexLock lock(st->mu);
    st->telemetry = on;
    st->telemetry_period_ms = static_cast<int64_t>(1000.0 / hz);
    st->next_telemetry_mono = 0;
  }
  st->sink->send_text(json::dump(svc.envelope(
      MessageType::kAck, json::Object{{"subscribed", on}, {"topic", "telemetry"}, {"hz", hz}})));
}

void NodeStream::pong(const json::Value& v) {
  NodeServices& svc = node.svc_;
  json::Object pong{{"type", "PONG"}};
  const json::Value* id = v.get("msg_id");
  pong.set("reply_to", id ? *id : json::Value());
  pong.set("timestamp_us", svc.clock.wall_ms() * 1000);
  st->sink->send_text(json::dump(json::Value(pong)));
}

// Everything else is an RCAN message through the pipeline, as this stream's principal.
void NodeStream::submit(json::Value message, int64_t received_us) {
  Ingress in;
  in.body = std::move(message);
  in.transport = "ws";
  in.route = "/rcan/v1/stream";
  in.remote = st->sink->remote_addr();
  in.received_mono_us = received_us;
  in.armed_epoch = st->armed_epoch;
  {
    MutexLock lock(st->mu);
    in.preauthenticated = st->principal;
  }
  auto state = st;
  node.submit(std::move(in),
              [state](Outcome out) { state->sink->send_text(json::dump(out.body)); });
}

// ---------------------------------------------------------------------------------------------

Node::Node(NodeServices& services)
    : svc_(services),
      pipeline_(services, standard_stages(services)),
      routes_(services),
      respond_timer_(&services.metrics.stage("respond")) {
  add_routes();
  event_sub_ = svc_.events.subscribe([this](const Event& ev) {
    std::string text;  // serialised once, for the first stream that may see it
    std::vector<std::shared_ptr<StreamState>> copy;
    {
      MutexLock lock(streams_mu_);
      copy = streams_;
    }
    for (auto& st : copy) {
      bool admitted;
      {
        MutexLock lock(st->mu);
        admitted = st->connected && !st->closed &&
                   ev.audience.admits(st->principal ? &*st->principal : nullptr);
      }
      if (!admitted) continue;
      if (text.empty()) text = json::dump(ev.body);
      st->sink->send_text(text);
    }
  });
  revocation_sub_ = svc_.revocations.subscribe([this](const Revocation&) {
    close_revoked_streams();
    svc_.control.end_revoked(svc_.revocations);
  });
  svc_.metrics.add_gauge("rcan_estop_active", "1 while ESTOP is latched.",
                         [this] { return svc_.act.estop_active() ? 1.0 : 0.0; });
  svc_.metrics.add_gauge("rcan_audit_queue_depth", "Audit records waiting to be durable.",
                         [this] { return static_cast<double>(svc_.trail.inflight.load()); });
  svc_.metrics.add_gauge("rcan_audit_available", "0 when the audit log cannot record.",
                         [this] { return svc_.audit.available() ? 1.0 : 0.0; });
  svc_.metrics.add_counter_fn(
      "rcan_audit_recoveries_total", "Times the audit log came back after a failure.",
      [this] { return static_cast<double>(svc_.audit.stats().recoveries); });
  svc_.metrics.add_counter_fn(
      "rcan_audit_index_fallbacks_total",
      "Audit reads whose index entry did not lead to the record, answered from the segment itself.",
      [this] { return static_cast<double>(svc_.audit.stats().index_fallbacks); });
  // Records per group commit = records / groups; syncs per second = the disk's flush rate.
  svc_.metrics.add_counter_fn(
      "rcan_audit_group_commits_total", "Audit group commits (one write each).",
      [this] { return static_cast<double>(svc_.audit.stats().groups_committed); });
  svc_.metrics.add_counter_fn("rcan_audit_syncs_total", "fdatasync calls of the audit log.",
                              [this] { return static_cast<double>(svc_.audit.stats().syncs); });
  svc_.metrics.add_counter_fn("rcan_audit_failures_total", "Audit appends that failed.",
                              [this] { return static_cast<double>(svc_.trail.failures.load()); });
  svc_.metrics.add_gauge("rcan_streams_open", "Connected WebSocket streams.",
                         [this] { return static_cast<double>(stream_count()); });
  svc_.metrics.add_gauge("rcan_control_sessions", "Live control sessions.", [this] {
    return svc_.control.sessions().controller(svc_.clock.mono_ms()) ? 1.0 : 0.0;
  });
  svc_.metrics.add_gauge("rcan_audit_last_seq", "Last durable audit seq.",
                         [this] { return static_cast<double>(svc_.audit.stats().last_seq); });
}

Node::~Node() {
  shutdown();
  svc_.revocations.unsubscribe(revocation_sub_);
  svc_.events.unsubscribe(event_sub_);
}

void Node::close_revoked_streams() {
  std::vector<std::shared_ptr<StreamState>> copy;
  {
    MutexLock lock(streams_mu_);
    copy = streams_;
  }
  for (auto& st : copy) {
    Status revoked = Status::Ok();
    Principal who;
    {
      MutexLock lock(st->mu);
      if (!st->connected || st->closed || !st->principal) continue;
      revoked = svc_.check_revoked(*st->principal);
      if (revoked.ok()) continue;
      st->closed = true;  // nothing more goes through this stream
      who = *st->principal;
    }
    svc_.trail.record("STREAM_CLOSED", "blocked")
        .by(who)
        .reason("token_revoked")
        .message(st->stream_id)
        .detail("transport", "ws")
        .write();
    st->sink->send_text(json::dump(svc_.error(revoked.error())));
    st->sink->close(1008, "token revoked");
  }
}

void Node::start() {
  if (running_.exchange(true)) return;
  svc_.trail.record("SYSTEM_START")
      .by_system()
      .detail("rcan_version", svc_.settings.rcan_version)
      .detail("estop_active", svc_.act.estop_active())
      .write();
  control_start();
  pump_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "node-pump");
    pump();
  });
}

void Node::shutdown() {
  if (!running_.exchange(false)) return;
  { MutexLock wake(pump_mu_); }
  pump_cv_.notify_all();
  if (pump_.joinable()) pump_.join();
  svc_.trail.refusals.on_change({});
  svc_.control.stop();  // saves the control state
  std::vector<std::shared_ptr<StreamState>> copy;
  {
    MutexLock lock(streams_mu_);
    copy = streams_;
  }
  for (auto& st : copy) st->sink->close(1001, "node shutting down");
  worker_.shutdown();
  relay_worker_.shutdown();
  svc_.trail.flush_refusals(true);  // the counts of refusals not recorded one by one
  // Appended synchronously (blocks until durable): the last word of the run.
  (void)svc_.audit.append(std::move(svc_.trail.record("SYSTEM_STOP").by_system().entry()));
}

size_t Node::stream_count() const {
  MutexLock lock(streams_mu_);
  return streams_.size();
}

void Node::register_stream(const std::shared_ptr<StreamState>& st) {
  {
    MutexLock lock(streams_mu_);
    streams_.push_back(st);
  }
  { MutexLock wake(pump_mu_); }
  pump_cv_.notify_all();  // telemetry and the CONNECT deadline start now, not at the next idle tick
}

void Node::unregister_stream(const std::shared_ptr<StreamState>& st) {
  std::string key;
  {
    MutexLock lock(st->mu);
    if (st->principal) key = st->principal->key();
  }
  MutexLock lock(streams_mu_);
  for (auto it = streams_.begin(); it != streams_.end(); ++it) {
    if (*it == st) {
      streams_.erase(it);
      break;
    }
  }
  if (!key.empty()) {
    closed_streams_of_[key] = svc_.clock.mono_ms();
    wake_pump();  // its grace is timed
  }
}

std::vector<std::string> Node::streamless_claimants() {
  const int64_t now = svc_.clock.mono_ms();
  const int64_t grace = svc_.control.sessions().options().queue_stream_grace_ms;
  std::vector<std::string> due;
  {
    MutexLock lock(streams_mu_);
    for (auto it = closed_streams_of_.begin(); it != closed_streams_of_.end();) {
      if (now - it->second < grace) {
        ++it;
        continue;
      }
      due.push_back(it->first);
      it = closed_streams_of_.erase(it);
    }
    if (due.empty()) return due;
    for (auto& st : streams_) {  // a stream of its own again (another tab, a reconnect)
      MutexLock sl(st->mu);
      if (st->closed || !st->principal) continue;
      std::erase(due, st->principal->key());
    }
  }
  return due;
}

void Node::wake_pump() {
  MutexLock lk(pump_mu_);
  pump_woken_ = true;
  pump_cv_.notify_one();
}

bool Node::control_quiet() {
  {
    MutexLock lock(streams_mu_);
    if (!closed_streams_of_.empty()) return false;
  }
  return svc_.control.quiet() && svc_.trail.refusals.quiet();
}

void Node::pump() {
  // Telemetry at each stream's rate; streams that never CONNECT are closed after 10 s.
  // With streams open it wakes every 10 ms (telemetry rates up to 100 Hz); without, only for
  // the control tick — an idle node costs next to nothing (bench/fleet_bench prints the figure).
  // The control tick runs every 100 ms while something waits for a time (a session, a lease,
  // a queued claim, a transfer, a consent request, a refusal window, a closed stream's grace);
  // when nothing does, the pump sleeps until a change wakes it (wake_pump(), called by the
  // session table, ownership, consent book and refusal ledger on every change), and at the
  // latest after kQuietTickMs. A thousand idle robots in one process cost a few wake-ups a
  // second each (bench/fleet_bench prints them), not ten.
  constexpr int64_t kControlTickMs = 100, kQuietTickMs = 5000;
  int64_t next_control_tick = 0;
  while (running_.load()) {
    bool woken;
    {
      bool streams;
      {
        MutexLock lock(streams_mu_);
        streams = !streams_.empty();
      }
      int64_t wait_ms = next_control_tick - svc_.clock.mono_ms();
      if (streams) wait_ms = std::min<int64_t>(wait_ms, 10);  // telemetry at up to 100 Hz
      MutexLock lk(pump_mu_);
      if (!pump_woken_ && wait_ms > 0)
        pump_cv_.wait_for(pump_mu_, std::chrono::milliseconds(wait_ms));
      woken = pump_woken_;
      pump_woken_ = false;
    }
    if (!running_.load()) break;
    int64_t now = svc_.clock.mono_ms();
    if (woken || now >= next_control_tick) {
      control_tick();  // expiries, promotions, lease ends (control_routes.cpp)
      next_control_tick = now + (control_quiet() ? kQuietTickMs : kControlTickMs);
    }
    std::vector<std::shared_ptr<StreamState>> copy;
    {
      MutexLock lock(streams_mu_);
      copy = streams_;
    }
    std::string telemetry;
    for (auto& st : copy) {
      bool send = false, handshake_timeout = false;
      {
        MutexLock lock(st->mu);
        if (!st->connected && now - st->opened_mono > 10'000) handshake_timeout = true;
        if (st->connected && st->telemetry && now >= st->next_telemetry_mono) {
          send = true;
          st->next_telemetry_mono = now + st->telemetry_period_ms;
        }
      }
      if (handshake_timeout) {
        st->sink->close(1002, "no CONNECT within 10 s");
        continue;
      }
      if (send) {
        if (telemetry.empty()) {
          json::Object t{{"type", "STREAM"},
                         {"topic", "telemetry"},
                         {"timestamp_ms", svc_.clock.wall_ms()},
                         {"estop_active", svc_.act.estop_active()},
                         {"payload", svc_.act.telemetry()}};
          telemetry = json::dump(json::Value(t));
        }
        st->sink->send_text(telemetry);
      }
    }
  }
}

void Node::on_safety_event(const std::string& type, const std::string& session_id,
                           int64_t elapsed_ms, const std::string& detail) {
  AuditRecord r = svc_.trail.record(type);
  r.by_system().reason(type);
  if (!session_id.empty()) r.detail("session_id", session_id);
  r.detail("elapsed_ms", elapsed_ms);
  if (!detail.empty()) r.detail("detail", detail);
  r.write();
  svc_.events.publish(json::Value(json::Object{{"type", "EVENT"},
                                               {"event", type},
                                               {"session_id", session_id},
                                               {"elapsed_ms", elapsed_ms},
                                               {"timestamp_ms", svc_.clock.wall_ms()}}));
}

std::unique_ptr<transport::StreamReceiver> Node::open(const transport::HttpRequest& upgrade,
                                                      std::shared_ptr<transport::StreamSink> sink,
                                                      transport::HttpResponse& refusal) {
  if (upgrade.path != "/rcan/v1/stream" && upgrade.path != "/ws/telemetry") {
    refusal.status = 404;
    refusal.body =
        json::dump(svc_.error(Error(ErrorCode::kNotFound, "no stream at " + upgrade.path)));
    return nullptr;
  }
  auto st = std::make_shared<StreamState>();
  st->sink = std::move(sink);
  st->stream_id = new_uuid_v4();
  st->opened_mono = svc_.clock.mono_ms();
  st->reserve = upgrade.reserve;
  if (std::string_view bearer = upgrade.bearer(); !bearer.empty())
    st->upgrade_token = std::string(bearer);
  else if (upgrade.has_query("token"))
    st->upgrade_token = std::string(upgrade.query_value("token"));
  if (upgrade.path == "/ws/telemetry") {
    // v1.1 telemetry socket: the token is in the query; telemetry starts at once.
    auto p = svc_.authenticate(st->upgrade_token, RefusalLedger::source_of(upgrade.remote_addr));
    if (!p.ok()) {
      refusal.status = http_status(p.error().code);
      refusal.body = json::dump(svc_.error(p.error()));
      return nullptr;
    }
    MutexLock lock(st->mu);
    st->connected = true;
    st->principal = *p;
    st->telemetry = true;
    st->telemetry_period_ms = 1000 / std::max(1, svc_.settings.telemetry_hz);
  }
  register_stream(st);
  return std::make_unique<NodeStream>(*this, st);
}

// ---------------------------------------------------------------------------------------------
// HTTP

void Node::answer_json(Respond& respond, const std::string& route, int status, json::Value body,
                       std::vector<std::pair<std::string, std::string>> headers) {
  node::answer_json(svc_, respond, route, status, body, std::move(headers));
}

void Node::answer_error(Respond& respond, const std::string& route, const Error& err) {
  node::answer_error(svc_, respond, route, err);
}

Result<Principal> Node::bearer_principal(const transport::HttpRequest& req) const {
  return svc_.authenticate_header(req.header("authorization"),
                                  RefusalLedger::source_of(req.remote_addr));
}

void Node::handle(transport::HttpRequest req, Respond respond) {
  // The transport keeps a connection's long keep-alive only after an answer to a request that
  // presented a valid credential (docs/TRANSPORT.md): a pipeline message whose token verified,
  // or a bearer token the route verified — found in the verified-token cache when the answer
  // goes out. Nothing is verified here: a bad token costs one verification, not two, and is
  // charged to its address once (NodeServices::authenticate).
  if (std::string_view bearer = req.bearer(); !bearer.empty()) {
    respond = [this, token = std::string(bearer),
               inner = std::move(respond)](transport::HttpResponse r) {
      if (!r.authenticated && svc_.auth.is_cached(token, svc_.clock.wall_ms() / 1000))
        r.authenticated = svc_.authenticate(token).ok();  // cached: no signature check
      inner(std::move(r));
    };
  }
  routes_.dispatch(req, respond);
}

bool Node::serve_on_reserve(const transport::HttpRequest& req) {
  if (req.method == "POST" && req.path == "/api/stop") return true;
  return req.method == "GET" && req.path == "/rcan/v1/stream";
}

void Node::run_pipeline(transport::HttpRequest& req, Respond& respond, const std::string& route,
                        json::Value body) {
  Ingress in;
  // The reference client wraps the message: {"session_id": …, "message": {…}}.
  if (body.is_object() && !body.get("type") && !body.get("cmd") && !body.get("message_type")) {
    if (const json::Value* inner = body.get("message"); inner && inner->is_object()) {
      json::Value m = *inner;
      body = std::move(m);
    }
  }
  in.body = std::move(body);
  in.bearer = std::string(req.bearer());
  in.transport = "http";
  in.route = route;
  in.remote = req.remote_addr;
  in.received_mono_us = req.received_mono_us;
  std::string r = route;
  pipeline_.submit(std::move(in), [this, respond, r](Outcome out) mutable {
    svc_.metrics.count_request(r, out.status);
    transport::HttpResponse resp;
    resp.status = out.status;
    resp.body = json::dump(out.body);
    resp.headers = std::move(out.headers);
    resp.answered_mono_us = steady_us();
    resp.authenticated = out.authenticated;
    respond(std::move(resp));
  });
}

void Node::answer_waited(int64_t us) { respond_timer_->observe_us(static_cast<double>(us)); }

bool Node::audit_reader(const Principal& p, const std::string& route, std::string_view scope,
                        Respond& respond) {
  return owner_reader(p, route, scope, "AUDIT_READ", "the audit log names every principal",
                      respond);
}

bool Node::owner_reader(const Principal& p, const std::string& route, std::string_view scope,
                        const char* event, std::string_view why, Respond& respond) {
  if (role_level(p.role) >= role_level(Role::kOwner) && (scope.empty() || p.has_scope(scope)))
    return true;
  Error err(ErrorCode::kInsufficientPrivileges,
            std::string(why) + ": reading it needs OWNER" +
                (scope.empty() ? std::string() : " and scope " + std::string(scope)),
            "role");
  svc_.trail.record(event, "blocked")
      .by(p)
      .reason(std::string(error_name(err.code)))
      .detail("route", route)
      .write();
  answer_error(respond, route, err);
  return false;
}

void Node::record_audit_read(const Principal& p, const std::string& route, json::Object query,
                             Respond& respond, std::function<void()> read) {
  record_read("AUDIT_READ", p, route, std::move(query), respond, std::move(read));
}

void Node::record_read(const char* event, const Principal& p, const std::string& route,
                       json::Object query, Respond& respond, std::function<void()> read) {
  svc_.trail.record(event)
      .by(p)
      .detail("route", route)
      .detail("query", std::move(query))
      .write(
          [this, respond, route, read = std::move(read)](rcan::Result<audit::Receipt> r) mutable {
            if (r.ok()) return read();
            answer_error(respond, route,
                         Error(ErrorCode::kAuditUnavailable,
                               "this read is recorded, and the audit log cannot record now"));
          });
}

void Node::audit_listing(transport::HttpRequest& req, Respond& respond, const std::string& route) {
  auto pr = bearer_principal(req);
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (!audit_reader(*pr, route, "", respond)) return;
  auto q = parse_audit_query(
      [&req](std::string_view name) -> std::optional<std::string_view> {
        if (!req.has_query(name)) return std::nullopt;
        return req.query_value(name);
      },
      svc_.settings.audit_listing);
  if (!q.ok()) return answer_error(respond, route, q.error());
  json::Object recorded = q->to_json();
  auto read = [this, respond, route, q = std::move(q).value()]() mutable {
    bool posted =
        worker_.post([this, respond, route, q]() mutable { list_audit(respond, route, q); });
    if (!posted) answer_error(respond, route, Error(ErrorCode::kSafeStop, "busy; try again"));
  };
  record_audit_read(*pr, route, std::move(recorded), respond, std::move(read));
}

void Node::list_audit(Respond& respond, const std::string& route, const AuditQuery& q) {
  const audit::AuditStats st = svc_.audit.stats();
  AuditPage page = run_audit_query(svc_.audit, q);
  // Records in the range that cannot be shown (changed on disk, unreadable): named, never
  // left out silently.
  if (!page.unreadable.empty())
    log(LogLevel::kWarn, "audit.listing_unreadable",
        {{"count", static_cast<int64_t>(page.unreadable.size())},
         {"first_seq", page.unreadable.front()},
         {"error", page.first_error}});
  json::Object body{{"count", static_cast<int64_t>(page.entries.size())},
                    {"first_seq", static_cast<int64_t>(st.first_seq)},
                    {"last_seq", static_cast<int64_t>(st.last_seq)},
                    {"scanned", static_cast<int64_t>(page.scanned)},
                    {"complete", page.complete},
                    {"unreadable", std::move(page.unreadable)}};
  body.set("next_before", page.next_before > 0 ? json::Value(static_cast<int64_t>(page.next_before))
                                               : json::Value(nullptr));
  body.set("entries", std::move(page.entries));
  answer_json(respond, route, 200, std::move(body));
}

void Node::audit_export(transport::HttpRequest& req, Respond& respond, const std::string& route) {
  auto pr = bearer_principal(req);
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (!audit_reader(*pr, route, "config", respond)) return;
  auto parse_time = [&](std::string_view name, int64_t def, int64_t& out) -> bool {
    if (!req.has_query(name)) {
      out = def;
      return true;
    }
    std::string s(req.query_value(name));
    char* end = nullptr;
    long long v = std::strtoll(s.c_str(), &end, 10);
    if (s.empty() || !end || *end || v < 0) return false;
    out = v < 100'000'000'000LL ? v * 1000 : v;  // seconds or milliseconds
    return true;
  };
  int64_t from = 0, to = 0;
  if (!parse_time("from", 0, from) || !parse_time("to", INT64_MAX / 2, to))
    return answer_error(respond, route,
                        Error(ErrorCode::kSchemaValidationFailed,
                              "from/to must be Unix seconds or milliseconds", "from"));
  std::string format = req.has_query("format") ? std::string(req.query_value("format")) : "jsonl";
  if (format != "jsonl")
    return answer_error(
        respond, route,
        Error(ErrorCode::kSchemaValidationFailed, "format must be jsonl", "format"));
  auto read = [this, respond, route, from, to]() mutable {
    bool posted = worker_.post([this, respond, route, from, to]() mutable {
      auto text = svc_.audit.export_jsonl(from, to);
      if (!text.ok()) return answer_error(respond, route, text.error());
      svc_.metrics.count_request(route, 200);
      transport::HttpResponse r;
      r.content_type = "application/x-ndjson";
      r.body = std::move(text).value();
      respond(std::move(r));
    });
    if (!posted) answer_error(respond, route, Error(ErrorCode::kSafeStop, "busy; try again"));
  };
  record_audit_read(*pr, route,
                    json::Object{{"from", from}, {"to", to}, {"format", std::move(format)}},
                    respond, std::move(read));
}

void Node::node_log(transport::HttpRequest& req, Respond& respond, const std::string& route) {
  auto pr = bearer_principal(req);
  if (!pr.ok()) return answer_error(respond, route, pr.error());
  if (!owner_reader(*pr, route, "config", "LOG_READ",
                    "the node's log names addresses, files and principals", respond))
    return;
  auto limit =
      parse_limit(req.has_query("limit") ? std::optional(req.query_value("limit")) : std::nullopt,
                  100, kLogRingCapacity);
  if (!limit.ok()) return answer_error(respond, route, limit.error());
  const size_t n = *limit;
  auto read = [this, respond, route, n]() mutable {
    RecentLog recent = recent_log_lines(n);
    // The lines are JSON texts the node wrote itself: spliced into the answer as they are.
    std::string body = "{\"count\":" + std::to_string(recent.lines.size()) +
                       ",\"limit\":" + std::to_string(n) +
                       ",\"capacity\":" + std::to_string(kLogRingCapacity) +
                       ",\"written\":" + std::to_string(recent.written) + ",\"lines\":[";
    for (size_t i = 0; i < recent.lines.size(); ++i) body += (i ? "," : "") + recent.lines[i];
    body += "]}";
    svc_.metrics.count_request(route, 200);
    transport::HttpResponse r;
    r.body = std::move(body);
    respond(std::move(r));
  };
  record_read("LOG_READ", *pr, route, json::Object{{"limit", static_cast<int64_t>(n)}}, respond,
              std::move(read));
}

}  // namespace rcan::node
