// gRPC transport on the callback API (grpc_server.h, docs/TRANSPORT.md §gRPC).
#include "node/bindings/grpc_server.h"

#include <grpc/support/log.h>
#include <grpcpp/grpcpp.h>

#include <atomic>
#include <deque>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "node/api/node.h"
#include "rcan.grpc.pb.h"
#include "rcan/errors.h"
#include "runtime/log.h"
#include "transport/grpc_convert.h"
#include "transport/http_api.h"

namespace rcan::node {

namespace {

using v1::RCANMessage;

constexpr const char* kSendRoute = "/rcan.v1.Rcan/Send";
constexpr const char* kStreamRoute = "/rcan.v1.Rcan/Stream";

std::string bearer_of(const grpc::CallbackServerContext* ctx) {
  const auto& md = ctx->client_metadata();
  auto it = md.find("authorization");
  if (it == md.end()) return {};
  return std::string(
      transport::bearer_token(std::string_view(it->second.data(), it->second.size())));
}

std::string error_code_of(const json::Value& body) {
  const json::Value* p = body.get("payload");
  const json::Value* c = p ? p->get("error_code") : nullptr;
  return c && c->is_string() ? c->as_string() : std::string();
}

std::string error_text_of(const json::Value& body) {
  const json::Value* p = body.get("payload");
  const json::Value* e = p ? p->get("error") : nullptr;
  return e && e->is_string() ? e->as_string().substr(0, 512) : std::string("error");
}

// The non-OK status for an error answer: code per the table, message = the error text,
// details = the error body as a serialized RCANMessage; trailing metadata names the code.
grpc::Status error_status(grpc::CallbackServerContext* ctx, const Outcome& out) {
  std::string code = error_code_of(out.body);
  ctx->AddTrailingMetadata("rcan-error-code", code.empty() ? "UNKNOWN" : code);
  ctx->AddTrailingMetadata("rcan-http-status", std::to_string(out.status));
  for (const auto& [k, v] : out.headers)
    if (k == "Retry-After" || k == "retry-after") ctx->AddTrailingMetadata("retry-after", v);
  RCANMessage err;
  transport::json_to_grpc(out.body, err);
  return grpc::Status(static_cast<grpc::StatusCode>(transport::grpc_status_code(code, out.status)),
                      error_text_of(out.body), err.SerializeAsString());
}

// An error refused before the message was decoded has reply_to null; the transport knows
// which message it answers, so a stream client can correlate every answer.
void fill_reply_to(Outcome& out, const std::string& id) {
  if (id.empty() || !out.body.is_object()) return;
  json::Value* r = out.body.get("reply_to");
  if (!r || r->is_null()) out.body.as_object().set("reply_to", id);
}

// gRPC's own diagnostics (e.g. a TLS handshake refused to a plaintext client) go through the
// node's JSON log like everything else, never as raw lines on stderr.
void grpc_library_log(gpr_log_func_args* args) {
  LogLevel lvl = args->severity == GPR_LOG_SEVERITY_ERROR  ? LogLevel::kWarn
                 : args->severity == GPR_LOG_SEVERITY_INFO ? LogLevel::kInfo
                                                           : LogLevel::kDebug;
  std::string file = args->file ? args->file : "";
  if (auto slash = file.rfind('/'); slash != std::string::npos) file = file.substr(slash + 1);
  log(lvl, "grpc.library",
      json::Object{{"message", std::string(args->message ? args->message : "").substr(0, 512)},
                   {"where", file + ":" + std::to_string(args->line)}});
}

Result<std::string> read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error(ErrorCode::kInternal, "cannot read " + path);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

class StreamReactor;

// What outlives a stream reactor: callbacks (pipeline answers, events) reach the reactor
// only through this link, and only while `r` is set (cleared in OnDone).
struct StreamLink {
  Mutex mu;
  StreamReactor* r GUARDED_BY(mu) = nullptr;
};

struct GrpcServer::Impl {
  Impl(GrpcOptions o, Node& n) : opt(std::move(o)), node(n), svc(n.services()) {}
  GrpcOptions opt;
  Node& node;
  NodeServices& svc;
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<v1::Rcan::CallbackService> service;
  std::atomic<bool> stopping{false};
  std::atomic<uint64_t> calls_total{0}, streams_open{0}, streams_total{0}, streams_refused{0};
  Mutex links_mu;
  std::set<std::shared_ptr<StreamLink>> links GUARDED_BY(links_mu);
  Mutex stop_mu;
  bool stopped GUARDED_BY(stop_mu) = false;
};

class StreamReactor final : public grpc::ServerBidiReactor<RCANMessage, RCANMessage> {
 public:
  StreamReactor(GrpcServer::Impl& impl, grpc::CallbackServerContext* ctx)
      : impl_(impl), ctx_(ctx), link_(std::make_shared<StreamLink>()) {
    link_->r = this;
    stream_id_ = new_uuid_v4();
    bearer_ = bearer_of(ctx);
    NodeServices& svc = impl_.svc;
    if (!bearer_.empty()) {
      auto p = svc.authenticate(bearer_, RefusalLedger::source_of(ctx->peer()));
      if (!p.ok()) {
        svc.trail.record("STREAM_REFUSED", "blocked")
            .reason(std::string(error_name(p.error().code)))
            .detail("transport", "grpc")
            .write();
        Outcome out{http_status(p.error().code), svc.error(p.error()), {}};
        register_link();
        final_ = error_status(ctx_, out);
        try_finish();
        return;
      }
      principal_ = *p;
      armed_epoch_->store(svc.act.estop_epoch());
      svc.trail.record("STREAM_OPEN")
          .by(*p)
          .message(stream_id_)
          .detail("transport", "grpc")
          .write();
      std::weak_ptr<StreamLink> weak = link_;
      event_sub_ = svc.events.subscribe([weak, who = *p](const Event& ev) {
        if (!ev.audience.admits(&who)) return;  // another principal's event
        auto l = weak.lock();
        if (!l) return;
        MutexLock lock(l->mu);
        if (!l->r) return;
        l->r->link_->mu.assert_held();  // the same mutex: a reactor's link_ is `l` for its life
        RCANMessage m;
        transport::json_to_grpc(ev.body, m);
        l->r->enqueue(std::move(m));
      });
      // Revoked since the stream opened: ended at once, UNAUTHENTICATED.
      revocation_sub_ = svc.revocations.subscribe([weak, who = *p, &svc](const Revocation&) {
        if (svc.check_revoked(who).ok()) return;
        auto l = weak.lock();
        if (!l) return;
        MutexLock lock(l->mu);
        if (!l->r) return;
        l->r->end(grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "token revoked"));
      });
    }
    register_link();
    StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      {
        MutexLock lock(mu_);
        reads_done_ = true;
      }
      try_finish();
      return;
    }
    handle(in_);
    {
      MutexLock lock(mu_);
      if (final_) {
        reads_done_ = true;
      }
    }
    bool more;
    {
      MutexLock lock(mu_);
      more = !reads_done_;
    }
    if (more)
      StartRead(&in_);
    else
      try_finish();
  }

  void OnWriteDone(bool ok) override {
    const RCANMessage* next = nullptr;
    {
      MutexLock lock(mu_);
      if (!q_.empty()) q_.pop_front();
      if (!ok) {
        q_.clear();  // the client is gone; the pending read ends too
        broken_ = true;
      }
      if (!q_.empty() && !broken_)
        next = &q_.front();
      else
        writing_ = false;
    }
    if (next)
      StartWrite(next);
    else
      try_finish();
  }

  void OnCancel() override {}

  void OnDone() override {
    {
      MutexLock lock(link_->mu);
      link_->r = nullptr;
    }
    if (event_sub_) impl_.svc.events.unsubscribe(event_sub_);
    if (revocation_sub_) impl_.svc.revocations.unsubscribe(revocation_sub_);
    {
      MutexLock lock(impl_.links_mu);
      impl_.links.erase(link_);
    }
    impl_.streams_open.fetch_sub(1);
    if (principal_) {
      impl_.svc.trail.record("STREAM_CLOSED")
          .by(*principal_)
          .message(stream_id_)
          .detail("transport", "grpc")
          .write();
    }
    delete this;
  }

  // Queues one message for the client.
  void enqueue(RCANMessage m) REQUIRES(link_->mu) EXCLUDES(mu_) {
    const RCANMessage* start = nullptr;
    {
      MutexLock lock(mu_);
      if (final_ || broken_) return;
      if (q_.size() >= impl_.opt.stream_send_queue) {
        q_.clear();
        final_ = grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, "send queue limit exceeded");
        log(LogLevel::kWarn, "grpc.send_queue_full", json::Object{{"stream", stream_id_}});
      } else {
        q_.push_back(std::move(m));
        if (!writing_) {
          writing_ = true;
          start = &q_.front();
        }
      }
    }
    if (start)
      StartWrite(start);
    else
      try_finish();
  }

  // Ends the stream with `s` once the write in progress is done (shutdown).
  void end(grpc::Status s) EXCLUDES(mu_) {
    {
      MutexLock lock(mu_);
      if (final_) return;
      final_ = std::move(s);
      q_.clear();
    }
    try_finish();
  }

  void answer(const Outcome& out) REQUIRES(link_->mu) EXCLUDES(mu_) {
    impl_.svc.metrics.count_request(kStreamRoute, out.status);
    RCANMessage m;
    transport::json_to_grpc(out.body, m);
    enqueue(std::move(m));
    {
      MutexLock lock(mu_);
      --pending_;
    }
    try_finish();
  }

 private:
  void register_link() EXCLUDES(impl_.links_mu) {
    MutexLock lock(impl_.links_mu);
    impl_.links.insert(link_);
  }

  void handle(const RCANMessage& msg) {
    NodeServices& svc = impl_.svc;
    auto body = transport::grpc_to_json(msg, impl_.opt.max_message_bytes);
    if (!body.ok()) {
      impl_.svc.metrics.count_request(kStreamRoute, http_status(body.error().code));
      RCANMessage m;
      transport::json_to_grpc(svc.error(body.error(), msg.message_id().substr(0, 64)), m);
      MutexLock lock(link_->mu);
      enqueue(std::move(m));
      return;
    }
    Ingress in;
    in.body = std::move(body).value();
    in.bearer = bearer_;
    in.transport = "grpc";
    in.route = kStreamRoute;
    in.remote = ctx_->peer();
    in.preauthenticated = principal_;
    in.armed_epoch = armed_epoch_;
    {
      MutexLock lock(mu_);
      ++pending_;
    }
    std::shared_ptr<StreamLink> link = link_;
    std::string id = msg.message_id().substr(0, 64);
    impl_.node.submit(std::move(in), [link, id](Outcome out) {
      fill_reply_to(out, id);
      MutexLock lock(link->mu);
      if (!link->r) return;
      link->r->link_->mu.assert_held();  // the same mutex: a reactor's link_ is `link`
      link->r->answer(out);
    });
  }

  // Finishes once: at the end of the client's messages with every answer written, or at
  // once (after the write in progress) when the stream was ended.
  void try_finish() EXCLUDES(mu_) {
    grpc::Status s;
    {
      MutexLock lock(mu_);
      if (finished_ || writing_) return;
      bool natural = reads_done_ && pending_ == 0 && q_.empty();
      if (!final_ && !natural && !broken_) return;
      if (broken_ && !(reads_done_ && pending_ == 0) && !final_) return;
      finished_ = true;
      s = final_ ? *final_ : grpc::Status::OK;
    }
    Finish(s);
  }

  GrpcServer::Impl& impl_;
  grpc::CallbackServerContext* ctx_;
  std::shared_ptr<StreamLink> link_;
  std::string stream_id_;
  std::string bearer_;
  std::optional<Principal> principal_;
  // The ESTOP epoch this stream is armed at (Ingress::armed_epoch), set when it authenticates.
  std::shared_ptr<std::atomic<uint64_t>> armed_epoch_ = std::make_shared<std::atomic<uint64_t>>(0);
  uint64_t event_sub_ = 0;
  uint64_t revocation_sub_ = 0;
  RCANMessage in_;
  Mutex mu_;
  std::deque<RCANMessage> q_ GUARDED_BY(mu_);
  bool writing_ GUARDED_BY(mu_) = false;
  bool reads_done_ GUARDED_BY(mu_) = false;
  bool broken_ GUARDED_BY(mu_) = false;
  bool finished_ GUARDED_BY(mu_) = false;
  int pending_ GUARDED_BY(mu_) = 0;
  std::optional<grpc::Status> final_ GUARDED_BY(mu_);
};

namespace {

class RefuseReactor final : public grpc::ServerBidiReactor<RCANMessage, RCANMessage> {
 public:
  explicit RefuseReactor(grpc::Status s) { Finish(std::move(s)); }
  void OnDone() override { delete this; }
};

class Service final : public v1::Rcan::CallbackService {
 public:
  explicit Service(GrpcServer::Impl& impl) : impl_(impl) {}

  grpc::ServerUnaryReactor* Send(grpc::CallbackServerContext* ctx, const RCANMessage* req,
                                 RCANMessage* resp) override {
    impl_.calls_total.fetch_add(1);
    auto* reactor = ctx->DefaultReactor();
    NodeServices& svc = impl_.svc;
    auto body = transport::grpc_to_json(*req, impl_.opt.max_message_bytes);
    if (!body.ok()) {
      finish(ctx, reactor, resp,
             Outcome{http_status(body.error().code),
                     svc.error(body.error(), req->message_id().substr(0, 64)),
                     {}});
      return reactor;
    }
    Ingress in;
    in.body = std::move(body).value();
    in.bearer = bearer_of(ctx);
    in.transport = "grpc";
    in.route = kSendRoute;
    in.remote = ctx->peer();
    GrpcServer::Impl* impl = &impl_;
    std::string id = req->message_id().substr(0, 64);
    impl_.node.submit(std::move(in), [impl, ctx, reactor, resp, id](Outcome out) {
      fill_reply_to(out, id);
      Service::finish_with(*impl, ctx, reactor, resp, std::move(out));
    });
    return reactor;
  }

  grpc::ServerBidiReactor<RCANMessage, RCANMessage>* Stream(
      grpc::CallbackServerContext* ctx) override {
    impl_.calls_total.fetch_add(1);
    if (impl_.stopping.load())
      return new RefuseReactor(grpc::Status(grpc::StatusCode::UNAVAILABLE, "node shutting down"));
    if (impl_.streams_open.fetch_add(1) >= static_cast<uint64_t>(impl_.opt.max_streams)) {
      impl_.streams_open.fetch_sub(1);
      impl_.streams_refused.fetch_add(1);
      impl_.svc.metrics.count_request(kStreamRoute, 503);
      return new RefuseReactor(
          grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, "too many streams"));
    }
    impl_.streams_total.fetch_add(1);
    return new StreamReactor(impl_, ctx);
  }

  static void finish_with(GrpcServer::Impl& impl, grpc::CallbackServerContext* ctx,
                          grpc::ServerUnaryReactor* reactor, RCANMessage* resp, Outcome out) {
    impl.svc.metrics.count_request(kSendRoute, out.status);
    if (out.status >= 400) {
      reactor->Finish(error_status(ctx, out));
      return;
    }
    transport::json_to_grpc(out.body, *resp);
    reactor->Finish(grpc::Status::OK);
  }

 private:
  void finish(grpc::CallbackServerContext* ctx, grpc::ServerUnaryReactor* reactor,
              RCANMessage* resp, Outcome out) {
    finish_with(impl_, ctx, reactor, resp, std::move(out));
  }
  GrpcServer::Impl& impl_;
};

}  // namespace

GrpcServer::GrpcServer(GrpcOptions opt, Node& node)
    : impl_(std::make_unique<Impl>(std::move(opt), node)) {}

GrpcServer::~GrpcServer() { stop(0); }

Result<uint16_t> GrpcServer::start() {
  Impl& im = *impl_;
  gpr_set_log_function(&grpc_library_log);
  std::shared_ptr<grpc::ServerCredentials> creds;
  if (im.opt.tls) {
    auto cert = read_file(im.opt.cert_file);
    if (!cert.ok()) return cert.error();
    auto key = read_file(im.opt.key_file);
    if (!key.ok()) return key.error();
    grpc::SslServerCredentialsOptions so(
        im.opt.client_ca_file.empty() ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                                      : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
    if (!im.opt.client_ca_file.empty()) {
      auto ca = read_file(im.opt.client_ca_file);
      if (!ca.ok()) return ca.error();
      so.pem_root_certs = *ca;
    }
    so.pem_key_cert_pairs.push_back({*key, *cert});
    creds = grpc::SslServerCredentials(so);
  } else {
    creds = grpc::InsecureServerCredentials();
  }
  std::string host = im.opt.bind_address.find(':') != std::string::npos
                         ? "[" + im.opt.bind_address + "]"
                         : im.opt.bind_address;
  std::string addr = host + ":" + std::to_string(im.opt.port);
  im.service = std::make_unique<Service>(im);
  grpc::ServerBuilder b;
  int selected = 0;
  b.AddListeningPort(addr, creds, &selected);
  b.RegisterService(im.service.get());
  b.SetMaxReceiveMessageSize(static_cast<int>(im.opt.max_message_bytes));
  b.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  im.server = b.BuildAndStart();
  if (!im.server || selected == 0) {
    im.server.reset();
    return Error(ErrorCode::kInternal, "cannot listen on " + addr);
  }
  log(LogLevel::kInfo, "grpc.listening",
      json::Object{{"address", im.opt.bind_address}, {"port", selected}, {"tls", im.opt.tls}});
  return static_cast<uint16_t>(selected);
}

void GrpcServer::stop(int drain_ms) {
  Impl& im = *impl_;
  MutexLock lock(im.stop_mu);
  if (im.stopped || !im.server) {
    im.stopped = true;
    return;
  }
  im.stopped = true;
  im.stopping.store(true);
  std::vector<std::shared_ptr<StreamLink>> links;
  {
    MutexLock l(im.links_mu);
    for (const auto& each : im.links) links.push_back(each);
  }
  for (auto& link : links) {
    MutexLock l(link->mu);
    if (link->r) link->r->end(grpc::Status(grpc::StatusCode::UNAVAILABLE, "node shutting down"));
  }
  im.server->Shutdown(wall_now() + std::chrono::milliseconds(std::max(0, drain_ms)));
  im.server->Wait();
  log(LogLevel::kInfo, "grpc.stopped", json::Object{});
}

GrpcStats GrpcServer::stats() const {
  const Impl& im = *impl_;
  return GrpcStats{im.calls_total.load(), im.streams_open.load(), im.streams_total.load(),
                   im.streams_refused.load()};
}

}  // namespace rcan::node
