// The MQTT topic layout of RCAN robots, fleets and swarms (docs/FLEET.md), and the parser of
// inbound topics and payloads. Pure functions, no I/O: the fuzz target mqtt_fuzz drives them.
//
//   <prefix>/robot/<registry>/<manufacturer>/<model>/<device_id>/cmd        in  QoS 1
//   <prefix>/robot/…/reply | status (retained, will) | telemetry | events | audit   out
//   <prefix>/fleet/<fleet_id>/cmd                       in  broadcast to every member
//   <prefix>/fleet/<fleet_id>/estop                     in  retained fleet ESTOP / RESUME
//   <prefix>/fleet/<fleet_id>/robot/<member>/cmd        in  one member
//   <prefix>/fleet/<fleet_id>/robot/<member>/reply | status | telemetry | events | audit  out
//   <prefix>/swarm/<swarm_id>/announce                  SWARM_ANNOUNCE (retained)
//   <prefix>/swarm/<swarm_id>/heartbeat/<member>        liveness
//   <prefix>/swarm/<swarm_id>/join                      join requests (SWARM_JOIN)
//   <prefix>/swarm/<swarm_id>/join/<member>             the answer to <member>
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/json.h"
#include "rcan/result.h"
#include "rcan/ruri.h"

namespace rcan::mqtt {

inline constexpr size_t kMaxMqttPayloadBytes = 64 * 1024;
inline constexpr size_t kMaxTopicSegmentBytes = 128;

// A topic segment we build from configuration: 1..128 bytes of [A-Za-z0-9._-] (no '/', no
// wildcards, no '$'). Used to validate fleet, member, swarm ids and the prefix's segments.
bool valid_topic_segment(std::string_view s);
// A prefix: one or more valid segments joined by '/'.
bool valid_topic_prefix(std::string_view s);

struct RobotTopics {
  std::string base;  // <prefix>/robot/<registry>/<manufacturer>/<model>/<device_id>, '.' → '_'
  std::string cmd() const { return base + "/cmd"; }
  std::string reply() const { return base + "/reply"; }
  std::string status() const { return base + "/status"; }
  std::string telemetry() const { return base + "/telemetry"; }
  std::string events() const { return base + "/events"; }
  std::string audit() const { return base + "/audit"; }
};

// Topics of a robot from its RURI, each '.' of a segment written as '_' (`local.rcan` →
// `local_rcan`): NATS maps topics onto its dotted subjects and refuses a '.' in a topic, and no
// RURI segment may hold a '_', so the mapping is one-to-one. Errors: kInvalidRuri when a segment
// cannot be a topic segment.
Result<RobotTopics> robot_topics(std::string_view prefix, const Ruri& ruri);

struct FleetTopics {
  std::string base;  // <prefix>/fleet/<fleet_id>
  std::string cmd() const { return base + "/cmd"; }
  std::string estop() const { return base + "/estop"; }
  RobotTopics member(std::string_view member) const {
    return RobotTopics{base + "/robot/" + std::string(member)};
  }
};
FleetTopics fleet_topics(std::string_view prefix, std::string_view fleet_id);

struct SwarmTopics {
  std::string base;  // <prefix>/swarm/<swarm_id>
  std::string announce() const { return base + "/announce"; }
  std::string heartbeat(std::string_view member) const {
    return base + "/heartbeat/" + std::string(member);
  }
  std::string heartbeats() const { return base + "/heartbeat/+"; }
  std::string join() const { return base + "/join"; }
  std::string join_answer(std::string_view member) const {
    return base + "/join/" + std::string(member);
  }
};
SwarmTopics swarm_topics(std::string_view prefix, std::string_view swarm_id);

// What an inbound topic addresses.
enum class TopicKind {
  kRobotCmd,    // this robot's own cmd topic
  kFleetCmd,    // fleet broadcast
  kFleetEstop,  // the retained fleet ESTOP
  kMemberCmd,   // this robot within its fleet
  kSwarmAnnounce,
  kSwarmHeartbeat,  // member = who beats
  kSwarmJoin,
  kOther,  // a topic this node does not act on
};

struct InboundTopic {
  TopicKind kind = TopicKind::kOther;
  std::string fleet_id;
  std::string swarm_id;
  std::string member;
};

// Classifies `topic` relative to `prefix` (any fleet / swarm id; the caller checks they are
// its own). Never fails: unknown or malformed topics are kOther.
InboundTopic parse_topic(std::string_view prefix, std::string_view topic);

// Parses an inbound payload: UTF-8 JSON object, at most kMaxMqttPayloadBytes, depth 32.
// Errors: kBodyTooLarge, kMalformedJson, kSchemaValidationFailed (not an object).
Result<json::Value> parse_payload(std::string_view payload);

}  // namespace rcan::mqtt
