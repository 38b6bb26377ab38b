// Serving the embedded dashboard (web_assets.h).
#include "node/api/web_assets.h"

#include <string>

#include "node/api/route_table.h"
#include "rcan/errors.h"

namespace rcan::node {

namespace {

constexpr std::string_view kCsp =
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; font-src 'self'; manifest-src 'self'; base-uri 'none'; form-action "
    "'none'; "
    "frame-ancestors 'none'; object-src 'none'";

bool starts_with(std::string_view s, std::string_view p) { return s.substr(0, p.size()) == p; }

// If-None-Match holds a list of entity tags (or *); a weak match is enough for GET.
bool etag_matches(std::string_view header, std::string_view etag) {
  if (header.empty()) return false;
  size_t i = 0;
  while (i < header.size()) {
    while (i < header.size() && (header[i] == ' ' || header[i] == ',' || header[i] == '\t')) ++i;
    size_t j = header.find(',', i);
    std::string_view tag =
        header.substr(i, j == std::string_view::npos ? std::string_view::npos : j - i);
    while (!tag.empty() && (tag.back() == ' ' || tag.back() == '\t')) tag.remove_suffix(1);
    if (tag == "*") return true;
    if (starts_with(tag, "W/")) tag.remove_prefix(2);
    if (!tag.empty() && tag == etag) return true;
    if (j == std::string_view::npos) break;
    i = j + 1;
  }
  return false;
}

void security_headers(transport::HttpResponse& r) {
  r.headers.emplace_back("Content-Security-Policy", std::string(kCsp));
  r.headers.emplace_back("X-Frame-Options", "DENY");
  r.headers.emplace_back("Referrer-Policy", "no-referrer");
  r.headers.emplace_back("Cross-Origin-Opener-Policy", "same-origin");
  r.headers.emplace_back("Cross-Origin-Resource-Policy", "same-origin");
  r.headers.emplace_back("Permissions-Policy",
                         "camera=(), microphone=(), geolocation=(), payment=()");
}

}  // namespace

std::string_view web_csp() { return kCsp; }

bool is_web_path(std::string_view p) {
  return p == "/" || p == "/index.html" || p == "/ui" || starts_with(p, "/ui/") ||
         p == "/favicon.ico";
}

const WebAsset* find_web_asset(std::string_view p) {
  std::string_view file;
  if (p == "/" || p == "/index.html" || p == "/ui" || p == "/ui/") {
    file = "/index.html";
  } else if (p == "/favicon.ico") {
    file = "/favicon.svg";
  } else if (starts_with(p, "/ui/")) {
    file = p.substr(3);
    // The table is closed (only embedded names match), but refuse traversal-looking names early.
    if (file.find("..") != std::string_view::npos || file.find('\\') != std::string_view::npos)
      return nullptr;
  } else {
    return nullptr;
  }
  for (const WebAsset& a : web_assets())
    if (file == a.path) return &a;
  return nullptr;
}

transport::HttpResponse web_response(const transport::HttpRequest& req, int64_t now_ms) {
  transport::HttpResponse r;
  if (req.method != "GET" && req.method != "HEAD") {
    r = RouteTable::method_not_allowed(
        error_body(Error(ErrorCode::kMethodNotAllowed, req.method + " is not allowed on /ui"), "",
                   now_ms),
        "GET, HEAD");
    security_headers(r);
    return r;
  }
  security_headers(r);
  const WebAsset* a = find_web_asset(req.path);
  if (!a) {
    r.status = 404;
    r.body = json::dump(error_body(
        Error(ErrorCode::kNotFound, "no dashboard file " + req.path.substr(0, 128)), "", now_ms));
    return r;
  }
  // Revalidate every time (cheap: 304 with no body), so a new rcand never serves a stale page.
  r.headers.emplace_back("Cache-Control", "no-cache");
  r.headers.emplace_back("ETag", a->etag);
  if (etag_matches(req.header("if-none-match"), a->etag)) {
    r.status = 304;
    r.content_type.clear();
    return r;
  }
  r.content_type = a->content_type;
  r.body.assign(reinterpret_cast<const char*>(a->data), a->size);
  return r;
}

}  // namespace rcan::node
