#include "rcan/mdns_txt.h"

#include <cctype>

#include "base/strings.h"

namespace rcan {

std::map<std::string, std::string> parse_txt(const std::vector<std::string>& items) {
  std::map<std::string, std::string> out;
  for (const auto& item : items) {
    size_t eq = item.find('=');
    std::string key = ascii_lower(item.substr(0, eq));
    if (key.empty()) continue;
    std::string value = eq == std::string::npos ? std::string() : item.substr(eq + 1);
    out.emplace(std::move(key), std::move(value));  // first wins
  }
  return out;
}

bool txt_says_tls(const std::map<std::string, std::string>& txt) {
  auto is = [&](const char* k, const char* v) {
    auto it = txt.find(k);
    return it != txt.end() && it->second == v;
  };
  return is("tls", "1") || is("scheme", "https");
}

}  // namespace rcan
