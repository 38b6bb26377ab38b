// A tiny blocking HTTP/1.1 client for the node's own outbound calls: the consent webhook and
// the issuer reachability probe. http:// only (host:port/path), one request per connection,
// a hard timeout for connect, send and receive. Not for general use.
#pragma once

#include <string>
#include <string_view>

#include "rcan/result.h"

namespace rcan::node {

struct FetchResult {
  int status = 0;
  std::string body;
};

struct UrlParts {
  std::string host;
  std::string port = "80";
  std::string path = "/";
};
// "http://host[:port][/path]". Errors: SCHEMA_VALIDATION_FAILED.
Result<UrlParts> parse_http_url(std::string_view url);
// The status code of "HTTP/1.x NNN ..." (0 when it is not a status line). The fuzz target.
int parse_status_line(std::string_view line);

// Errors: SCHEMA_VALIDATION_FAILED (bad URL), INTERNAL (connect/IO/timeout).
Result<FetchResult> http_fetch(std::string_view method, std::string_view url, std::string_view body,
                               int timeout_ms);

}  // namespace rcan::node
