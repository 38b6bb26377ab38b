// The §16 stages of the pipeline: the confidence gate (§16.3), the HiTL gate (§16.4) and the
// watermark (§16.6), in that order, for the gate slot before dispatch (node/api/stage_order.cpp).
#pragma once

#include <memory>
#include <vector>

#include "node/pipeline/pipeline.h"

namespace rcan::node {

std::vector<std::unique_ptr<Stage>> ai_stages(NodeServices& services);

}  // namespace rcan::node
