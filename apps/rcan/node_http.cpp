// The small HTTP helpers of node_http.h, on the client library (include/rcan/client.h):
// http and https URLs, one request per call.
#include "node_http.h"

#include <cstdlib>

#include "client/net.h"
#include "rcan/client.h"
#include "rcan/errors.h"

namespace rcan::cli {

Result<Target> parse_url(const std::string& url) {
  auto ep = client::parse_endpoint(url);
  if (!ep.ok()) return Error(ErrorCode::kSchemaValidationFailed, ep.error().message);
  Target t;
  t.host = ep->url();  // the whole base URL: request() hands it to the client library
  t.port = std::to_string(ep->port);
  return t;
}

Result<std::pair<int, std::string>> request(const Target& t, const std::string& method,
                                            const std::string& path, const std::string& body,
                                            const std::string& token) {
  client::ClientOptions co;
  co.url = t.host;
  co.token = token;
  client::Client c(co);
  auto r = c.request(method, path, body, !token.empty());
  if (!r.ok()) return Error(ErrorCode::kNotFound, r.error().message);
  return std::make_pair(r->status, r->body);
}

std::string secret_from(const Options& o, const std::string& option, const char* env, bool required,
                        std::string& err) {
  std::string file = o.get(option);
  if (file.empty())
    if (const char* e = std::getenv(env)) file = e;
  if (file.empty()) {
    if (required)
      err = "a " + std::string(option == "token-file" ? "token" : "key") + " is required: --" +
            option + " F or " + env;
    return {};
  }
  auto t = read_file(file);
  if (!t.ok()) {
    err = t.error().message;
    return {};
  }
  std::string s = *t;
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  return s;
}

std::string token_from(const Options& o, bool required, std::string& err) {
  return secret_from(o, "token-file", "RCAN_TOKEN_FILE", required, err);
}

std::string node_url(const Options& o) {
  std::string url = o.get("url");
  if (url.empty())
    if (const char* env = std::getenv("RCAN_URL")) url = env;
  return url.empty() ? "http://127.0.0.1:8080" : url;
}

std::string node_token(const Options& o, bool required, std::string& err) {
  return token_from(o, required, err);
}

Result<std::pair<int, std::string>> node_request(const std::string& url, const std::string& method,
                                                 const std::string& path, const std::string& body,
                                                 const std::string& token) {
  auto t = parse_url(url);
  if (!t.ok()) return t.error();
  return request(*t, method, path, body, token);
}

Result<std::pair<int, std::string>> node_request(
    const std::string& url, const std::string& method, const std::string& path,
    const std::string& body, const std::string& token,
    const std::vector<std::pair<std::string, std::string>>& headers) {
  if (headers.empty()) return node_request(url, method, path, body, token);
  auto ep = client::parse_endpoint(url);
  if (!ep.ok()) return Error(ErrorCode::kSchemaValidationFailed, ep.error().message);
  auto h = headers;
  if (!token.empty()) h.emplace_back("Authorization", "Bearer " + token);
  auto r = client::net::http_exchange(*ep, method, path, body, h, 10'000, "", false);
  if (!r.ok()) return Error(ErrorCode::kNotFound, r.error().message);
  return std::make_pair(r->status, r->body);
}

}  // namespace rcan::cli
