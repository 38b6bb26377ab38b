// IP addresses for the registry's rate limits and webhooks (docs/REGISTRY.md): CIDR blocks
// (--trusted-proxy), the client a request came from behind a trusted proxy (X-Forwarded-For),
// and whether an address is a public one a webhook may be delivered to.
#pragma once

#include <sys/socket.h>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/result.h"

namespace rcan::registry::api {

// An IPv4 or IPv6 address as 16 bytes (IPv4 as ::ffff:a.b.c.d, `v4` set; `mapped` when it was
// written or connected to as an IPv4-mapped IPv6 address).
struct IpAddress {
  std::array<uint8_t, 16> b{};
  bool v4 = false;
  bool mapped = false;
};

// "192.0.2.1", "2001:db8::1", "[2001:db8::1]"; an IPv4-mapped IPv6 address is the IPv4 one
// (mapped set). nullopt for anything else (a name, a port, a zone).
std::optional<IpAddress> parse_ip(std::string_view text);
std::optional<IpAddress> ip_of(const sockaddr* sa);
std::string ip_text(const IpAddress& a);

struct Cidr {
  IpAddress base;
  int bits = 0;  // of the 16-byte form (an IPv4 /24 is 120)
  bool contains(const IpAddress& a) const;
};
// "10.0.0.0/8", "fd00::/8", or one address (a /32 or /128). Errors: SCHEMA_VALIDATION_FAILED.
Result<Cidr> parse_cidr(std::string_view text);

// The client a request came from: `peer` itself, unless `peer` is a trusted proxy; then the
// right-most address of `forwarded_for` (the X-Forwarded-For values in order) that is not a
// trusted proxy itself — what the proxies nearest to us saw; the left-most when every one is.
// A malformed entry ends the walk at the last address the chain vouched for.
std::string client_address(const std::string& peer, const std::vector<std::string>& forwarded_for,
                           const std::vector<Cidr>& trusted);

// Whether a webhook may be delivered to `a`: not loopback, private (RFC 1918, unique-local
// fc00::/7), link-local (the cloud metadata address 169.254.169.254 among them), CGNAT
// (100.64.0.0/10), unspecified, multicast, broadcast, reserved, documentation, benchmarking,
// IPv4-mapped, IPv4-compatible, NAT64 or 6to4 (a way to an IPv4 address not judged as one).
bool is_public_address(const IpAddress& a);

}  // namespace rcan::registry::api
