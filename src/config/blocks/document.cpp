// The whole document: the blocks' tables in the order build() reads them, the schema they
// make, and the blocks kept as JSON. A later block may read what an earlier one set (the
// capabilities read robot.type; grpc.port is checked against server.port; the heartbeat
// default reads agent.latency_budget_ms; fleet and swarm read mqtt and the RURI), and the
// order decides which error a file with several faults reports first.
#include "config/blocks/blocks.h"

namespace rcan::config::internal {

const Table<NodeConfig>& document_rows() {
  static const Table<NodeConfig> rows = [] {
    Table<NodeConfig> all;
    for (Table<NodeConfig> part :
         {identity_blocks(), server_blocks(), security_blocks(), rbac_blocks(), agent_blocks(),
          safety_blocks(), driver_blocks(), control_blocks(), fleet_blocks(), profile_blocks()}) {
      for (Row<NodeConfig>& r : part) all.push_back(std::move(r));
    }
    return all;
  }();
  return rows;
}

namespace {

// Blocks kept as they are for the profiles (NodeConfig::kept), in this order.
void keep_blocks(const At& root, NodeConfig& c) {
  for (const char* k : {"bridge", "hardware_safety", "messaging", "metadata", "physics", "drivers",
                        "network", "tiered_brain", "reactive", "learner", "camera", "audio",
                        "channels", "agent_roster", "swarm", "connection", "notes", "ros2"}) {
    if (At b = root[k]) c.kept.set(k, *b.v);
  }
}

}  // namespace

SP config_schema() {
  static const SP schema = object_of(document_rows());
  return schema;
}

NodeConfig build(const json::Value& root_value, const ConfigOptions& opts) {
  NodeConfig c;
  Ctx x{At{&root_value, ""}, opts, c};
  walk(document_rows(), x.root, c, x);
  keep_blocks(x.root, c);
  derive_paths(c);
  return c;
}

}  // namespace rcan::config::internal
