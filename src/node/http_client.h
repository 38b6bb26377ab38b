// A small blocking HTTP/1.1 client for the node's outbound calls (brain layers, HiTL
// webhooks). Plain http:// only, one request per connection, every step bounded by one
// deadline. Call it from a worker thread, never from a transport thread.
#pragma once

#include <cstdint>
#include <string>

#include "rcan/result.h"

namespace rcan::node {

struct HttpUrl {
  std::string host;
  uint16_t port = 80;
  std::string path = "/";
};

// Parses http://host[:port][/path]. https:// and anything else is an error (the node has no
// TLS client; put a local proxy in front of a remote endpoint).
Result<HttpUrl> parse_http_url(const std::string& url);

struct HttpAnswer {
  int status = 0;
  std::string body;
};

// POSTs `json_body` (Content-Type: application/json) and reads the answer, at most
// `max_body` bytes, within `timeout_ms` overall. Errors: kTimeout-like kInternal with a
// message (connect refused, timeout, malformed answer).
Result<HttpAnswer> http_post_json(const HttpUrl& url, const std::string& json_body, int timeout_ms,
                                  size_t max_body = 256 * 1024);

}  // namespace rcan::node
