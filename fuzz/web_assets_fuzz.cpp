// libFuzzer: the dashboard's file server (src/node/api/web_assets.cpp) on arbitrary request
// lines. Input: "METHOD\nPATH\nIF-NONE-MATCH" (missing parts empty). Must never crash; every
// answer is 200/304/404/405 with the CSP header, a 200 carries exactly the embedded bytes and
// a 304 carries none.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "node/api/web_assets.h"

namespace {

void check(bool cond) {
  if (!cond) std::abort();
}

std::string_view next_line(std::string_view& s) {
  size_t nl = s.find('\n');
  std::string_view line = s.substr(0, nl);
  s = nl == std::string_view::npos ? std::string_view() : s.substr(nl + 1);
  return line;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view in(reinterpret_cast<const char*>(data), size);
  rcan::transport::HttpRequest req;
  req.method = std::string(next_line(in));
  req.path = std::string(next_line(in));
  req.headers.emplace_back("if-none-match", std::string(next_line(in)));
  rcan::transport::HttpResponse r = rcan::node::web_response(req, 0);
  bool csp = false;
  for (const auto& h : r.headers)
    if (h.first == "Content-Security-Policy") csp = h.second == rcan::node::web_csp();
  check(csp);
  const rcan::node::WebAsset* a = rcan::node::find_web_asset(req.path);
  switch (r.status) {
    case 200:
      check(a != nullptr && r.body.size() == a->size &&
            r.body == std::string_view(reinterpret_cast<const char*>(a->data), a->size));
      break;
    case 304:
      check(a != nullptr && r.body.empty());
      break;
    case 404:
      check(a == nullptr);
      break;
    case 405:
      check(req.method != "GET" && req.method != "HEAD");
      break;
    default:
      check(false);
  }
  return 0;
}
