// A small in-process HTTP + WebSocket server (the project's transport) that answers the
// documented contracts of endpoints the client library uses but a test wants to drive
// precisely: §16 pending/authorize (PROFILE §8), the thought log, the public watermark
// verify endpoint, and a stream whose connections the test can drop. Header-only.
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "rcan/errors.h"
#include "rcan/json.h"
#include "transport/http_api.h"
#include "transport/http_server.h"

namespace rcan::test {

class FakeNode final : public transport::HttpHandler, public transport::StreamHandler {
 public:
  static constexpr const char* kGoodToken = "good-token";
  static constexpr const char* kConfigToken = "config-token";
  static constexpr const char* kWatermark = "rcan-wm-v1:0123456789abcdef0123456789abcdef";

  explicit FakeNode(bool tls = false, std::string cert = {}, std::string key = {},
                    uint16_t port = 0) {
    transport::ServerOptions o;
    o.port = port;
    o.tls = tls;
    tls_ = tls;
    o.cert_file = std::move(cert);
    o.key_file = std::move(key);
    server_ = std::make_unique<transport::HttpServer>(o, *this, *this);
    auto p = server_->start();
    if (p.ok()) port_ = *p;
  }
  ~FakeNode() override { server_->stop(500); }
  uint16_t port() const { return port_; }
  std::string url() const {
    return std::string(tls_ ? "https" : "http") + "://127.0.0.1:" + std::to_string(port_);
  }

  // What the fake saw.
  std::mutex mu;
  std::vector<json::Value> authorizations;
  std::vector<std::string> pending_ids{"7f1c2a9e-0000-4000-8000-000000000001"};
  std::atomic<int> stream_connects{0};
  std::atomic<int> drop_streams_after_ack{
      0};                                  // > 0: close that many streams right after CONNECT_ACK
  std::vector<std::string> stream_frames;  // every text frame received after CONNECT

  void handle(transport::HttpRequest req, Respond respond) override {
    auto token = bearer(req);
    auto err = [&](int status, ErrorCode code, const std::string& msg) {
      transport::HttpResponse r;
      r.status = status;
      r.body = json::dump(error_body(Error(code, msg), "", 1));
      respond(std::move(r));
    };
    auto ok = [&](json::Value body, int status = 200) {
      transport::HttpResponse r;
      r.status = status;
      r.body = json::dump(body);
      respond(std::move(r));
    };
    const std::string& p = req.path;
    if (p == "/rcan/v1/status") {
      return ok(json::Object{{"ruri", "rcan://local.rcan/fake/node/00000001"},
                             {"rrn", "RRN-000000000001"},
                             {"name", "fake"},
                             {"rcan_version", "1.0.0"},
                             {"estop_active", false},
                             {"mode", "NORMAL"},
                             {"active_sessions", 0},
                             {"sessions", json::Array{}}});
    }
    if (p == "/rcan/v1/pending" || p == "/rcan/v1/authorize" || p.rfind("/api/thoughts/", 0) == 0) {
      if (token.empty()) return err(401, ErrorCode::kAuthRequired, "a bearer token is required");
      if (token != kGoodToken && token != kConfigToken)
        return err(401, ErrorCode::kAuthInvalid, "token rejected");
    }
    if (p == "/rcan/v1/command" && req.method == "POST") {
      // Every command waits for a human (a HiTL gate on everything): 202 PENDING_AUTH.
      auto v = json::parse(req.body);
      const json::Value* id = v.ok() ? v->get("message_id") : nullptr;
      std::string mid = id && id->is_string() ? id->as_string() : "";
      {
        std::lock_guard<std::mutex> lock(mu);
        pending_ids.push_back(mid);
      }
      return ok(json::Object{{"type", "PENDING_AUTH"},
                             {"message_id", "pa-1"},
                             {"reply_to", mid},
                             {"payload", json::Object{{"message_id", mid},
                                                      {"action_type", "arm_move"},
                                                      {"description", "gated"},
                                                      {"auth_timeout_ms", 30000},
                                                      {"expires_at_ms", int64_t{1795000000000}}}}},
                202);
    }
    if (p == "/rcan/v1/pending" && req.method == "GET") {
      json::Array list;
      std::lock_guard<std::mutex> lock(mu);
      for (const auto& id : pending_ids)
        list.push_back(json::Value(
            json::Object{{"type", "PENDING_AUTH"},
                         {"message_id", "env-" + id},
                         {"payload", json::Object{{"message_id", id},
                                                  {"action_type", "arm_move"},
                                                  {"description", "move the arm near a person"},
                                                  {"principal", "user-7"},
                                                  {"auth_timeout_ms", 30000},
                                                  {"expires_at_ms", int64_t{1795000000000}}}}}));
      return ok(json::Object{{"pending", list}});
    }
    if (p == "/rcan/v1/authorize" && req.method == "POST") {
      auto v = json::parse(req.body);
      if (!v.ok() || !v->is_object())
        return err(400, ErrorCode::kMalformedJson, "body is not JSON");
      const json::Value* t = v->get("type");
      const json::Value* pl = v->get("payload");
      if (!t || !t->is_string() || t->as_string() != "AUTHORIZE" || !pl || !pl->is_object())
        return err(400, ErrorCode::kSchemaValidationFailed, "an AUTHORIZE message is required");
      const json::Value* id = pl->get("message_id");
      const json::Value* d = pl->get("decision");
      if (!d || !d->is_string() || (d->as_string() != "approve" && d->as_string() != "deny"))
        return err(400, ErrorCode::kSchemaValidationFailed, "decision must be approve or deny");
      std::lock_guard<std::mutex> lock(mu);
      bool known = false;
      for (const auto& pid : pending_ids)
        known = known || (id && id->is_string() && id->as_string() == pid);
      if (!known) return err(404, ErrorCode::kNotFound, "nothing pending with that message_id");
      authorizations.push_back(*v);
      return ok(
          json::Object{{"type", "ACK"},
                       {"message_id", "ack-1"},
                       {"reply_to", v->get("message_id") ? *v->get("message_id") : json::Value()},
                       {"payload", json::Object{{"decision", d->as_string()}}}});
    }
    if (p.rfind("/api/thoughts/", 0) == 0) {
      std::string id = p.substr(14);
      if (id != "th_42") return err(404, ErrorCode::kNotFound, "no thought " + id);
      json::Object th{{"id", "th_42"},
                      {"timestamp_ms", int64_t{1795000000000}},
                      {"provider", "anthropic"},
                      {"model", "planner-1"},
                      {"layer", "planner"},
                      {"instruction", "go to the kitchen"},
                      {"action", json::Object{{"type", "move"}, {"linear_x", 0.4}}},
                      {"confidence", 0.87},
                      {"escalated_from", json::Value()}};
      if (token == kConfigToken) th.set("reasoning", "the kitchen is north");
      return ok(json::Value(std::move(th)));
    }
    if (p == "/api/v1/watermark/verify") {
      std::string tok(req.query_value("token"));
      bool well_formed = tok.size() == 43 && tok.rfind("rcan-wm-v1:", 0) == 0 &&
                         tok.find_first_not_of("0123456789abcdef", 11) == std::string::npos;
      transport::HttpResponse r;
      if (!well_formed) {
        r.status = 400;
        r.body = R"({"error":"Invalid watermark token format","code":"HTTP_400"})";
      } else if (tok != kWatermark) {
        r.status = 404;
        r.body = R"({"error":"Watermark token not found in audit log","code":"HTTP_404"})";
      } else {
        r.body = json::dump(json::Value(json::Object{
            {"valid", true},
            {"rrn", "RRN-000000000001"},
            {"watermark_token", tok},
            {"audit_entry", json::Object{{"event", "COMMAND"}, {"watermark_token", tok}}}}));
      }
      return respond(std::move(r));
    }
    err(404, ErrorCode::kNotFound, "no route for " + p);
  }

  struct Receiver final : public transport::StreamReceiver {
    Receiver(FakeNode& n, std::shared_ptr<transport::StreamSink> s) : node(n), sink(std::move(s)) {}
    void on_text(std::string text) override {
      auto v = json::parse(text);
      if (!connected) {
        const json::Value* tok = v.ok() ? v->get("token") : nullptr;
        if (!tok || !tok->is_string() || tok->as_string() != kGoodToken) {
          sink->send_text(
              R"({"type":"ERROR","code":8001,"name":"ConnectionRefused","message":"bad token"})");
          sink->close(4001, "connection refused");
          return;
        }
        connected = true;
        int n = ++node.stream_connects;
        sink->send_text(
            json::dump(json::Value(json::Object{{"type", "CONNECT_ACK"},
                                                {"session_id", "s-" + std::to_string(n)},
                                                {"server_version", "1.0.0"}})));
        if (node.drop_streams_after_ack.load() > 0) {
          --node.drop_streams_after_ack;
          sink->close(1001, "going away");
          return;
        }
        sink->send_text(R"({"type":"EVENT","event":"HELLO","session_id":"s-)" + std::to_string(n) +
                        R"("})");
        return;
      }
      {
        std::lock_guard<std::mutex> lock(node.mu);
        node.stream_frames.push_back(text);
      }
      if (v.ok() && v->get("type") && v->get("type")->is_string() &&
          v->get("type")->as_string() == "COMMAND") {
        const json::Value* id = v->get("message_id");
        sink->send_text(json::dump(json::Value(json::Object{{"type", "ACK"},
                                                            {"reply_to", id ? *id : json::Value()},
                                                            {"payload", json::Object{}}})));
      }
    }
    void on_binary() override { sink->close(1003, "binary"); }
    void on_closed() override {}
    FakeNode& node;
    std::shared_ptr<transport::StreamSink> sink;
    bool connected = false;
  };

  std::unique_ptr<transport::StreamReceiver> open(const transport::HttpRequest& upgrade,
                                                  std::shared_ptr<transport::StreamSink> sink,
                                                  transport::HttpResponse& refusal) override {
    if (upgrade.path != "/rcan/v1/stream") {
      refusal.status = 404;
      refusal.body = json::dump(error_body(Error(ErrorCode::kNotFound, "no stream here"), "", 1));
      return nullptr;
    }
    return std::make_unique<Receiver>(*this, std::move(sink));
  }

  void set_tls(bool t) { tls_ = t; }

 private:
  static std::string bearer(const transport::HttpRequest& req) {
    std::string_view a = req.header("authorization");
    return a.size() > 7 && a.substr(0, 7) == "Bearer " ? std::string(a.substr(7)) : std::string();
  }
  std::unique_ptr<transport::HttpServer> server_;
  uint16_t port_ = 0;
  bool tls_ = false;
};

}  // namespace rcan::test
