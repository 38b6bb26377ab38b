// Request parsing helpers shared by the HTTP server and the request fuzzer: the mapping of
// Beast parser errors to the project's error answers, the Beast message → HttpRequest
// conversion (percent-decoding of path and query, lower-cased header names) and the
// WebSocket upgrade checks. Header-only so that fuzz/http_request_fuzz.cpp (which links only
// librcan) runs exactly this code. Includes Beast: include it only from src/transport/*.cpp
// and fuzz targets.
//
// Transport-level answers (docs/TRANSPORT.md):
//   400 MALFORMED_JSON            unparsable request line / header / chunking, bad target,
//                                 invalid percent-encoding, a malformed WebSocket upgrade,
//                                 a Transfer-Encoding other than exactly "chunked" (also in
//                                 HTTP/1.0 or with Content-Length), obs-fold (check_framing)
//   408 SCHEMA_VALIDATION_FAILED  the whole request did not arrive within read_timeout_ms
//                                 (reason "read_timeout")
//   413 BODY_TOO_LARGE            Content-Length or chunked body over max_body_bytes
//   426 SCHEMA_VALIDATION_FAILED  WebSocket upgrade with Sec-WebSocket-Version other than 13
//   431 SCHEMA_VALIDATION_FAILED  request line + headers over max_header_bytes
//                                 (message "request headers too large")
//   503 RATE_LIMITED              over max_connections (reason "too_many_connections"), over
//                                 max_connections_per_address
//                                 ("too_many_connections_from_address"), a request other than a
//                                 stop on a reserve connection ("reserve_for_stop_only")
// The error catalogue has no dedicated code for 408/431/503-at-the-socket; the codes above
// are the closest generic ones and `reason` says exactly what happened.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "base/clock.h"
#include "base/strings.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "transport/beast.h"
#include "transport/http_api.h"

namespace rcan::transport::detail {

namespace beast = boost::beast;
namespace http = boost::beast::http;

// A failure the transport answers itself.
struct TransportError {
  int status = 400;
  ErrorCode code = ErrorCode::kMalformedJson;
  std::string_view reason;   // machine-readable, e.g. "body_too_large"
  std::string_view message;  // one sentence
};

inline TransportError bad_request(std::string_view reason, std::string_view message) {
  return {400, ErrorCode::kMalformedJson, reason, message};
}
inline TransportError read_timeout_error() {
  return {408, ErrorCode::kSchemaValidationFailed, "read_timeout",
          "request not received within the read timeout"};
}
inline TransportError body_too_large_error() {
  return {413, ErrorCode::kBodyTooLarge, "body_too_large", "request body too large"};
}
inline TransportError headers_too_large_error() {
  return {431, ErrorCode::kSchemaValidationFailed, "headers_too_large",
          "request headers too large"};
}
inline TransportError too_many_connections_error() {
  return {503, ErrorCode::kRateLimited, "too_many_connections", "too many connections"};
}
inline TransportError too_many_from_address_error() {
  return {503, ErrorCode::kRateLimited, "too_many_connections_from_address",
          "too many connections from this address"};
}
inline TransportError reserve_only_error() {
  return {503, ErrorCode::kRateLimited, "reserve_for_stop_only",
          "the server is at its connection limit: only a stop request is served now"};
}
inline TransportError shutting_down_error() {
  return {503, ErrorCode::kRateLimited, "shutting_down", "server is shutting down"};
}

// The JSON error body for `err` (the project's single error body, rcan/errors.h).
inline std::string error_json(const TransportError& err) {
  const auto now = unix_ms();
  Error e(err.code, std::string(err.message), {}, std::string(err.reason));
  return json::dump(error_body(e, {}, static_cast<int64_t>(now)));
}

// Maps an error from reading a request to the answer, or nullopt when there is nobody to
// answer (peer closed, reset, cancelled).
inline std::optional<TransportError> classify_read_error(const beast::error_code& ec) {
  if (ec == http::error::body_limit) return body_too_large_error();
  if (ec == http::error::header_limit) return headers_too_large_error();
  if (ec == http::error::end_of_stream || ec == http::error::partial_message) return std::nullopt;
  if (ec == http::error::buffer_overflow)
    return bad_request("line_too_long", "request line or chunk header too long");
  if (ec == http::error::bad_transfer_encoding)
    return bad_request("bad_transfer_encoding", "Transfer-Encoding other than chunked");
  if (ec.category() == http::make_error_code(http::error::bad_method).category())
    return bad_request("bad_request", "malformed HTTP request");
  return std::nullopt;
}

inline int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// Decodes %XX escapes (and '+' as space when `plus_is_space`). False on a truncated or
// non-hex escape or an encoded NUL.
inline bool percent_decode(std::string_view in, bool plus_is_space, std::string& out) {
  out.clear();
  out.reserve(in.size());
  for (size_t i = 0; i < in.size(); ++i) {
    const char c = in[i];
    if (c == '%') {
      if (i + 2 >= in.size()) return false;
      const int hi = hex_value(in[i + 1]);
      const int lo = hex_value(in[i + 2]);
      if (hi < 0 || lo < 0) return false;
      const char d = static_cast<char>((hi << 4) | lo);
      if (d == '\0') return false;
      out.push_back(d);
      i += 2;
    } else if (c == '+' && plus_is_space) {
      out.push_back(' ');
    } else {
      out.push_back(c);
    }
  }
  return true;
}

// Splits a request target into the decoded path and query parameters. Accepts origin-form
// ("/a/b?x=1"), absolute-form ("http://host/a?x=1") and "*".
inline std::optional<TransportError> split_target(
    std::string_view target, std::string& path,
    std::vector<std::pair<std::string, std::string>>& query) {
  path.clear();
  query.clear();
  if (target == "*") {
    path = "*";
    return std::nullopt;
  }
  std::string_view t = target;
  std::string rebuilt;
  for (std::string_view scheme : {std::string_view("http://"), std::string_view("https://")}) {
    if (t.size() >= scheme.size()) {
      bool match = true;
      for (size_t i = 0; i < scheme.size(); ++i) {
        char ch = t[i];
        if (ch >= 'A' && ch <= 'Z') ch = static_cast<char>(ch - 'A' + 'a');
        if (ch != scheme[i]) {
          match = false;
          break;
        }
      }
      if (match) {
        t.remove_prefix(scheme.size());
        const size_t slash = t.find_first_of("/?");
        if (slash == std::string_view::npos) {
          t = "/";
        } else if (t[slash] == '?') {
          // "http://host?x" → path "/" with the query.
          rebuilt = "/";
          rebuilt.append(t.substr(slash));
          t = rebuilt;
        } else {
          t.remove_prefix(slash);
        }
        break;
      }
    }
  }
  if (t.empty() || t.front() != '/')
    return bad_request("bad_target", "request target must be a path");
  const size_t q = t.find('?');
  const std::string_view raw_path = t.substr(0, q);
  if (!percent_decode(raw_path, false, path))
    return bad_request("bad_percent_encoding", "invalid percent-encoding in the path");
  if (q == std::string_view::npos) return std::nullopt;
  std::string_view rest = t.substr(q + 1);
  std::string k, v;
  while (!rest.empty()) {
    const size_t amp = rest.find('&');
    const std::string_view part = rest.substr(0, amp);
    rest = amp == std::string_view::npos ? std::string_view() : rest.substr(amp + 1);
    if (part.empty()) continue;
    const size_t eq = part.find('=');
    if (!percent_decode(part.substr(0, eq), true, k) ||
        !percent_decode(eq == std::string_view::npos ? std::string_view() : part.substr(eq + 1),
                        true, v))
      return bad_request("bad_percent_encoding", "invalid percent-encoding in the query");
    query.emplace_back(std::move(k), std::move(v));
  }
  return std::nullopt;
}

// True when the comma-separated header value contains `token` (case-insensitive).
inline bool has_token(std::string_view value, std::string_view token) {
  while (!value.empty()) {
    const size_t comma = value.find(',');
    const std::string_view part = trim(value.substr(0, comma), " \t");
    value = comma == std::string_view::npos ? std::string_view() : value.substr(comma + 1);
    if (part.size() != token.size()) continue;
    bool eq = true;
    for (size_t i = 0; i < part.size() && eq; ++i) {
      char a = part[i];
      char b = token[i];
      if (a >= 'A' && a <= 'Z') a = static_cast<char>(a - 'A' + 'a');
      if (b >= 'A' && b <= 'Z') b = static_cast<char>(b - 'A' + 'a');
      eq = a == b;
    }
    if (eq) return true;
  }
  return false;
}

// Request framing by RFC 9112, where Beast 1.81 is lenient: it reads a Transfer-Encoding whose
// last coding is not "chunked" ("xchunked", "chunked, identity") as no body at all, so that the
// body is parsed as a second request (smuggling past any proxy that frames it otherwise), takes
// chunked in HTTP/1.0, and unfolds obs-fold. Any of these is 400 and the connection closed
// (§6.3 point 4, §6.1, §5.2). A Transfer-Encoding with a Content-Length is 400 too (§6.3 point
// 3, the strict choice): the parser refuses chunked with one in either order, and any other
// coding is refused here. `header_block` is the raw bytes the parser consumed for the header
// (from the request line; what follows the empty line is ignored), `header` the parsed header.
inline std::optional<TransportError> check_header_block(std::string_view header_block) {
  if (const size_t end = header_block.find("\r\n\r\n"); end != std::string_view::npos)
    header_block = header_block.substr(0, end + 2);
  for (size_t eol = header_block.find("\r\n");
       eol != std::string_view::npos && eol + 2 < header_block.size();
       eol = header_block.find("\r\n", eol + 2)) {
    const char next = header_block[eol + 2];
    if (next == ' ' || next == '\t')
      return bad_request("obs_fold", "obsolete line folding in a header field");
  }
  return std::nullopt;
}

template <class Header>
std::optional<TransportError> check_framing(const Header& header) {
  size_t te_fields = 0;
  std::string_view te;
  for (const auto& f : header) {
    if (f.name() != http::field::transfer_encoding) continue;
    ++te_fields;
    te = f.value();
  }
  if (te_fields == 0) return std::nullopt;
  while (!te.empty() && (te.front() == ' ' || te.front() == '\t')) te.remove_prefix(1);
  while (!te.empty() && (te.back() == ' ' || te.back() == '\t')) te.remove_suffix(1);
  if (te_fields != 1 || !beast::iequals(te, "chunked"))
    return bad_request("bad_transfer_encoding", "Transfer-Encoding other than chunked");
  if (header.version() < 11)
    return bad_request("bad_transfer_encoding", "Transfer-Encoding in an HTTP/1.0 request");
  return std::nullopt;  // chunked with a Content-Length: the parser has refused it already
}

// Converts a parsed message (the body is moved out). Fails on a bad target.
template <class Fields>
std::optional<TransportError> to_http_request(http::request<http::string_body, Fields>& msg,
                                              std::string remote_addr, bool tls, HttpRequest& out) {
  out.method = std::string(msg.method_string());
  out.target = std::string(msg.target());
  if (auto err = split_target(out.target, out.path, out.query)) return err;
  out.headers.clear();
  for (const auto& f : msg)
    out.headers.emplace_back(ascii_lower(f.name_string()), std::string(f.value()));
  out.body = std::move(msg.body());
  out.remote_addr = std::move(remote_addr);
  out.tls = tls;
  return std::nullopt;
}

// True when the request asks for a WebSocket (an Upgrade header naming "websocket").
inline bool wants_websocket(const HttpRequest& req) {
  return has_token(req.header("upgrade"), "websocket");
}

// Checks an upgrade request the way RFC 6455 §4.2.1 asks, before the node sees it.
inline std::optional<TransportError> check_websocket_upgrade(const HttpRequest& req,
                                                             unsigned http_version) {
  if (req.method != "GET" || http_version < 11)
    return bad_request("bad_upgrade", "WebSocket upgrade must be an HTTP/1.1 GET");
  if (!has_token(req.header("connection"), "upgrade"))
    return bad_request("bad_upgrade", "WebSocket upgrade without Connection: upgrade");
  const std::string_view key = req.header("sec-websocket-key");
  // base64 of 16 bytes: 22 characters and "==".
  bool key_ok = key.size() == 24 && key.substr(22) == "==";
  for (size_t i = 0; key_ok && i < 22; ++i) {
    const char c = key[i];
    key_ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
             c == '+' || c == '/';
  }
  if (!key_ok) return bad_request("bad_upgrade", "missing or malformed Sec-WebSocket-Key");
  if (req.header("sec-websocket-version") != "13")
    return TransportError{426, ErrorCode::kSchemaValidationFailed, "bad_websocket_version",
                          "unsupported Sec-WebSocket-Version (13 is supported)"};
  return std::nullopt;
}

// Configures a request parser with the server's limits.
template <class Parser>
void apply_limits(Parser& parser, size_t max_header_bytes, size_t max_body_bytes) {
  parser.header_limit(
      static_cast<std::uint32_t>(max_header_bytes > UINT32_MAX ? UINT32_MAX : max_header_bytes));
  parser.body_limit(static_cast<std::uint64_t>(max_body_bytes));
}

// The outcome of parsing a byte string as one request (the fuzzer's entry point; the server
// runs the same parser, limits, classification and conversion over a socket).
struct ParseOutcome {
  enum class Kind { kRequest, kNeedMore, kError, kSilent } kind = Kind::kNeedMore;
  HttpRequest request;     // kRequest
  TransportError error;    // kError
  std::string error_body;  // kError
  bool websocket = false;  // kRequest wanting an upgrade (check already applied)
  size_t consumed = 0;     // bytes of `bytes` used by this request
};

inline ParseOutcome parse_request_bytes(std::string_view bytes, size_t max_header_bytes,
                                        size_t max_body_bytes) {
  ParseOutcome out;
  http::request_parser<http::string_body> parser;
  apply_limits(parser, max_header_bytes, max_body_bytes);
  parser.eager(true);
  beast::error_code ec;
  size_t used = 0;
  std::optional<TransportError> framing;
  while (!parser.is_done() && used < bytes.size()) {
    const bool had_header = parser.is_header_done();
    const size_t n =
        parser.put(boost::asio::const_buffer(bytes.data() + used, bytes.size() - used), ec);
    if (!had_header && parser.is_header_done()) {
      // The parser takes the header whole: these bytes start at the request line.
      framing = check_header_block(bytes.substr(used, n));
      if (!framing) framing = check_framing(parser.get());
      if (framing) {
        out.consumed = used + n;
        out.kind = ParseOutcome::Kind::kError;
        out.error = *framing;
        out.error_body = error_json(*framing);
        return out;
      }
    }
    used += n;
    if (ec == http::error::need_more) {
      ec = {};
      if (n == 0) break;  // the rest is an incomplete element
      continue;
    }
    if (ec) break;
    if (n == 0) break;
  }
  out.consumed = used;
  if (ec) {
    if (auto err = classify_read_error(ec)) {
      out.kind = ParseOutcome::Kind::kError;
      out.error = *err;
      out.error_body = error_json(*err);
    } else {
      out.kind = ParseOutcome::Kind::kSilent;
    }
    return out;
  }
  if (!parser.is_done()) return out;  // kNeedMore
  auto msg = parser.release();
  const unsigned version = msg.version();
  if (auto err = to_http_request(msg, "127.0.0.1:1", false, out.request)) {
    out.kind = ParseOutcome::Kind::kError;
    out.error = *err;
    out.error_body = error_json(*err);
    return out;
  }
  if (wants_websocket(out.request)) {
    out.websocket = true;
    if (auto err = check_websocket_upgrade(out.request, version)) {
      out.kind = ParseOutcome::Kind::kError;
      out.error = *err;
      out.error_body = error_json(*err);
      return out;
    }
  }
  out.kind = ParseOutcome::Kind::kRequest;
  return out;
}

}  // namespace rcan::transport::detail
