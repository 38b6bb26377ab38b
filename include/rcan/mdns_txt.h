// The TXT record of an `_rcan._tcp` announcement (seed §1.3, docs/PROTOCOL.md): read by the
// client's discovery (rcan::client::discover) and by the node's mDNS browser (the dashboard's
// Robots view). Untrusted input from anyone on the network: fuzzed by client_discovery_fuzz.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace rcan {

// TXT items ("key=value", "flag") → map with lower-cased keys; the first of duplicate keys
// wins (RFC 6763 §6.4); items with an empty key are dropped; a key without '=' maps to "".
// Values are kept as bytes.
std::map<std::string, std::string> parse_txt(const std::vector<std::string>& items);

// Whether the announcement says the node serves HTTPS: `tls=1` or `scheme=https`.
bool txt_says_tls(const std::map<std::string, std::string>& txt);

}  // namespace rcan
