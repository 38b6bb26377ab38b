#include "rcan/registry.h"

#include <cctype>
#include <string>

#include "base/strings.h"
#include "rcan/ruri.h"

namespace rcan::registry {

std::string slugify(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    char l = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    bool keep = (l >= 'a' && l <= 'z') || (l >= '0' && l <= '9') || l == '-';
    char put = keep ? l : '-';
    if (put == '-' && !out.empty() && out.back() == '-') continue;
    out.push_back(put);
  }
  if (out.size() > 64) out.resize(64);
  return out;
}

std::optional<std::string> normalize_rrn(std::string_view s) {
  auto r = parse_rrn(ascii_upper(s));
  if (!r.ok()) return std::nullopt;
  return r->str();
}

std::string proof_message(std::string_view challenge_id, std::string_view nonce,
                          std::string_view manufacturer, std::string_view model,
                          std::string_view version, std::string_view device_id) {
  std::string m = "rcan-registry-pop:";
  m.append(challenge_id).append(":").append(nonce).append(":");
  m.append(manufacturer).append("/").append(model).append("/").append(version).append("/");
  m.append(device_id);
  return m;
}

std::string update_message(std::string_view rrn, int64_t timestamp_ms, std::string_view body) {
  std::string m = "rcan-registry-update:";
  m.append(rrn).append(":").append(std::to_string(timestamp_ms)).append(":").append(body);
  return m;
}

}  // namespace rcan::registry
