#include "registry/api/address.h"

#include <arpa/inet.h>
#include <netinet/in.h>

#include <charconv>
#include <cstring>

#include "rcan/errors.h"

namespace rcan::registry::api {
namespace {

constexpr std::array<uint8_t, 12> kMappedPrefix{0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff};

IpAddress from_v6(const uint8_t* p) {
  IpAddress a;
  std::memcpy(a.b.data(), p, 16);
  if (std::memcmp(p, kMappedPrefix.data(), kMappedPrefix.size()) == 0) a.v4 = a.mapped = true;
  return a;
}

IpAddress from_v4(const uint8_t* p) {
  IpAddress a;
  std::memcpy(a.b.data(), kMappedPrefix.data(), kMappedPrefix.size());
  std::memcpy(a.b.data() + 12, p, 4);
  a.v4 = true;
  return a;
}

// Blocks no webhook is delivered to, as CIDRs of the 16-byte form.
const std::vector<Cidr>& non_public() {
  static const std::vector<Cidr> blocks = [] {
    std::vector<Cidr> out;
    for (const char* c :
         {"0.0.0.0/8",     "10.0.0.0/8",      "100.64.0.0/10",  "127.0.0.0/8",    "169.254.0.0/16",
          "172.16.0.0/12", "192.0.0.0/24",    "192.0.2.0/24",   "192.88.99.0/24", "192.168.0.0/16",
          "198.18.0.0/15", "198.51.100.0/24", "203.0.113.0/24", "224.0.0.0/4",    "240.0.0.0/4",
          "::/96",         "::1/128",         "64:ff9b::/96",   "64:ff9b:1::/48", "100::/64",
          "2001::/23",     "2001:db8::/32",   "2002::/16",      "fc00::/7",       "fe80::/10",
          "fec0::/10",     "ff00::/8"})
      out.push_back(*parse_cidr(c));
    return out;
  }();
  return blocks;
}

}  // namespace

std::optional<IpAddress> parse_ip(std::string_view text) {
  if (text.size() >= 2 && text.front() == '[' && text.back() == ']')
    text = text.substr(1, text.size() - 2);
  if (text.empty() || text.size() >= INET6_ADDRSTRLEN) return std::nullopt;
  const std::string s(text);
  uint8_t buf[16];
  if (inet_pton(AF_INET, s.c_str(), buf) == 1) return from_v4(buf);
  if (inet_pton(AF_INET6, s.c_str(), buf) == 1) return from_v6(buf);
  return std::nullopt;
}

std::optional<IpAddress> ip_of(const sockaddr* sa) {
  if (sa == nullptr) return std::nullopt;
  if (sa->sa_family == AF_INET) {
    const auto* in = reinterpret_cast<const sockaddr_in*>(sa);
    return from_v4(reinterpret_cast<const uint8_t*>(&in->sin_addr));
  }
  if (sa->sa_family == AF_INET6) {
    const auto* in6 = reinterpret_cast<const sockaddr_in6*>(sa);
    return from_v6(in6->sin6_addr.s6_addr);
  }
  return std::nullopt;
}

std::string ip_text(const IpAddress& a) {
  char buf[INET6_ADDRSTRLEN] = {};
  if (a.v4) {
    inet_ntop(AF_INET, a.b.data() + 12, buf, sizeof buf);
  } else {
    inet_ntop(AF_INET6, a.b.data(), buf, sizeof buf);
  }
  return buf;
}

bool Cidr::contains(const IpAddress& a) const {
  const int whole = bits / 8, rest = bits % 8;
  if (std::memcmp(a.b.data(), base.b.data(), static_cast<size_t>(whole)) != 0) return false;
  if (rest == 0) return true;
  const uint8_t mask = static_cast<uint8_t>(0xff << (8 - rest));
  return (a.b[static_cast<size_t>(whole)] & mask) == (base.b[static_cast<size_t>(whole)] & mask);
}

Result<Cidr> parse_cidr(std::string_view text) {
  auto bad = [&] {
    return Error(ErrorCode::kSchemaValidationFailed,
                 "'" + std::string(text.substr(0, 64)) +
                     "' is not an address or a CIDR block (10.0.0.0/8, fd00::/8)",
                 "trusted-proxy");
  };
  const size_t slash = text.find('/');
  auto ip = parse_ip(text.substr(0, slash));
  if (!ip) return bad();
  Cidr c;
  c.base = *ip;
  const int max = ip->v4 ? 32 : 128;
  int bits = max;
  if (slash != std::string_view::npos) {
    std::string_view b = text.substr(slash + 1);
    auto [p, ec] = std::from_chars(b.data(), b.data() + b.size(), bits);
    if (b.empty() || ec != std::errc() || p != b.data() + b.size() || bits < 0 || bits > max)
      return bad();
  }
  c.bits = ip->v4 ? bits + 96 : bits;
  return c;
}

std::string client_address(const std::string& peer, const std::vector<std::string>& forwarded_for,
                           const std::vector<Cidr>& trusted) {
  auto is_trusted = [&](const IpAddress& a) {
    for (const Cidr& c : trusted)
      if (c.contains(a)) return true;
    return false;
  };
  auto p = parse_ip(peer);
  if (!p) return peer;
  if (!is_trusted(*p)) return ip_text(*p);
  // Every X-Forwarded-For line, split at commas, walked from the right (the nearest hop).
  std::vector<std::string_view> hops;
  for (const std::string& line : forwarded_for) {
    std::string_view v = line;
    while (!v.empty()) {
      const size_t comma = v.find(',');
      std::string_view h = v.substr(0, comma);
      while (!h.empty() && (h.front() == ' ' || h.front() == '\t')) h.remove_prefix(1);
      while (!h.empty() && (h.back() == ' ' || h.back() == '\t')) h.remove_suffix(1);
      hops.push_back(h);
      if (comma == std::string_view::npos) break;
      v.remove_prefix(comma + 1);
    }
  }
  IpAddress client = *p;
  for (auto it = hops.rbegin(); it != hops.rend(); ++it) {
    auto h = parse_ip(*it);
    if (!h) break;  // what a trusted hop did not write is not believed
    client = *h;
    if (!is_trusted(*h)) break;
  }
  return ip_text(client);
}

bool is_public_address(const IpAddress& a) {
  if (a.mapped) return false;
  for (const Cidr& c : non_public())
    if (c.contains(a)) return false;
  // An IPv4 address outside the blocks above is public; so is an IPv6 one in 2000::/3 only.
  return a.v4 || (a.b[0] & 0xe0) == 0x20;
}

}  // namespace rcan::registry::api
