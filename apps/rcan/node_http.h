// The CLI's tiny HTTP client for talking to a running node (defined in node_cmd.cpp).
#pragma once

#include <string>
#include <utility>

#include "cli.h"
#include "rcan/result.h"

namespace rcan::cli {

struct Target {
  std::string host;
  std::string port;
};

// http://host[:port][/…] → host and port.
Result<Target> parse_url(const std::string& url);
// One HTTP/1.1 request; returns {status, body}.
Result<std::pair<int, std::string>> request(const Target& t, const std::string& method, const std::string& path,
                                            const std::string& body, const std::string& token);
// The bearer token from --token-file or $RCAN_TOKEN_FILE; `err` set when required and absent.
std::string token_from(const Options& o, bool required, std::string& err);

}  // namespace rcan::cli
