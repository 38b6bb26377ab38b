// AiServices — the node's §16 AI-accountability state (docs/AI.md): the configured
// confidence gates, HiTL gates and brain layers, the held (PENDING_AUTH) commands and their
// timer, the thought log and the watermark key. The pipeline's gate stages (gate_stages.cpp) and
// the §16 routes (ai_routes.cpp) use it; the daemon creates it and sets NodeServices::ai.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "base/thread_annotations.h"
#include "base/worker.h"
#include "config/config.h"
#include "node/ai/hitl.h"
#include "node/ai/thoughts.h"
#include "node/pipeline/pipeline.h"
#include "rcan/crypto/keys.h"

namespace rcan::node {

class NodeServices;

struct AiOptions {
  std::vector<config::ConfidenceGate> confidence_gates;
  std::vector<config::HitlGate> hitl_gates;
  std::array<std::optional<config::AgentLayer>, 3> layers;  // reactive, fast, planner
  std::string pending_file;         // held commands survive restarts here (0600)
  keys::SecretBytes watermark_key;  // the robot's ML-DSA-65 secret key (4032 bytes)
  size_t thought_capacity = 1000;
  std::string thought_file;  // the §16.5 thought log survives restarts here (0600; "" = memory)
  int webhook_timeout_ms = 2000;
};

// Builds the options from a configuration (the key is added by the caller).
AiOptions ai_options(const config::NodeConfig& cfg);

class AiServices {
 public:
  AiServices(NodeServices& svc, AiOptions opts);
  ~AiServices();
  AiServices(const AiServices&) = delete;
  AiServices& operator=(const AiServices&) = delete;

  // Binds the node's pipeline, reloads held commands from the pending file (settling those
  // that expired while the node was down) and starts the timeout timer.
  Status start(Pipeline& pipeline) EXCLUDES(mu_);
  // Stops the timer and the worker (held commands stay in the pending file).
  void shutdown() EXCLUDES(mu_);

  // --- confidence gates (§16.3)
  const config::ConfidenceGate* gate_for(const Context& ctx) const;
  // The next configured layer strictly above `rank` (-1: the lowest configured).
  std::optional<std::pair<int, config::AgentLayer>> layer_above(int rank) const;
  // Posts the escalation to the worker; the context is finished or resumed from there.
  void escalate(const std::shared_ptr<Context>& ctx, const config::ConfidenceGate& gate,
                int to_rank, const config::AgentLayer& layer);

  // --- HiTL gates (§16.4)
  // The HiTL gate that holds `action` (either side may name a synonym; rcan/actions.h).
  const config::HitlGate* hitl_gate_for(const std::string& action) const;
  // Holds the command: persists it, audits HITL_PENDING, notifies, answers 202 (from the disk
  // worker, once the pending file holds it). False, doing nothing, when a command with the same
  // message_id is already held (another principal's: ids are unique per principal).
  bool hold(const std::shared_ptr<Context>& ctx, const config::HitlGate& gate,
            const std::string& action_type) EXCLUDES(mu_);
  // An AUTHORIZE from `p` (authenticated). `done` gets the answer for the authorizer.
  void authorize(const Principal& p, const json::Value& body, const std::string& transport,
                 const std::string& route, std::function<void(int status, json::Value body)> done);
  json::Value pending_list() const EXCLUDES(mu_);
  size_t pending_count() const EXCLUDES(mu_);

  // --- thought log (§16.5)
  ThoughtLog& thoughts() { return thoughts_; }
  // Clears the thought log (ownership transfer).
  void clear_thoughts() { thoughts_.clear(); }

  // --- watermark (§16.6)
  bool has_watermark_key() const { return !opts_.watermark_key.empty(); }
  std::string watermark(const std::string& thought_id, const std::string& timestamp_iso) const;

  // Publishes an event to the streams of OWNER/CREATOR principals only, or to one principal.
  void notify_owners(json::Value event);
  void notify_principal(const std::string& principal_key, json::Value event);

  // Disk work (pending file, audit look-ups) off the transport threads.
  Worker& worker() { return disk_; }

 private:
  struct Held {
    PendingItem item;
  };
  void decide(const Principal& p, const AuthorizeRequest& req, const std::string& transport,
              const std::string& route, const std::function<void(int, json::Value)>& done)
      EXCLUDES(mu_);
  void timer_loop() EXCLUDES(mu_);
  void settle_timeout(PendingItem item);
  void dispatch_held(const PendingItem& item, json::Object extra_detail, bool timeout_bypass,
                     std::function<void(Outcome)> done);
  void persist_locked() REQUIRES(mu_);
  // Held commands time out on the monotonic clock: a wall-clock step since the last reading
  // shifts every deadline by the step (a step forward must not time out, or auto-allow, what
  // is waiting for its approver). Returns whether anything moved.
  bool absorb_wall_step_locked(int64_t now_mono_ms, int64_t now_wall_ms) REQUIRES(mu_);
  void post_webhooks(const PendingItem& item, const json::Value& event);
  std::shared_ptr<Context> rebuild(const PendingItem& item, Error& err);

  NodeServices& svc_;
  AiOptions opts_;
  ThoughtLog thoughts_;
  Pipeline* pipeline_ = nullptr;  // set by start(), before the timer
  mutable Mutex mu_;
  CondVar cv_;
  std::map<std::string, PendingItem> pending_ GUARDED_BY(mu_);
  bool quit_ GUARDED_BY(mu_) = false;
  int64_t anchor_mono_ms_ GUARDED_BY(mu_) = -1;
  int64_t anchor_wall_ms_ GUARDED_BY(mu_) = 0;
  std::thread timer_;
  Worker net_{2};   // layer calls and webhooks (may wait for their timeouts)
  Worker disk_{1};  // the pending file and audit look-ups, in order
};

}  // namespace rcan::node
