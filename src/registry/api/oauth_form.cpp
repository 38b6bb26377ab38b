#include "registry/api/oauth_form.h"

#include <cstring>

#include "rcan/encoding.h"
#include "transport/http_parse.h"

namespace rcan::registry::api {
namespace {

Error bad(std::string msg) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), "body", "invalid_request");
}

}  // namespace

Result<Form> parse_form(std::string_view body) {
  if (body.size() > kMaxFormBytes) return bad("the form is too large");
  Form f;
  size_t count = 0;
  while (!body.empty()) {
    size_t amp = body.find('&');
    std::string_view part = body.substr(0, amp);
    body = amp == std::string_view::npos ? std::string_view() : body.substr(amp + 1);
    if (part.empty()) continue;
    if (++count > kMaxFormFields) return bad("too many form fields");
    size_t eq = part.find('=');
    std::string k, v;
    if (!transport::detail::percent_decode(part.substr(0, eq), true, k) ||
        !transport::detail::percent_decode(
            eq == std::string_view::npos ? std::string_view() : part.substr(eq + 1), true, v))
      return bad("a malformed percent escape in the form");
    if (k.empty()) return bad("a form field without a name");
    // A NUL byte (sent raw, which percent_decode passes on, or as %00) ends a C string: the
    // database would see another client id than the one checked here.
    if (k.find('\0') != std::string::npos || v.find('\0') != std::string::npos)
      return bad("a NUL byte in the form");
    if (!f.fields.emplace(std::move(k), std::move(v)).second) return bad("a parameter is repeated");
  }
  return f;
}

std::optional<BasicCredentials> parse_basic(std::string_view h) {
  if (h.size() < 6 || (h.substr(0, 6) != "Basic " && h.substr(0, 6) != "basic ")) return {};
  std::string_view b = h.substr(6);
  while (!b.empty() && b.front() == ' ') b.remove_prefix(1);
  while (!b.empty() && b.back() == ' ') b.remove_suffix(1);
  if (b.size() > 4096) return {};
  auto raw = base64_decode(b);
  if (!raw) return {};
  std::string s = to_string(*raw);
  size_t colon = s.find(':');
  if (colon == std::string::npos) return {};
  BasicCredentials c;
  if (!transport::detail::percent_decode(std::string_view(s).substr(0, colon), true, c.id) ||
      !transport::detail::percent_decode(std::string_view(s).substr(colon + 1), true, c.secret))
    return {};
  if (c.id.empty()) return {};
  if (c.id.find('\0') != std::string::npos || c.secret.find('\0') != std::string::npos) return {};
  return c;
}

std::optional<std::vector<std::string>> parse_scope(std::string_view s) {
  std::vector<std::string> out;
  while (!s.empty()) {
    size_t sp = s.find(' ');
    std::string_view tok = s.substr(0, sp);
    s = sp == std::string_view::npos ? std::string_view() : s.substr(sp + 1);
    if (tok.empty()) continue;
    if (tok.size() > 64 || out.size() >= 32) return std::nullopt;
    for (char c : tok)
      if (c < 0x21 || c > 0x7e || c == '"' || c == '\\') return std::nullopt;
    bool seen = false;
    for (const auto& o : out) seen = seen || o == tok;
    if (!seen) out.emplace_back(tok);
  }
  return out;
}

std::string normalize_user_code(std::string_view s) {
  std::string code;
  for (char c : s) {
    if (c == '-' || c == ' ') continue;
    char u = (c >= 'a' && c <= 'z') ? static_cast<char>(c - 'a' + 'A') : c;
    if (std::strchr(kUserCodeAlphabet, u) == nullptr || u == '\0') return {};
    code.push_back(u);
    if (code.size() > 8) return {};
  }
  if (code.size() != 8) return {};
  return code.substr(0, 4) + "-" + code.substr(4);
}

}  // namespace rcan::registry::api
