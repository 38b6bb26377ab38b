#include "rcan/mqtt_topics.h"

#include <vector>

namespace rcan::mqtt {

namespace {

std::vector<std::string_view> split(std::string_view s) {
  std::vector<std::string_view> out;
  size_t start = 0;
  while (true) {
    size_t slash = s.find('/', start);
    out.push_back(
        s.substr(start, slash == std::string_view::npos ? std::string_view::npos : slash - start));
    if (slash == std::string_view::npos) break;
    start = slash + 1;
    if (out.size() > 64) break;  // deeper than any topic of ours
  }
  return out;
}

}  // namespace

bool valid_topic_segment(std::string_view s) {
  if (s.empty() || s.size() > kMaxTopicSegmentBytes) return false;
  for (char c : s) {
    bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
              c == '.' || c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

bool valid_topic_prefix(std::string_view s) {
  if (s.empty() || s.size() > 256) return false;
  for (auto seg : split(s))
    if (!valid_topic_segment(seg)) return false;
  return true;
}

Result<RobotTopics> robot_topics(std::string_view prefix, const Ruri& ruri) {
  std::string base = std::string(prefix) + "/robot";
  for (const std::string* seg :
       {&ruri.registry, &ruri.manufacturer, &ruri.model, &ruri.device_id}) {
    if (!valid_topic_segment(*seg) || seg->find('_') != std::string::npos)
      return Error(ErrorCode::kInvalidRuri,
                   "RURI segment \"" + *seg + "\" cannot be an MQTT topic segment", "ruri");
    std::string s = *seg;
    for (char& c : s)
      if (c == '.') c = '_';
    base += "/" + s;
  }
  return RobotTopics{std::move(base)};
}

FleetTopics fleet_topics(std::string_view prefix, std::string_view fleet_id) {
  return FleetTopics{std::string(prefix) + "/fleet/" + std::string(fleet_id)};
}

SwarmTopics swarm_topics(std::string_view prefix, std::string_view swarm_id) {
  return SwarmTopics{std::string(prefix) + "/swarm/" + std::string(swarm_id)};
}

InboundTopic parse_topic(std::string_view prefix, std::string_view topic) {
  InboundTopic t;
  if (topic.size() > 1024 || prefix.empty() || topic.size() <= prefix.size() + 1) return t;
  if (topic.substr(0, prefix.size()) != prefix || topic[prefix.size()] != '/') return t;
  auto segs = split(topic.substr(prefix.size() + 1));
  for (auto s : segs)
    if (!valid_topic_segment(s)) return t;
  const size_t n = segs.size();
  if (segs[0] == "robot" && n == 6 && segs[5] == "cmd") {
    t.kind = TopicKind::kRobotCmd;
  } else if (segs[0] == "fleet" && n == 3 && segs[2] == "cmd") {
    t.kind = TopicKind::kFleetCmd;
    t.fleet_id = std::string(segs[1]);
  } else if (segs[0] == "fleet" && n == 3 && segs[2] == "estop") {
    t.kind = TopicKind::kFleetEstop;
    t.fleet_id = std::string(segs[1]);
  } else if (segs[0] == "fleet" && n == 5 && segs[2] == "robot" && segs[4] == "cmd") {
    t.kind = TopicKind::kMemberCmd;
    t.fleet_id = std::string(segs[1]);
    t.member = std::string(segs[3]);
  } else if (segs[0] == "swarm" && n == 3 && segs[2] == "announce") {
    t.kind = TopicKind::kSwarmAnnounce;
    t.swarm_id = std::string(segs[1]);
  } else if (segs[0] == "swarm" && n == 4 && segs[2] == "heartbeat") {
    t.kind = TopicKind::kSwarmHeartbeat;
    t.swarm_id = std::string(segs[1]);
    t.member = std::string(segs[3]);
  } else if (segs[0] == "swarm" && n == 3 && segs[2] == "join") {
    t.kind = TopicKind::kSwarmJoin;
    t.swarm_id = std::string(segs[1]);
  }
  return t;
}

Result<json::Value> parse_payload(std::string_view payload) {
  if (payload.size() > kMaxMqttPayloadBytes)
    return Error(ErrorCode::kBodyTooLarge,
                 "the MQTT payload exceeds " + std::to_string(kMaxMqttPayloadBytes) + " bytes");
  json::ParseOptions po;
  po.max_depth = 32;
  po.max_bytes = kMaxMqttPayloadBytes;
  auto v = json::parse(payload, po);
  if (!v.ok()) {
    Error e = v.error();
    e.code = ErrorCode::kMalformedJson;
    return e;
  }
  if (!v->is_object())
    return Error(ErrorCode::kSchemaValidationFailed, "an MQTT payload must be a JSON object");
  return v;
}

}  // namespace rcan::mqtt
