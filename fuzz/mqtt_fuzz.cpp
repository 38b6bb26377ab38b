// libFuzzer: the MQTT inbound parsers — topic classification, payload parsing and broker URLs.
// Input: "<topic>\n<payload>". Invariants: never crash; a classified topic round-trips through
// the builders; an accepted payload is a JSON object; an accepted URL has a host and a port.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "rcan/mqtt_topics.h"
#include "transport/mqtt_client.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  size_t nl = text.find('\n');
  std::string_view topic = text.substr(0, nl);
  std::string_view payload =
      nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
  using rcan::mqtt::TopicKind;
  auto t = rcan::mqtt::parse_topic("rcan", topic);
  switch (t.kind) {
    case rcan::mqtt::TopicKind::kFleetCmd:
      if (rcan::mqtt::fleet_topics("rcan", t.fleet_id).cmd() != topic) std::abort();
      break;
    case rcan::mqtt::TopicKind::kFleetEstop:
      if (rcan::mqtt::fleet_topics("rcan", t.fleet_id).estop() != topic) std::abort();
      break;
    case rcan::mqtt::TopicKind::kMemberCmd:
      if (rcan::mqtt::fleet_topics("rcan", t.fleet_id).member(t.member).cmd() != topic)
        std::abort();
      break;
    case rcan::mqtt::TopicKind::kSwarmAnnounce:
      if (rcan::mqtt::swarm_topics("rcan", t.swarm_id).announce() != topic) std::abort();
      break;
    case rcan::mqtt::TopicKind::kSwarmHeartbeat:
      if (rcan::mqtt::swarm_topics("rcan", t.swarm_id).heartbeat(t.member) != topic) std::abort();
      break;
    case rcan::mqtt::TopicKind::kSwarmJoin:
      if (rcan::mqtt::swarm_topics("rcan", t.swarm_id).join() != topic) std::abort();
      break;
    case rcan::mqtt::TopicKind::kRobotCmd:
    case rcan::mqtt::TopicKind::kOther:
      break;
  }
  auto p = rcan::mqtt::parse_payload(payload);
  if (p.ok() && !p->is_object()) std::abort();
  auto u = rcan::transport::parse_broker_url(topic);
  if (u.ok() && (u->host.empty() || u->port == 0)) std::abort();
  return 0;
}
