// OAuth 2.0 request parsing for the registry's token authority (RFC 6749 §3.2, §2.3.1):
// application/x-www-form-urlencoded bodies and HTTP Basic client credentials. Apart from the
// routes so that a fuzz target can run arbitrary bytes through them; no store, clock or network.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/result.h"

namespace rcan::registry::api {

inline constexpr size_t kMaxFormBytes = 16384;
inline constexpr size_t kMaxFormFields = 32;

// A decoded form. Errors (kInvalidRequest-style, reason "invalid_request"): body too large,
// too many fields, a bad percent escape, an empty or repeated parameter name (RFC 6749 §3.2:
// parameters must not be included more than once).
struct Form {
  std::map<std::string, std::string> fields;
  bool has(const std::string& k) const { return fields.count(k) != 0; }
  std::string get(const std::string& k) const {
    auto it = fields.find(k);
    return it == fields.end() ? std::string() : it->second;
  }
};
Result<Form> parse_form(std::string_view body);

// "Basic <base64(urlencoded id ':' urlencoded secret)>" → {id, secret}; nullopt otherwise.
struct BasicCredentials {
  std::string id, secret;
};
std::optional<BasicCredentials> parse_basic(std::string_view authorization);

// A space-separated scope list (RFC 6749 §3.3): each token 1..64 printable ASCII without '"'
// or '\'; at most 32. nullopt when malformed.
std::optional<std::vector<std::string>> parse_scope(std::string_view s);

// A user code typed by a person: upper-cased, dashes and spaces dropped, then "XXXX-XXXX";
// empty when not 8 letters of the user-code alphabet.
std::string normalize_user_code(std::string_view s);
inline constexpr const char* kUserCodeAlphabet = "BCDFGHJKLMNPQRSTVWXZ";

}  // namespace rcan::registry::api
