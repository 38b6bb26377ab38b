// The operator dashboard's static files, compiled into the node (web/ → a generated source,
// cmake/embed_web.cmake), and how they are served: `/` is the page, `/ui/<file>` the rest.
// docs/DASHBOARD.md describes the page and its security headers.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "transport/http_api.h"

namespace rcan::node {

struct WebAsset {
  const char* path;          // "/index.html", "/js/main.js", … (relative to web/)
  const char* content_type;  // with charset for text
  const char* etag;          // strong ETag, quoted
  const unsigned char* data;
  size_t size;
};

// Every embedded file (generated at build time).
std::span<const WebAsset> web_assets();

// The asset a request path names: "/" (and "/ui/", "/index.html") is the page, "/ui/<file>"
// a file under web/. nullptr when there is none.
const WebAsset* find_web_asset(std::string_view request_path);

// True for the paths the dashboard owns ("/", "/index.html", "/ui", "/ui/…").
bool is_web_path(std::string_view request_path);

// The response for a dashboard path: 200 with the file and its headers (CSP, ETag, …), 304 when
// If-None-Match matches, 404 for an unknown file, 405 for a method other than GET/HEAD.
transport::HttpResponse web_response(const transport::HttpRequest& req, int64_t now_ms);

// The Content-Security-Policy every dashboard response carries.
std::string_view web_csp();

}  // namespace rcan::node
