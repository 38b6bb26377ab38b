// Node — the robot node's front door: HTTP routes and the WebSocket stream binding, all
// feeding the one Pipeline (docs/NODE.md). It implements the transport interface
// (http_api.h) and owns the pipeline, the stream registry and the telemetry pump.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "base/thread_annotations.h"
#include "base/worker.h"
#include "node/api/audit_query.h"
#include "node/api/route_table.h"
#include "node/pipeline/pipeline.h"
#include "node/services/node_services.h"
#include "transport/http_api.h"

namespace rcan::node {

struct StreamState;
class RobotDirectory;

class Node final : public transport::HttpHandler, public transport::StreamHandler {
 public:
  // `services` must outlive the node.
  explicit Node(NodeServices& services);
  ~Node() override;
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;

  // Starts the telemetry pump and writes the SYSTEM_START audit record.
  void start();
  // Stops the pump, closes streams (1001) and writes SYSTEM_STOP (waits for it).
  void shutdown() EXCLUDES(streams_mu_, pump_mu_);

  void handle(transport::HttpRequest req, Respond respond) override;
  void answer_waited(int64_t us) override;
  // Over the connection limit only a stop gets through: POST /api/stop and the stream upgrade
  // (a reserve stream then carries only SAFETY messages).
  bool serve_on_reserve(const transport::HttpRequest& req) override;
  std::unique_ptr<transport::StreamReceiver> open(const transport::HttpRequest& upgrade,
                                                  std::shared_ptr<transport::StreamSink> sink,
                                                  transport::HttpResponse& refusal) override;

  // Runs a message through the pipeline as if it came from `transport` (used by streams and
  // tests).
  void submit(Ingress in, std::function<void(Outcome)> done) {
    pipeline_.submit(std::move(in), std::move(done));
  }

  // The robots the dashboard's Robots view lists and can stop (dashboard.robots); set before
  // the transports start, and it must outlive the node. None: the view lists this node alone.
  void set_robot_directory(RobotDirectory* robots);

  NodeServices& services() { return svc_; }
  Pipeline& pipeline() { return pipeline_; }
  size_t stream_count() const EXCLUDES(streams_mu_);

  // Called by the safety core's event callback (deadman, watchdog): audit + notify streams.
  void on_safety_event(const std::string& type, const std::string& session_id, int64_t elapsed_ms,
                       const std::string& detail);

 private:
  friend struct NodeStream;
  void answer_json(Respond& respond, const std::string& route, int status, json::Value body,
                   std::vector<std::pair<std::string, std::string>> headers = {});
  void answer_error(Respond& respond, const std::string& route, const Error& err);
  void run_pipeline(transport::HttpRequest& req, Respond& respond, const std::string& route,
                    json::Value body);
  // The route table: every HTTP route in one list (routes.cpp).
  void add_routes();
  void add_control_routes();
  // GET /api/robots and POST /api/robots/estop (robots_routes.cpp).
  void add_robots_routes();
  void robots_estop(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                    const std::string& route);
  // Control sessions, leases, ownership transfer, consent (control_routes.cpp).
  void queue_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                   const std::string& route);
  void claim_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                   const std::string& route);
  void renew_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                   const std::string& route);
  void release_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                     const std::string& route);
  void handoff_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                     const std::string& route);
  void lease_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                   const std::string& route, const std::string& lease_id, bool grants);
  void transfer_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                      const std::string& route);
  void consent_list_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                          const std::string& route);
  void consent_request_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                             const std::string& route);
  void consent_decision_route(transport::HttpRequest& req, Respond& respond,
                              const json::Value& body, const std::string& route,
                              const std::string& id, const std::string& verb);
  Result<Principal> route_principal(const transport::HttpRequest& req, const json::Value& body,
                                    const std::string& route, const std::string& denied_event,
                                    Role min_role, std::string_view scope);
  // Wakes the pump on every change to timed state, registers the control gauges and starts
  // ControlService (control_routes.cpp).
  void control_start();
  // The refusal summaries due, then ControlService's tick (with the streamless claimants).
  void control_tick() EXCLUDES(streams_mu_);
  // Answers a control operation: its refusal, or its body once its audit record is durable.
  void answer_control(Respond& respond, const std::string& route, ControlAnswer a);
  // POSTs the owner's notification of a consent request to control.consent_webhook, on the
  // worker, and records CONSENT_NOTIFIED.
  void notify_consent_webhook(const ConsentRequest& c, const json::Value& note);
  void audit_listing(transport::HttpRequest& req, Respond& respond, const std::string& route);
  void audit_export(transport::HttpRequest& req, Respond& respond, const std::string& route);
  // Reading the audit log: OWNER (and `scope`, when not empty), else 403 recorded as
  // AUDIT_READ blocked. Answers the refusal itself and returns false.
  bool audit_reader(const Principal& p, const std::string& route, std::string_view scope,
                    Respond& respond);
  // True for OWNER holding `scope` (none: any OWNER); otherwise records `event` blocked,
  // answers 403 INSUFFICIENT_PRIVILEGES ("<why>: reading it needs OWNER …") and returns false.
  bool owner_reader(const Principal& p, const std::string& route, std::string_view scope,
                    const char* event, std::string_view why, Respond& respond);
  // Records the read (AUDIT_READ: who, the route, the query) and runs `read` once the record is
  // durable; if it cannot be recorded, answers 503 AUDIT_UNAVAILABLE and reads nothing.
  void record_audit_read(const Principal& p, const std::string& route, json::Object query,
                         Respond& respond, std::function<void()> read);
  void list_audit(Respond& respond, const std::string& route, const AuditQuery& q);
  // GET /api/node/log: the newest lines of the process's log ring (runtime/log.h), for OWNER with
  // scope `config`; each read recorded as LOG_READ (a refused one as LOG_READ blocked).
  void node_log(transport::HttpRequest& req, Respond& respond, const std::string& route);
  // Records `event` (who, the route, the query) and runs `read` once the record is durable; if
  // it cannot be recorded, answers 503 AUDIT_UNAVAILABLE and reads nothing.
  void record_read(const char* event, const Principal& p, const std::string& route,
                   json::Object query, Respond& respond, std::function<void()> read);
  Result<Principal> bearer_principal(const transport::HttpRequest& req) const;
  void pump() EXCLUDES(streams_mu_, pump_mu_);
  // Wakes the pump for a control tick now: something timed may have begun (a session, a
  // transfer, a consent request, a refusal window, a closed stream).
  void wake_pump() EXCLUDES(pump_mu_);
  // True when no control state waits for a time: the pump may sleep until woken.
  bool control_quiet() EXCLUDES(streams_mu_);
  void stream_text(const std::shared_ptr<StreamState>& st, std::string text);
  void register_stream(const std::shared_ptr<StreamState>& st) EXCLUDES(streams_mu_, pump_mu_);
  void unregister_stream(const std::shared_ptr<StreamState>& st) EXCLUDES(streams_mu_);
  // A closed tab leaves the control queue: the principals whose last stream closed and who
  // opened none again within control.queue_stream_grace_s; the control tick drops their queued
  // claims (CLAIM_DROPPED, docs/SESSIONS.md).
  std::vector<std::string> streamless_claimants() EXCLUDES(streams_mu_);
  // Closes (1008, after an AUTH_INVALID `token_revoked` frame) every stream whose CONNECT
  // principal the revocation list now names.
  void close_revoked_streams() EXCLUDES(streams_mu_);
  // Revocation routes (revocation_routes.cpp): GET and POST /rcan/v1/revocations, OWNER.
  void add_revocation_routes();
  void revocations_route(transport::HttpRequest& req, Respond& respond, const json::Value& body,
                         const std::string& route);

  NodeServices& svc_;
  Pipeline pipeline_;
  RouteTable routes_;
  Histogram* respond_timer_;  // stage "respond": answer handed over → its write begins
  Worker worker_{1};
  RobotDirectory* robots_ = nullptr;
  Worker relay_worker_{2};  // relayed stops (they wait on other robots' answers)
  mutable Mutex streams_mu_;
  std::vector<std::shared_ptr<StreamState>> streams_ GUARDED_BY(streams_mu_);
  // Principals (key) whose stream closed, and when: streamless_claimants() looks at them.
  std::map<std::string, int64_t> closed_streams_of_ GUARDED_BY(streams_mu_);
  std::atomic<bool> running_{false};
  std::thread pump_;
  Mutex pump_mu_;
  CondVar pump_cv_;  // wakes the pump on a new stream, a control change and on shutdown
  bool pump_woken_ GUARDED_BY(pump_mu_) = false;
  uint64_t event_sub_ = 0;
  uint64_t revocation_sub_ = 0;
};

}  // namespace rcan::node
