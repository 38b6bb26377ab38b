#include "runtime/http_client.h"

#include <cstring>

#include "client/net.h"
#include "rcan/errors.h"

namespace rcan {
namespace {

Error fail(const std::string& what) { return Error(ErrorCode::kInternal, what); }

// The node's wording of a failed exchange (these messages reach audit records, logs and, for
// a brain layer, the refusal of the escalated command).
Error describe(const client::net::ExchangeFailure& f, const HttpUrl& url, int timeout_ms) {
  using client::net::FailedAt;
  const std::string where = url.host + ":" + std::to_string(url.port);
  switch (f.at) {
    case FailedAt::kResolve:
      return fail("cannot resolve " + url.host);
    case FailedAt::kAddress:
      return fail("refused: " + url.host + " resolves to no allowed address");
    case FailedAt::kConnect:
      if (f.timed_out) return fail("connect to " + where + " timed out");
      return fail("connect to " + where + " failed: " + std::strerror(f.sys_error));
    case FailedAt::kSend:
      return fail(f.timed_out ? "send timed out" : "send failed");
    case FailedAt::kReceive:
      if (f.timed_out) return fail("no answer within " + std::to_string(timeout_ms) + " ms");
      return fail("receive failed");
    case FailedAt::kNoAnswer:
      return fail("no answer");
    case FailedAt::kTooLarge:
      return fail("answer too large");
    case FailedAt::kChunked:
      return fail("chunked answers are not supported");
    case FailedAt::kTls:
      return fail("TLS with " + where + " failed" + (f.timed_out ? " (timed out)" : ""));
    case FailedAt::kNone:
    case FailedAt::kMalformed:
      break;
  }
  return fail("malformed HTTP answer");
}

}  // namespace

Result<HttpUrl> parse_http_url(std::string_view url) {
  constexpr std::string_view kScheme = "http://";
  auto bad = [](const char* why) { return Error(ErrorCode::kSchemaValidationFailed, why, "url"); };
  if (url.substr(0, kScheme.size()) != kScheme || url.size() > 2048)
    return bad("only http:// URLs are supported");
  std::string_view rest = url.substr(kScheme.size());
  size_t slash = rest.find('/');
  std::string_view authority = rest.substr(0, slash);
  HttpUrl u;
  if (slash != std::string_view::npos) u.path = std::string(rest.substr(slash));
  size_t colon = authority.rfind(':');
  if (colon != std::string_view::npos) {
    std::string_view ps = authority.substr(colon + 1);
    if (ps.empty() || ps.size() > 5) return bad("bad port");
    uint32_t p = 0;
    for (char c : ps) {
      if (c < '0' || c > '9') return bad("bad port");
      p = p * 10 + static_cast<uint32_t>(c - '0');
    }
    if (p < 1 || p > 65535) return bad("bad port");
    u.port = static_cast<uint16_t>(p);
    u.host = std::string(authority.substr(0, colon));
  } else {
    u.host = std::string(authority);
  }
  if (u.host.empty()) return bad("no host");
  for (char c : u.host)
    if (static_cast<unsigned char>(c) <= ' ' || c == '@' || c == '/' || c == 0x7f)
      return bad("bad host");
  for (char c : u.path)
    if (static_cast<unsigned char>(c) <= ' ' || c == 0x7f) return bad("bad path");
  return u;
}

Result<HttpUrl> parse_web_url(std::string_view url) {
  constexpr std::string_view kTls = "https://";
  if (url.substr(0, kTls.size()) != kTls) return parse_http_url(url);
  std::string plain = "http://" + std::string(url.substr(kTls.size()));
  auto u = parse_http_url(plain);
  if (!u.ok()) return u.error();
  std::string_view rest = url.substr(kTls.size());
  if (rest.substr(0, rest.find('/')).find(':') == std::string_view::npos) u->port = 443;
  u->tls = true;
  return u;
}

int parse_status_line(std::string_view line) {
  if (line.size() < 12 || line.substr(0, 7) != "HTTP/1." || line[8] != ' ') return 0;
  int code = 0;
  for (size_t i = 9; i < 12; ++i) {
    if (line[i] < '0' || line[i] > '9') return 0;
    code = code * 10 + (line[i] - '0');
  }
  if (line.size() > 12 && line[12] != ' ' && line[12] != '\r') return 0;
  return code >= 100 && code <= 599 ? code : 0;
}

Result<HttpAnswer> http_request(std::string_view method, std::string_view url,
                                std::string_view body, int timeout_ms, size_t max_body) {
  auto u = parse_http_url(url);
  if (!u.ok()) return u.error();
  return http_request(method, *u, body, timeout_ms, max_body);
}

Result<HttpAnswer> http_request(std::string_view method, const HttpUrl& url, std::string_view body,
                                int timeout_ms, size_t max_body) {
  HttpRequestOptions o;
  o.max_body = max_body;
  return http_request(method, url, body, timeout_ms, o);
}

Result<HttpAnswer> http_request(std::string_view method, const HttpUrl& url, std::string_view body,
                                int timeout_ms, const HttpRequestOptions& o) {
  auto clean = [](const std::string& v) {
    return v.find_first_of(std::string_view("\r\n\0", 3)) == std::string::npos;
  };
  std::string port = std::to_string(url.port);
  std::string req = std::string(method) + " " + url.path + " HTTP/1.1\r\nHost: " + url.host + ":" +
                    port +
                    "\r\nAccept: application/json\r\nConnection: close\r\nUser-Agent: rcand\r\n";
  for (const auto& [name, value] : o.headers) {
    if (name.empty() || !clean(name) || !clean(value) || name.find(':') != std::string::npos)
      return Error(ErrorCode::kSchemaValidationFailed, "a request header holds CR, LF or NUL",
                   "headers");
    req += name + ": " + value + "\r\n";
  }
  if (!body.empty() || method == "POST" || method == "PATCH") {
    if (!clean(o.content_type))
      return Error(ErrorCode::kSchemaValidationFailed, "the content type holds CR, LF or NUL",
                   "content_type");
    req += "Content-Type: " + o.content_type +
           "\r\nContent-Length: " + std::to_string(body.size()) + "\r\n";
  }
  req += "\r\n";
  req.append(body);
  client::Endpoint ep;
  ep.host = url.host;
  ep.port = url.port;
  ep.tls = url.tls;
  client::net::ExchangeOptions opts;
  opts.timeout_ms = timeout_ms;
  opts.max_body = o.max_body;
  opts.refuse_chunked = true;
  opts.ca_file = o.ca_file;
  opts.allow_address = o.allow_address;
  client::net::ExchangeFailure failure;
  auto r = client::net::exchange(ep, req, opts, &failure);
  if (!r.ok()) return describe(failure, url, timeout_ms);
  HttpAnswer a;
  a.status = r->status;
  a.body = std::move(r->body);
  return a;
}

}  // namespace rcan
