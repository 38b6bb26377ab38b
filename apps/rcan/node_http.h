// The tiny HTTP client the node verbs share (implemented in node_cmd.cpp).
#pragma once

#include <string>
#include <utility>

#include "cli.h"
#include "rcan/result.h"

namespace rcan::cli {

// --url, else $RCAN_URL, else http://127.0.0.1:8080.
std::string node_url(const Options& o);
// The token from --token-file or $RCAN_TOKEN_FILE; `err` says why when required and missing.
std::string node_token(const Options& o, bool required, std::string& err);
// One request; {status, body}.
Result<std::pair<int, std::string>> node_request(const std::string& url, const std::string& method,
                                                 const std::string& path, const std::string& body,
                                                 const std::string& token);

}  // namespace rcan::cli
