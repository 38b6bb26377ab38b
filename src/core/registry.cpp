#include "rcan/registry.h"

#include <cctype>

namespace rcan::registry {
namespace {

bool all_digits(std::string_view s, size_t min, size_t max) {
  if (s.size() < min || s.size() > max) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  return true;
}

bool is_prefix(std::string_view s) {
  if (s.size() < 2 || s.size() > 8) return false;
  for (char c : s)
    if (!std::isalnum(static_cast<unsigned char>(c))) return false;
  return true;
}

}  // namespace

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

bool is_rrn(std::string_view s) {
  if (s.size() < 4) return false;
  for (size_t i = 0; i < 4; ++i)
    if (std::toupper(static_cast<unsigned char>(s[i])) != "RRN-"[i]) return false;
  std::string_view rest = s.substr(4);
  auto dash = rest.find('-');
  if (dash == std::string_view::npos) return all_digits(rest, 8, 16);
  return is_prefix(rest.substr(0, dash)) && all_digits(rest.substr(dash + 1), 8, 16);
}

std::optional<std::string> normalize_rrn(std::string_view s) {
  if (!is_rrn(s)) return std::nullopt;
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}

std::string rrn_prefix(std::string_view rrn) {
  auto n = normalize_rrn(rrn);
  if (!n) return {};
  std::string_view rest = std::string_view(*n).substr(4);
  auto dash = rest.find('-');
  return dash == std::string_view::npos ? std::string() : std::string(rest.substr(0, dash));
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

}  // namespace rcan::registry
