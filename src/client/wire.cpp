#include "client/wire.h"

#include <openssl/evp.h>

#include <cctype>
#include <cstring>

#include "base/strings.h"
#include "rcan/encoding.h"

namespace rcan::client::wire {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

bool parse_size(std::string_view s, int base, uint64_t& out) {
  if (s.empty() || s.size() > 16) return false;
  uint64_t v = 0;
  for (char c : s) {
    int d;
    if (c >= '0' && c <= '9')
      d = c - '0';
    else if (base == 16 && c >= 'a' && c <= 'f')
      d = c - 'a' + 10;
    else if (base == 16 && c >= 'A' && c <= 'F')
      d = c - 'A' + 10;
    else
      return false;
    v = v * static_cast<uint64_t>(base) + static_cast<uint64_t>(d);
  }
  out = v;
  return true;
}

// Decodes a chunked body starting at `pos`. kComplete sets `end` past the trailer.
Parse dechunk(std::string_view buf, size_t pos, std::string& body, size_t& end, std::string& error,
              size_t max_body) {
  body.clear();
  while (true) {
    size_t eol = buf.find("\r\n", pos);
    if (eol == std::string_view::npos) {
      if (buf.size() - pos > 1024) {
        error = "chunk size line too long";
        return Parse::kError;
      }
      return Parse::kIncomplete;
    }
    std::string_view line = buf.substr(pos, eol - pos);
    if (auto semi = line.find(';'); semi != std::string_view::npos) line = line.substr(0, semi);
    uint64_t n = 0;
    if (!parse_size(trim(line), 16, n)) {
      error = "bad chunk size";
      return Parse::kError;
    }
    pos = eol + 2;
    if (n == 0) {
      // Trailer fields until an empty line.
      while (true) {
        size_t e = buf.find("\r\n", pos);
        if (e == std::string_view::npos) return Parse::kIncomplete;
        if (e == pos) {
          end = e + 2;
          return Parse::kComplete;
        }
        if (e - pos > kMaxHeaderBytes) {
          error = "trailer too long";
          return Parse::kError;
        }
        pos = e + 2;
      }
    }
    if (n > max_body || body.size() + n > max_body) {
      error = "body too large";
      return Parse::kError;
    }
    if (buf.size() - pos < n + 2) return Parse::kIncomplete;
    body.append(buf.substr(pos, n));
    pos += n;
    if (buf.substr(pos, 2) != "\r\n") {
      error = "chunk not followed by CRLF";
      return Parse::kError;
    }
    pos += 2;
  }
}

// A response head (no blank line): the status line and the header fields, names lower-cased.
bool parse_head(std::string_view head, ParsedResponse& out, std::string& error) {
  size_t line_end = head.find("\r\n");
  std::string_view status_line = head.substr(0, line_end);
  if (status_line.size() < 12 || status_line.substr(0, 7) != "HTTP/1." || status_line[8] != ' ') {
    error = "not an HTTP/1.x status line";
    return false;
  }
  uint64_t code = 0;
  if (!parse_size(status_line.substr(9, 3), 10, code) || code < 100 || code > 599 ||
      (status_line.size() > 12 && status_line[12] != ' ')) {
    error = "bad status code";
    return false;
  }
  out = ParsedResponse{};
  out.status = static_cast<int>(code);
  size_t pos = line_end == std::string_view::npos ? head.size() : line_end + 2;
  while (pos < head.size()) {
    size_t e = head.find("\r\n", pos);
    std::string_view line =
        head.substr(pos, e == std::string_view::npos ? std::string_view::npos : e - pos);
    pos = e == std::string_view::npos ? head.size() : e + 2;
    size_t colon = line.find(':');
    if (colon == std::string_view::npos || colon == 0) {
      error = "malformed header field";
      return false;
    }
    out.headers.emplace_back(ascii_lower(line.substr(0, colon)),
                             std::string(trim(line.substr(colon + 1))));
  }
  return true;
}

// The body after a final head: none (204, 304, 101), chunked, Content-Length, or up to the end
// of the connection.
Parse parse_body(std::string_view buf, bool eof, size_t body_start, ParsedResponse& out,
                 size_t& consumed, std::string& error, size_t max_body) {
  bool chunked = false;
  bool have_length = false;
  uint64_t length = 0;
  for (const auto& [k, v] : out.headers) {
    if (k == "transfer-encoding" && ascii_lower(v).find("chunked") != std::string::npos)
      chunked = true;
    if (k == "content-length") {
      uint64_t n = 0;
      if (!parse_size(trim(v), 10, n) || (have_length && n != length)) {
        error = "bad Content-Length";
        return Parse::kError;
      }
      have_length = true;
      length = n;
    }
  }
  if (out.status == 204 || out.status == 304 || out.status == 101) {
    consumed = body_start;
    return Parse::kComplete;
  }
  if (chunked) {
    size_t end = 0;
    Parse p = dechunk(buf, body_start, out.body, end, error, max_body);
    if (p == Parse::kIncomplete && eof) {
      error = "truncated chunked body";
      return Parse::kError;
    }
    if (p == Parse::kComplete) consumed = end;
    return p;
  }
  if (have_length) {
    if (length > max_body) {
      error = "body too large";
      return Parse::kError;
    }
    if (buf.size() - body_start < length) {
      if (eof) {
        error = "truncated body";
        return Parse::kError;
      }
      return Parse::kIncomplete;
    }
    out.body.assign(buf.substr(body_start, length));
    consumed = body_start + length;
    return Parse::kComplete;
  }
  if (buf.size() - body_start > max_body) {
    error = "body too large";
    return Parse::kError;
  }
  if (!eof) return Parse::kIncomplete;
  out.body.assign(buf.substr(body_start));
  consumed = buf.size();
  return Parse::kComplete;
}

}  // namespace

Parse parse_response(std::string_view buf, bool eof, ParsedResponse& out, size_t& consumed,
                     std::string& error, size_t max_body) {
  size_t start = 0;
  while (true) {
    size_t head_end = buf.find("\r\n\r\n", start);
    if (head_end == std::string_view::npos) {
      if (buf.size() - start > kMaxHeaderBytes) {
        error = "response header too large";
        return Parse::kError;
      }
      if (eof) {
        error = buf.size() == start ? "connection closed without an answer"
                                    : "truncated response header";
        return Parse::kError;
      }
      return Parse::kIncomplete;
    }
    if (head_end - start > kMaxHeaderBytes) {
      error = "response header too large";
      return Parse::kError;
    }
    if (!parse_head(buf.substr(start, head_end - start), out, error)) return Parse::kError;
    size_t body_start = head_end + 4;
    if (out.status >= 100 && out.status < 200 && out.status != 101) {  // interim: skip it
      start = body_start;
      continue;
    }
    return parse_body(buf, eof, body_start, out, consumed, error, max_body);
  }
}

std::string ws_frame(uint8_t opcode, std::string_view payload, const uint8_t mask[4]) {
  std::string f;
  f.push_back(static_cast<char>(0x80 | (opcode & 0x0f)));
  size_t n = payload.size();
  if (n < 126) {
    f.push_back(static_cast<char>(0x80 | n));
  } else if (n <= 0xffff) {
    f.push_back(static_cast<char>(0x80 | 126));
    f.push_back(static_cast<char>((n >> 8) & 0xff));
    f.push_back(static_cast<char>(n & 0xff));
  } else {
    f.push_back(static_cast<char>(0x80 | 127));
    for (int i = 7; i >= 0; --i)
      f.push_back(static_cast<char>((static_cast<uint64_t>(n) >> (8 * i)) & 0xff));
  }
  f.append(reinterpret_cast<const char*>(mask), 4);
  for (size_t i = 0; i < n; ++i)
    f.push_back(static_cast<char>(payload[i] ^ static_cast<char>(mask[i % 4])));
  return f;
}

Parse ws_parse(std::string_view buf, WsFrame& out, size_t& consumed, std::string& error,
               size_t max_payload) {
  if (buf.size() < 2) return Parse::kIncomplete;
  auto b0 = static_cast<uint8_t>(buf[0]);
  auto b1 = static_cast<uint8_t>(buf[1]);
  if (b0 & 0x70) {
    error = "reserved bits set";
    return Parse::kError;
  }
  uint8_t opcode = b0 & 0x0f;
  bool fin = (b0 & 0x80) != 0;
  if ((opcode >= 3 && opcode <= 7) || opcode > 10) {
    error = "reserved opcode";
    return Parse::kError;
  }
  if (opcode >= 8 && !fin) {
    error = "fragmented control frame";
    return Parse::kError;
  }
  bool masked = (b1 & 0x80) != 0;
  uint64_t len = b1 & 0x7f;
  size_t pos = 2;
  if (len == 126) {
    if (buf.size() < 4) return Parse::kIncomplete;
    len = (static_cast<uint64_t>(static_cast<uint8_t>(buf[2])) << 8) | static_cast<uint8_t>(buf[3]);
    pos = 4;
  } else if (len == 127) {
    if (buf.size() < 10) return Parse::kIncomplete;
    len = 0;
    for (int i = 0; i < 8; ++i)
      len = (len << 8) | static_cast<uint8_t>(buf[2 + static_cast<size_t>(i)]);
    pos = 10;
    if (len >> 63) {
      error = "bad frame length";
      return Parse::kError;
    }
  }
  if (opcode >= 8 && len > 125) {
    error = "control frame too long";
    return Parse::kError;
  }
  if (len > max_payload) {
    error = "frame too large";
    return Parse::kError;
  }
  uint8_t mask[4] = {0, 0, 0, 0};
  if (masked) {
    if (buf.size() < pos + 4) return Parse::kIncomplete;
    std::memcpy(mask, buf.data() + pos, 4);
    pos += 4;
  }
  if (buf.size() - pos < len) return Parse::kIncomplete;
  out.fin = fin;
  out.opcode = opcode;
  out.payload.assign(buf.substr(pos, len));
  if (masked)
    for (size_t i = 0; i < out.payload.size(); ++i)
      out.payload[i] = static_cast<char>(out.payload[i] ^ static_cast<char>(mask[i % 4]));
  consumed = pos + len;
  return Parse::kComplete;
}

std::string ws_accept(std::string_view key) {
  std::string s(key);
  s += "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";
  unsigned char d[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  if (EVP_Digest(s.data(), s.size(), d, &n, EVP_sha1(), nullptr) != 1) return {};
  return base64_encode(d, n);
}

}  // namespace rcan::client::wire
