// The node's stage order (stage_order.h).
#include "node/api/stage_order.h"

#include "node/ai/gate_stages.h"
#include "node/fleet/fleet.h"
#include "node/pipeline/guest_limits.h"
#include "node/pipeline/stages.h"

namespace rcan::node {

std::vector<std::unique_ptr<Stage>> standard_stages(NodeServices& s) {
  std::vector<std::unique_ptr<Stage>> v;
  v.push_back(make_shape_stage(s));
  v.push_back(make_token_stage(s));
  v.push_back(make_decode_stage(s));
  v.push_back(make_auth_stage(s));
  // A stale message or a copy of one its principal already sent is refused at once; nothing is
  // remembered before authorisation, the guest limits and the rate limit have passed, so a
  // message refused by any of them (or by a bad token) uses up neither its message_id nor a
  // place in its principal's replay memory (docs/SECURITY.md).
  v.push_back(make_freshness_stage(s));
  v.push_back(make_fleet_stage(s));
  v.push_back(make_authorize_stage(s));
  v.push_back(make_guest_limit_stage(s));
  v.push_back(make_rate_limit_stage(s));
  v.push_back(make_replay_stage(s));
  v.push_back(make_safety_state_stage(s));
  v.push_back(make_injection_stage(s));
  for (auto& g : ai_stages(s)) v.push_back(std::move(g));  // §16: confidence, HiTL, watermark
  v.push_back(make_dispatch_stage(s));
  return v;
}

}  // namespace rcan::node
