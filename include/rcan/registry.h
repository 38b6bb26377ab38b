// The registry's vocabulary, shared by rcan-registry, rcand and the CLI (docs/REGISTRY.md):
// RRNs, the slugs that name a robot, and the bytes a robot signs to prove it holds its keys.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace rcan::registry {

// The slug of a name, as the rcan.dev registry makes it: lower case; every character outside
// [a-z0-9-] becomes '-'; runs of '-' collapse to one; at most 64 characters. May be empty.
std::string slugify(std::string_view s);

// The canonical RRN (upper case, the number zero-padded to 12 digits: parse_rrn in
// rcan/ruri.h) of `s`, which may be in any letter case; nullopt when `s` is not an RRN.
std::optional<std::string> normalize_rrn(std::string_view s);

// What a robot signs, with both its Ed25519 and its ML-DSA-65 key, to register them:
//   "rcan-registry-pop:<challenge_id>:<nonce>:<manufacturer>/<model>/<version>/<device_id>"
// with the four slugs. The challenge comes from the registry (GET /api/v1/challenge) and is
// used once, so a proof cannot be replayed or moved to another robot.
std::string proof_message(std::string_view challenge_id, std::string_view nonce,
                          std::string_view manufacturer, std::string_view model,
                          std::string_view version, std::string_view device_id);

// What a robot that proved its keys signs to change its own record (PATCH
// /api/v1/robots/{rrn}, headers X-RCAN-Timestamp and X-RCAN-Signature):
//   "rcan-registry-update:<RRN>:<timestamp, Unix ms>:" followed by the request body.
std::string update_message(std::string_view rrn, int64_t timestamp_ms, std::string_view body);

}  // namespace rcan::registry
