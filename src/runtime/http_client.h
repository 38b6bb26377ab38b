// The node's one outbound HTTP/1.1 client: brain layers, HiTL and consent webhooks, the
// issuer reachability probe. Plain http:// only (URLs are validated as such; put a local proxy
// in front of a remote endpoint), one request per connection, every step (resolve excepted)
// bounded by one deadline, answers capped. Blocking: call it from a worker thread, never from a
// transport thread. The connection and the answer's parsing are the client library's
// (client::net::exchange, src/client/net.h); this file writes the node's request and words
// its errors.
#pragma once

#include <sys/socket.h>

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "rcan/result.h"

namespace rcan {

struct HttpUrl {
  std::string host;
  uint16_t port = 80;
  std::string path = "/";
  bool tls = false;  // https:// (parse_web_url only)
};

// "http://host[:port][/path]". Errors: SCHEMA_VALIDATION_FAILED (field "url").
Result<HttpUrl> parse_http_url(std::string_view url);
// The same, or "https://host[:port][/path]" (port 443 by default; the server's certificate is
// checked against the system's trust anchors or HttpRequestOptions::ca_file). For the node's
// links to services on the internet (its registry); the other callers stay on plain http.
Result<HttpUrl> parse_web_url(std::string_view url);
// The status code of "HTTP/1.x NNN ..." (0 when it is not a status line). A fuzz subject.
int parse_status_line(std::string_view line);

struct HttpAnswer {
  int status = 0;
  std::string body;
};

// Sends `method` with `body` (Content-Type: application/json when there is a body or the
// method is POST) and reads the answer, at most `max_body` bytes, within `timeout_ms`
// overall. Errors: kInternal with what went wrong (connect refused, timeout, malformed or
// chunked or oversized answer).
Result<HttpAnswer> http_request(std::string_view method, const HttpUrl& url, std::string_view body,
                                int timeout_ms, size_t max_body = 256 * 1024);
// The same from a URL string (errors of parse_http_url first).
Result<HttpAnswer> http_request(std::string_view method, std::string_view url,
                                std::string_view body, int timeout_ms,
                                size_t max_body = 256 * 1024);
// With request headers (names and values without CR, LF or NUL; others are refused) and,
// for https, a CA file.
struct HttpRequestOptions {
  std::vector<std::pair<std::string, std::string>> headers;
  std::string ca_file;
  size_t max_body = 256 * 1024;
  std::string content_type = "application/json";  // of a body (an RFC 7662 form, say)
  // Set: only the addresses it allows are connected to, judged after the name resolved (the
  // registry's webhooks: public addresses only).
  std::function<bool(const sockaddr*)> allow_address;
};
Result<HttpAnswer> http_request(std::string_view method, const HttpUrl& url, std::string_view body,
                                int timeout_ms, const HttpRequestOptions& opts);
inline Result<HttpAnswer> http_post_json(const HttpUrl& url, const std::string& json_body,
                                         int timeout_ms, size_t max_body = 256 * 1024) {
  return http_request("POST", url, json_body, timeout_ms, max_body);
}

}  // namespace rcan
