// libFuzzer target: the registry's client addresses (src/registry/api/address.h) — a CIDR block
// as --trusted-proxy gives it, and the X-Forwarded-For lines a request carries, which anyone
// writes. Input: lines; the first is a CIDR, the rest header values. Must never crash; a CIDR
// that parses contains its own base; the client is the peer, or an address of the header (never
// a value that is not an address); an address that parses prints and parses back the same.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "registry/api/address.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan::registry::api;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  std::vector<std::string> lines;
  while (!text.empty() && lines.size() < 16) {
    const size_t nl = text.find('\n');
    lines.emplace_back(text.substr(0, nl));
    text = nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
  }
  if (lines.empty()) return 0;
  std::vector<Cidr> trusted;
  auto c = parse_cidr(lines[0]);
  if (c.ok()) {
    if (!c->contains(c->base)) std::abort();
    trusted.push_back(*c);
  } else if (c.error().message.empty()) {
    std::abort();
  }
  for (const auto& l : lines)
    if (auto ip = parse_ip(l)) {
      auto back = parse_ip(ip_text(*ip));
      if (!back || back->b != ip->b) std::abort();
      (void)is_public_address(*ip);
    }
  auto local = parse_cidr("127.0.0.0/8");
  if (!local.ok()) std::abort();
  trusted.push_back(*local);
  const std::vector<std::string> header(lines.begin() + 1, lines.end());
  const std::string client = client_address("127.0.0.1", header, trusted);
  if (client != "127.0.0.1" && !parse_ip(client)) std::abort();
  if (client_address("192.0.2.7", header, trusted) != "192.0.2.7") std::abort();  // not a proxy
  return 0;
}
