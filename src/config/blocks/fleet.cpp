// The MQTT transport and what runs on it: `mqtt`, `fleet` and the seed §5.2 keys of `swarm`
// (docs/CONFIG.md §mqtt, fleet, swarm; docs/FLEET.md). fleet_config.h holds the structs.
#include <algorithm>

#include "config/blocks/blocks.h"
#include "rcan/mqtt_topics.h"
#include "transport/mqtt_client.h"

namespace rcan::config::internal {
namespace {

// Ids become MQTT topic segments.
void segment(const At& at) {
  if (at && !mqtt::valid_topic_segment(at.str()))
    fail(at.path,
         "expected 1-128 characters of [A-Za-z0-9._-], got \"" + printable(at.str()) + "\"",
         "invalid_value");
}
void segments(const At& list) {
  for (size_t i = 0; i < list.size(); ++i) segment(list[i]);
}

Table<MqttConfig> mqtt_rows() {
  using M = Rows<MqttConfig>;
  return {
      M::field("enabled", Bool(), &MqttConfig::enabled),
      // One URL, or a list: a cluster's nodes, tried in turn after a broker loss (failover).
      M::read("broker", Either({Str(512), Arr(Str(512), 16)}),
              [](const At& a, MqttConfig& m, Ctx&) {
                if (a.is_string()) m.broker = a.str();
                if (!a.is_array()) return;
                m.brokers = a.strs();
                if (m.brokers.empty())
                  fail(a.path, "needs at least one broker URL", "invalid_value");
                m.broker = m.brokers.front();
              }),
      M::check([](const At& mq, MqttConfig& m, Ctx&) {
        const At b = mq["broker"];
        const std::vector<std::string> urls = m.broker_urls();
        for (size_t i = 0; i < urls.size(); ++i) {
          const std::string path = b.is_array() ? b[i].path : b.path;
          auto u = transport::parse_broker_url(urls[i]);
          if (!u.ok()) fail(path, u.error().message, "invalid_value");
          // A failover URL never drops to plaintext (one TLS setting per connection).
          const bool first_tls = urls.front().rfind("mqtts://", 0) == 0;
          if (u->tls != first_tls)
            fail(path, "the broker URLs must all be mqtt:// or all mqtts://", "invalid_value");
          if (u->tls && mq["tls"]["ca_file"].str().empty())
            fail(mq["tls"]["ca_file"].path, "required with an mqtts:// broker", "missing_key");
        }
      }),
      M::read("client_id", Str(128),
              [](const At& a, MqttConfig& m, Ctx&) {
                m.client_id = a.str();
                if (!m.client_id.empty() && !mqtt::valid_topic_segment(m.client_id))
                  fail(a.path, "expected 1-128 characters of [A-Za-z0-9._-]", "invalid_value");
              }),
      M::read("topic_prefix", Str(256),
              [](const At& a, MqttConfig& m, Ctx&) {
                if (a) m.topic_prefix = a.str();
                if (!mqtt::valid_topic_prefix(m.topic_prefix))
                  fail(a.path, "expected '/'-separated segments of [A-Za-z0-9._-] (no wildcards)",
                       "invalid_value");
              }),
      M::field("keepalive_s", Int(5, 3600), &MqttConfig::keepalive_s),
      M::field("require_bound_tokens", Bool(), &MqttConfig::require_bound_tokens),
      M::field("username", Str(256), &MqttConfig::username),
      M::read("password_file", Str(),
              [](const At& a, MqttConfig& m, Ctx& x) {
                m.password_file = resolve_path(a.str(), x.opts.base_dir);
                if (!m.username.empty() && m.password_file.empty())
                  fail(a.path, "required with mqtt.username", "missing_key");
              }),
      M::block("tls",
               Table<MqttConfig>{
                   M::path("ca_file", Str(), &MqttConfig::ca_file),
                   M::path("cert_file", Str(), &MqttConfig::cert_file),
                   M::path("key_file", Str(), &MqttConfig::key_file),
                   M::check([](const At& tls, MqttConfig& m, Ctx&) {
                     if (m.cert_file.empty() != m.key_file.empty())
                       fail(tls.path, "cert_file and key_file go together", "missing_key");
                   }),
               }),
      M::block("reconnect",
               Table<MqttConfig>{
                   M::field("min_s", Int(1, 3600), &MqttConfig::reconnect_min_s),
                   M::field("max_s", Int(1, 3600), &MqttConfig::reconnect_max_s),
                   M::check([](const At& rc, MqttConfig& m, Ctx&) {
                     if (m.reconnect_max_s < m.reconnect_min_s)
                       fail(rc["max_s"].path, "must be at least reconnect.min_s", "out_of_range");
                   }),
               }),
      M::field("telemetry_hz", Int(0, 50), &MqttConfig::telemetry_hz),
      M::field("publish_audit", Bool(), &MqttConfig::publish_audit),
      M::field("estop_qos", Int(0, 2), &MqttConfig::estop_qos),
      M::field("max_qos", Int(1, 2), &MqttConfig::max_qos),
      M::field("reply_qos", Int(0, 1), &MqttConfig::reply_qos),
      M::field("failover_ms", Int(100, 600000), &MqttConfig::failover_ms),
      M::check([](const At& mq, MqttConfig& m, Ctx&) {
        if (m.estop_qos > m.max_qos)
          fail(mq["estop_qos"].path, "must not exceed mqtt.max_qos", "out_of_range");
      }),
  };
}

// Read only when the file has a `fleet` block.
Table<FleetConfig> fleet_rows() {
  using F = Rows<FleetConfig>;
  return {
      F::check([](const At& fl, FleetConfig&, Ctx& x) {
        if (!x.c.mqtt.enabled)
          fail(fl.path, "a fleet needs the MQTT transport (mqtt.enabled: true)", "invalid_value");
      }),
      F::read("fleet_id", Str(128),
              [](const At& a, FleetConfig& f, Ctx&) {
                segment(a);
                f.fleet_id = a.str();
              })
          .required(),
      F::read("robots", Arr(Str(128), 10'000),
              [](const At& a, FleetConfig& f, Ctx&) {
                segments(a);
                f.robots = a.strs();
              })
          .required(),
      F::read("member_id", Str(128),
              [](const At& a, FleetConfig& f, Ctx& x) {
                segment(a);
                f.member_id = a.str(x.c.ruri_parts.device_id);
              }),
      F::check([](const At& fl, FleetConfig& f, Ctx&) {
        if (std::find(f.robots.begin(), f.robots.end(), f.member_id) == f.robots.end())
          fail(fl["robots"].path,
               "must list this robot (\"" + printable(f.member_id) +
                   "\", fleet.member_id or the RURI device id)",
               "invalid_value");
      }),
      F::field("access_mode", Enum({"coordinated", "independent"}), &FleetConfig::access_mode),
      F::block("commands",
               Table<FleetConfig>{
                   F::field("broadcast", Bool(), &FleetConfig::broadcast),
                   F::field("individual", Bool(), &FleetConfig::individual),
                   F::field("choreographed", Bool(), &FleetConfig::choreographed),
               }),
  };
}

// The seed §5.2 keys, read only when the file gives swarm.swarm_id; the OpenCastor keys are
// kept.
Table<SwarmConfig> swarm_rows() {
  using W = Rows<SwarmConfig>;
  return {
      W::schema_only("enabled", Bool()),
      W::schema_only("sync_interval_s", Num(1.0)),
      W::schema_only("patch_sync", Bool()),
      W::schema_only("shared_memory_path", Str(1024)),
      W::read("swarm_id", Str(128),
              [](const At& id, SwarmConfig& s, Ctx& x) {
                if (!x.c.mqtt.enabled)
                  fail(id.path, "a swarm needs the MQTT transport (mqtt.enabled: true)",
                       "invalid_value");
                segment(id);
                s.swarm_id = id.str();
              }),
      W::read("members", Arr(Str(128), 256),
              [](const At& a, SwarmConfig& s, Ctx&) {
                segments(a);
                s.members = a.strs();
              }),
      W::read("member_id", Str(128),
              [](const At& a, SwarmConfig& s, Ctx& x) {
                segment(a);
                const NodeConfig& c = x.c;
                s.member_id =
                    a.str(c.fleet.member_id.empty() ? c.ruri_parts.device_id : c.fleet.member_id);
                if (std::find(s.members.begin(), s.members.end(), s.member_id) == s.members.end())
                  s.members.push_back(s.member_id);
                std::sort(s.members.begin(), s.members.end());
                s.members.erase(std::unique(s.members.begin(), s.members.end()), s.members.end());
              }),
      W::read("leader", Str(128),
              [](const At& a, SwarmConfig& s, Ctx&) {
                segment(a);
                s.leader = a.str(s.members.front());
                if (std::find(s.members.begin(), s.members.end(), s.leader) == s.members.end())
                  fail(a.path, "the leader must be one of swarm.members", "invalid_value");
              }),
      W::field("formation", Str(64), &SwarmConfig::formation),
      W::field("join_policy", Enum({"open", "approval", "closed"}), &SwarmConfig::join_policy),
      W::field("heartbeat_ms", Int(50, 60'000), &SwarmConfig::heartbeat_ms),
      W::read("leader_timeout_ms", Int(200, 600'000),
              [](const At& a, SwarmConfig& s, Ctx&) {
                if (a) assign(a, s.leader_timeout_ms);
                if (s.leader_timeout_ms < 2 * s.heartbeat_ms)
                  fail(a.path, "must be at least twice swarm.heartbeat_ms", "out_of_range");
              }),
      W::read("secret_file", Str(),
              [](const At& a, SwarmConfig& s, Ctx& x) {
                s.secret_file = resolve_path(a.str(), x.opts.base_dir);
                if (s.secret_file.empty())
                  fail(a.path,
                       "a swarm needs the members' shared secret file, which authenticates its "
                       "announces and heartbeats (make one with: rcan audit new-secret --out F)",
                       "missing_key");
              }),
  };
}

}  // namespace

Table<NodeConfig> fleet_blocks() {
  using R = Rows<NodeConfig>;
  static const Table<FleetConfig> fleet = fleet_rows();
  static const Table<SwarmConfig> swarm = swarm_rows();
  return {
      R::block("mqtt", mqtt_rows(), &NodeConfig::mqtt),
      R::read("fleet", object_of(fleet),
              [](const At& a, NodeConfig& c, Ctx& x) {
                if (a) walk(fleet, a, c.fleet, x);  // reads c.mqtt, c.ruri_parts
              }),
      R::read("swarm", object_of(swarm),
              [](const At& a, NodeConfig& c, Ctx& x) {
                if (a["swarm_id"]) walk(swarm, a, c.swarm, x);  // reads c.mqtt, c.fleet
              }),
  };
}

}  // namespace rcan::config::internal
