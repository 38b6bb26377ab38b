// SwarmAgent — swarm discovery and leadership (seed §5.2; docs/FLEET.md §Swarms).
//
// Every member beats on <prefix>/swarm/<id>/heartbeat/<member> every heartbeat_ms. The leader
// publishes SWARM_ANNOUNCE {swarm_id, members, leader, formation, join_policy, epoch} retained
// on <prefix>/swarm/<id>/announce, so a member starting later learns the swarm at once.
//
// Leader loss: when the leader has not been heard for leader_timeout_ms, every member applies
// the same rule — the new leader is the first member, in byte order, among those heard within
// the timeout (a member always counts itself) other than the silent leader and those whose
// heartbeat says they cannot hear (`hearing: false`: chosen, they would not learn it). The member
// the rule names takes over: it raises the epoch and announces (reason "leader_silent",
// previous_leader). An announce with a higher epoch (or an equal epoch and a smaller leader)
// wins, so members converge after a partition.
//
// Authenticity: every announce and heartbeat carries `swarm_mac`, the hex HMAC-SHA256 under the
// members' shared secret (swarm.secret_file) of "rcan-swarm-v1:<swarm_id>:" + the canonical JSON of
// the message without it. A member drops an announce or heartbeat whose MAC does not verify, a
// heartbeat whose member is not its topic's, and a heartbeat not newer than the last one of
// its member or more than 30 s from its own clock; it logs `swarm_message_dropped` (at most
// every 10 s) and counts them in state() `dropped`; the leader answers a dropped announce by
// announcing again (reason "restored", at most once a second), so the retained announce is the
// swarm's own. Anyone without the secret — another
// fleet's robot, a client with the broker's credentials — can neither change the swarm's
// members or leader nor keep a silent leader alive.
//
// Every change of the state raises the epoch (a pending join request too), so two announces of
// one epoch say the same; the state is kept in a file (state_file) across restarts.
//
// Joins: SWARM_JOIN {member, auth_token, message_id, timestamp_ms} on <prefix>/swarm/<id>/join.
// The leader alone answers, on <prefix>/swarm/<id>/join/<member>: the token must verify (as
// on every other route); then `open` grants (the member is added and announced), `closed`
// denies, `approval` answers PENDING_AUTH until a SWARM_APPROVE {member} under an OWNER token
// (or above) arrives on the same topic. Each decision is audited (SWARM_JOIN / SWARM_APPROVE).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "base/thread_annotations.h"
#include "config/fleet_config.h"
#include "rcan/json.h"
#include "rcan/mqtt_topics.h"

namespace rcan::node {

class NodeServices;

class SwarmAgent {
 public:
  using Publish =
      std::function<void(const std::string& topic, const json::Value& body, int qos, bool retain)>;

  // `require_bound_tokens`: join and approval requests need a key-bound token and a signature
  // by its key (mqtt.require_bound_tokens), like every other message over MQTT.
  // `state_file` ("" = not kept): the swarm's state as this member last knew it (epoch, leader,
  // members, pending), written on every change and read back here, so that after a restart an
  // announce of an earlier epoch (a replayed one, when the broker no longer holds the retained
  // announce) is still stale. The configured members are kept too.
  SwarmAgent(NodeServices& svc, config::SwarmConfig cfg, std::string secret, std::string prefix,
             Publish publish, bool require_bound_tokens = true, std::string state_file = "");

  // Topic filters to subscribe to; those a member must hear to judge its leader (announce and
  // heartbeats).
  std::vector<std::string> subscriptions() const;
  std::vector<std::string> hearing_subscriptions() const;
  // Called on every (re)connect: starts the silence clocks and announces when leader. Until it
  // has been called (and again after on_disconnected()), tick() neither beats nor judges the
  // leader: the client may report the connection up before its callback has run, and a
  // member ticked in between would find everyone silent since the last connection.
  void on_connected(int64_t now_mono_ms) EXCLUDES(mu_);
  void on_disconnected() EXCLUDES(mu_);
  void on_message(const mqtt::InboundTopic& topic, const json::Value& body, int64_t now_mono_ms)
      EXCLUDES(mu_);
  // Heartbeat and leader check; call every few tens of milliseconds. `hearing`: the member's
  // hearing_subscriptions() are granted. A member that cannot hear yet (a clustered broker
  // refuses subscriptions for a few seconds after a failover) beats but does not judge the
  // leader, and the silence clocks start again, a full timeout of grace, once it can.
  void tick(int64_t now_mono_ms, bool hearing) EXCLUDES(mu_);

  // {swarm_id, members, leader, epoch, formation, join_policy, pending, dropped, hearing}
  json::Value state() const EXCLUDES(mu_);
  std::string leader() const EXCLUDES(mu_);

 private:
  json::Value announce_body(const std::string& reason, const std::string& previous) const
      REQUIRES(mu_);
  void announce_locked(const std::string& reason, const std::string& previous) REQUIRES(mu_);
  // Writes the state file when the state differs from what it holds; read back at start.
  void persist_locked() REQUIRES(mu_);
  void restore_locked() REQUIRES(mu_);
  // The leader's answer to an announce it drops or finds stale: its own again, at most once a
  // second (two leaders holding different secrets, or a flood of replays, never loop).
  void reannounce_locked(const std::string& reason, int64_t now) REQUIRES(mu_);
  // `body` with its swarm_mac; whether a received body's swarm_mac verifies.
  json::Value sealed(json::Value body) const;
  bool authentic(const json::Value& body) const;
  void drop(const std::string& topic, const std::string& reason) EXCLUDES(mu_);
  void handle_join(const json::Value& body) EXCLUDES(mu_);
  void answer(const std::string& member, const std::string& type, const std::string& reply_to,
              const std::string& reason);

  NodeServices& svc_;
  config::SwarmConfig cfg_;
  mqtt::SwarmTopics topics_;
  Publish publish_;
  const bool require_bound_tokens_;
  const std::string state_file_;
  const std::string secret_;

  mutable Mutex mu_;
  std::set<std::string> members_ GUARDED_BY(mu_);
  std::set<std::string> pending_ GUARDED_BY(mu_);
  std::string leader_ GUARDED_BY(mu_);
  uint64_t epoch_ GUARDED_BY(mu_) = 0;
  std::map<std::string, int64_t> last_seen_ GUARDED_BY(mu_);
  int64_t last_beat_ GUARDED_BY(mu_) = 0;
  int64_t connected_since_ GUARDED_BY(mu_) = -1;  // -1: no connection callback yet
  bool hearing_ GUARDED_BY(mu_) = false;          // heard since the silence clocks last started
  std::map<std::string, int64_t> last_beat_ts_ GUARDED_BY(mu_);  // member → its heartbeat's ms
  // Members whose last heartbeat said they cannot hear: alive (a leader among them still leads)
  // but never chosen to lead, since they would not learn that they had been.
  std::set<std::string> deaf_ GUARDED_BY(mu_);
  std::string persisted_ GUARDED_BY(mu_);  // what the state file holds
  uint64_t dropped_ GUARDED_BY(mu_) = 0;
  int64_t drop_logged_mono_ GUARDED_BY(mu_) = -1;
  int64_t reannounced_mono_ GUARDED_BY(mu_) = -1;
  std::string reannounce_due_ GUARDED_BY(mu_);  // a re-announce the once-a-second limit held
};

}  // namespace rcan::node
