// The CLI's tiny HTTP client for talking to a running node (defined in node_cmd.cpp).
#pragma once

#include <string>
#include <utility>
#include <vector>

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
Result<std::pair<int, std::string>> request(const Target& t, const std::string& method,
                                            const std::string& path, const std::string& body,
                                            const std::string& token);
// The first line of the secret file named by --<option> or $<env> (trailing whitespace
// dropped); `err` set when required and absent, or unreadable.
std::string secret_from(const Options& o, const std::string& option, const char* env, bool required,
                        std::string& err);
// The bearer token from --token-file or $RCAN_TOKEN_FILE; `err` set when required and absent.
std::string token_from(const Options& o, bool required, std::string& err);

// --url, else $RCAN_URL, else http://127.0.0.1:8080.
std::string node_url(const Options& o);
// token_from() under the name the lease/transfer/consent verbs use.
std::string node_token(const Options& o, bool required, std::string& err);
// parse_url() + request().
Result<std::pair<int, std::string>> node_request(const std::string& url, const std::string& method,
                                                 const std::string& path, const std::string& body,
                                                 const std::string& token);
// The same with more request headers (names and values as given).
Result<std::pair<int, std::string>> node_request(
    const std::string& url, const std::string& method, const std::string& path,
    const std::string& body, const std::string& token,
    const std::vector<std::pair<std::string, std::string>>& headers);

}  // namespace rcan::cli
