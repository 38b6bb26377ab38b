// Hooks from the node's router and streams into the §16 routes (ai_routes.cpp).
#pragma once

#include <functional>
#include <optional>
#include <string>

#include "node/admission/authenticator.h"
#include "node/api/route_table.h"
#include "rcan/json.h"
#include "transport/http_api.h"

namespace rcan::node {

// Adds the rows for POST /rcan/v1/authorize, GET /rcan/v1/pending, GET /api/thoughts/<id> and
// GET /api/v1/watermark/verify; without AI accountability they answer 404.
void add_ai_routes(RouteTable& table, NodeServices& svc);

// A stream frame of type AUTHORIZE from a CONNECTed principal; false for other types.
bool ai_stream_message(NodeServices& svc, const std::string& type, const json::Value& body,
                       const std::optional<Principal>& principal,
                       const std::function<void(std::string)>& send);

}  // namespace rcan::node
