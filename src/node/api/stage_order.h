// The node's pipeline: which stages run, in which order (docs/NODE.md).
#pragma once

#include <memory>
#include <vector>

#include "node/pipeline/pipeline.h"

namespace rcan::node {

// shape → token → decode → authentication → freshness → fleet → authorisation → guest limits →
// rate limit → replay → safety state → injection screen → §16 gates → audit and dispatch.
std::vector<std::unique_ptr<Stage>> standard_stages(NodeServices& services);

}  // namespace rcan::node
