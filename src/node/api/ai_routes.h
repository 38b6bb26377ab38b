// Hooks from the node's router and streams into the §16 routes (ai_routes.cpp).
#pragma once

#include <functional>
#include <optional>
#include <string>

#include "node/admission/authenticator.h"
#include "rcan/json.h"
#include "transport/http_api.h"

namespace rcan::node {

class NodeServices;

// Answers POST /rcan/v1/authorize, GET /rcan/v1/pending, GET /api/thoughts/<id> and
// GET /api/v1/watermark/verify. False when the path is not one of them.
bool ai_route(NodeServices& svc, transport::HttpRequest& req,
              transport::HttpHandler::Respond& respond);

// A stream frame of type AUTHORIZE from a CONNECTed principal; false for other types.
bool ai_stream_message(NodeServices& svc, const std::string& type, const json::Value& body,
                       const std::optional<Principal>& principal,
                       const std::function<void(std::string)>& send);

}  // namespace rcan::node
