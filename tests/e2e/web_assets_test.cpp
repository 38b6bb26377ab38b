// The embedded dashboard: what is compiled in (every file referenced, no inline script or
// style, no HTML-parsing DOM sinks in the scripts) and how rcand serves it (content types,
// CSP and the other security headers, ETag revalidation, HEAD, 404/405), against a real rcand.
#include "node/api/web_assets.h"

#include <gtest/gtest.h>
#include <signal.h>

#include <regex>
#include <set>
#include <string>

#include "rcan/json.h"
#include "test_support.h"

namespace {

using rcan::node::find_web_asset;
using rcan::node::web_assets;
using rcan::test::HttpReply;

std::string text_of(const rcan::node::WebAsset& a) {
  return std::string(reinterpret_cast<const char*>(a.data), a.size);
}

bool ends_with(const std::string& s, const std::string& suf) {
  return s.size() >= suf.size() && s.compare(s.size() - suf.size(), suf.size(), suf) == 0;
}

TEST(WebAssets, ThePageAndItsFilesAreEmbeddedWithTheirTypes) {
  ASSERT_NE(find_web_asset("/"), nullptr);
  EXPECT_EQ(find_web_asset("/"), find_web_asset("/index.html"));
  EXPECT_EQ(find_web_asset("/"), find_web_asset("/ui/"));
  size_t total = 0;
  for (const auto& a : web_assets()) {
    std::string p = a.path;
    total += a.size;
    EXPECT_GT(a.size, 0u) << p;
    EXPECT_EQ(std::string(a.etag).size(), 18u) << p;  // 16 hex digits, quoted
    std::string want = ends_with(p, ".js")     ? "text/javascript; charset=utf-8"
                       : ends_with(p, ".css")  ? "text/css; charset=utf-8"
                       : ends_with(p, ".html") ? "text/html; charset=utf-8"
                                               : std::string(a.content_type);
    EXPECT_EQ(std::string(a.content_type), want) << p;
    if (p != "/index.html") {
      EXPECT_EQ(find_web_asset("/ui" + p), &a) << p;
    }
  }
  EXPECT_LT(total, 300u * 1024) << "the whole dashboard stays under 300 KB";
}

TEST(WebAssets, EveryReferencedFileExistsAndEveryImportResolves) {
  std::string html = text_of(*find_web_asset("/"));
  std::regex ref(R"re((?:src|href)="(/ui/[^"]+)")re");
  int refs = 0;
  for (std::sregex_iterator it(html.begin(), html.end(), ref), end; it != end; ++it, ++refs)
    EXPECT_NE(find_web_asset((*it)[1].str()), nullptr) << (*it)[1].str();
  EXPECT_GE(refs, 3);
  std::regex imp(R"re(from '\./([a-z_]+\.js)')re");
  for (const auto& a : web_assets()) {
    std::string p = a.path;
    if (!ends_with(p, ".js")) continue;
    std::string js = text_of(a);
    for (std::sregex_iterator it(js.begin(), js.end(), imp), end; it != end; ++it)
      EXPECT_NE(find_web_asset("/ui/js/" + (*it)[1].str()), nullptr)
          << p << " imports " << (*it)[1].str();
  }
}

TEST(WebAssets, NoInlineScriptStyleOrHtmlSinks) {
  std::string html = text_of(*find_web_asset("/"));
  // Every <script> loads a file; no style attributes or <style> blocks; no on* handlers.
  std::regex script(R"re(<script([^>]*)>)re");
  for (std::sregex_iterator it(html.begin(), html.end(), script), end; it != end; ++it)
    EXPECT_NE((*it)[1].str().find("src=\"/ui/"), std::string::npos) << (*it)[0].str();
  EXPECT_EQ(html.find("<style"), std::string::npos);
  EXPECT_FALSE(std::regex_search(html, std::regex(R"re(\sstyle\s*=)re")));
  EXPECT_FALSE(std::regex_search(html, std::regex(R"re(\son[a-z]+\s*=)re")));
  // The scripts never parse HTML from strings: robot-supplied text goes in as text only.
  for (const auto& a : web_assets()) {
    std::string p = a.path;
    if (!ends_with(p, ".js")) continue;
    std::string js = text_of(a);
    for (const char* sink :
         {"innerHTML", "outerHTML", "insertAdjacentHTML", "document.write", "eval(", "new Function",
          "DOMParser", "createContextualFragment", ".style."})
      EXPECT_EQ(js.find(sink), std::string::npos) << p << " uses " << sink;
  }
}

TEST(WebAssets, ResponsesCarryCspEtagAndRevalidate) {
  rcan::transport::HttpRequest req;
  req.method = "GET";
  req.path = "/ui/js/main.js";
  auto r = rcan::node::web_response(req, 1);
  ASSERT_EQ(r.status, 200);
  std::string etag, csp, cache;
  for (const auto& h : r.headers) {
    if (h.first == "ETag") etag = h.second;
    if (h.first == "Content-Security-Policy") csp = h.second;
    if (h.first == "Cache-Control") cache = h.second;
  }
  EXPECT_EQ(csp, rcan::node::web_csp());
  EXPECT_EQ(cache, "no-cache");
  ASSERT_FALSE(etag.empty());
  for (std::string inm : {etag, "\"nope\", " + etag, "W/" + etag, std::string("*")}) {
    req.headers = {{"if-none-match", inm}};
    auto c = rcan::node::web_response(req, 1);
    EXPECT_EQ(c.status, 304) << inm;
    EXPECT_TRUE(c.body.empty());
  }
  for (std::string inm :
       {std::string("\"nope\""), std::string(""), std::string(","), etag.substr(1)}) {
    req.headers = {{"if-none-match", inm}};
    EXPECT_EQ(rcan::node::web_response(req, 1).status, 200) << inm;
  }
  req.headers.clear();
  req.path = "/ui/../index.html";
  EXPECT_EQ(rcan::node::web_response(req, 1).status, 404);
  req.path = "/ui/js/nothing.js";
  EXPECT_EQ(rcan::node::web_response(req, 1).status, 404);
  req.path = "/";
  req.method = "POST";
  auto m = rcan::node::web_response(req, 1);
  EXPECT_EQ(m.status, 405);
  EXPECT_NE(m.body.find("METHOD_NOT_ALLOWED"), std::string::npos);
}

// Against a real rcand: the transport keeps the page's headers and still guards the API.
TEST(WebAssetsRcand, ServedAtRootWithSecurityHeaders) {
  rcan::test::TempDir dir;
  rcan::test::Process proc;
  ASSERT_TRUE(proc.start({RCAND_PATH, "--data-dir", dir.path() + "/node", "--port", "0"}));
  auto line = proc.wait_for_line("\"event\":\"listening\"", 30000);
  ASSERT_TRUE(line) << proc.err();
  auto v = rcan::json::parse(*line);
  ASSERT_TRUE(v.ok());
  std::string url = v->get("url")->as_string();
  auto port = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));

  HttpReply page = rcan::test::http(port, "GET", "/");
  ASSERT_EQ(page.status, 200);
  EXPECT_EQ(page.header("content-type"), "text/html; charset=utf-8");
  EXPECT_EQ(page.header("content-security-policy"), rcan::node::web_csp());
  EXPECT_NE(page.header("content-security-policy").find("frame-ancestors 'none'"),
            std::string::npos);
  EXPECT_EQ(page.header("x-content-type-options"), "nosniff");
  EXPECT_EQ(page.header("x-frame-options"), "DENY");
  EXPECT_EQ(page.header("referrer-policy"), "no-referrer");
  EXPECT_EQ(page.header("cache-control"), "no-cache");
  EXPECT_EQ(page.body, text_of(*find_web_asset("/")));
  std::string etag = page.header("etag");
  ASSERT_FALSE(etag.empty());

  HttpReply again = rcan::test::http(port, "GET", "/", "", {{"If-None-Match", etag}});
  EXPECT_EQ(again.status, 304);
  EXPECT_TRUE(again.body.empty());

  // HEAD: the headers of the GET, no body (read raw: the test client expects a body after a
  // Content-Length).
  {
    rcan::test::HttpClient c(port);
    ASSERT_TRUE(c.connected());
    std::string raw =
        c.raw("HEAD /ui/js/main.js HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n", 5000);
    EXPECT_EQ(raw.rfind("HTTP/1.1 200", 0), 0u) << raw;
    EXPECT_NE(raw.find("Content-Type: text/javascript; charset=utf-8"), std::string::npos) << raw;
    EXPECT_NE(raw.find("Content-Length: " + std::to_string(find_web_asset("/ui/js/main.js")->size)),
              std::string::npos)
        << raw;
    EXPECT_TRUE(raw.substr(raw.find("\r\n\r\n") + 4).empty()) << raw;
  }

  HttpReply css = rcan::test::http(port, "GET", "/ui/css/app.css");
  EXPECT_EQ(css.status, 200);
  EXPECT_EQ(css.header("content-type"), "text/css; charset=utf-8");

  HttpReply missing = rcan::test::http(port, "GET", "/ui/secret.txt");
  EXPECT_EQ(missing.status, 404);
  EXPECT_NE(missing.body.find("NOT_FOUND"), std::string::npos);
  EXPECT_EQ(rcan::test::http(port, "DELETE", "/").status, 405);

  // The API keeps its own caching rule (never stored).
  HttpReply health = rcan::test::http(port, "GET", "/healthz");
  EXPECT_EQ(health.status, 200);
  EXPECT_EQ(health.header("cache-control"), "no-store");
  // The dashboard is no back door: the same API still wants a token.
  EXPECT_EQ(rcan::test::http(port, "GET", "/api/audit").status, 401);
  EXPECT_EQ(proc.stop(SIGTERM, 15000), 0);
}

}  // namespace
