// RURI — Robot Universal Resource Identifier — and RRN, the robot registration number.
//
// Canonical form (emitted everywhere):
//   rcan://<registry>/<manufacturer>/<model>/<device-id>[:<port>][/<capability>]
// all lower case; device-id is 8 hex digits or a full UUID (the spec's normative regex),
// port 1..65535. Accepted on input as well and normalised (docs/PROTOCOL.md §Addressing):
//   * one trailing '/'
//   * v1.1 dot shorthand  rcan://mfr.model.id[/cap]   → rcan://local.rcan/mfr/model/id[/cap]
//   * the SDKs' 5-segment form rcan://registry/mfr/model/version/device-id
//   * the mDNS-discovered form rcan://local.rcan/discovered/<ipv4>:<port>
// Wildcards ('*') are never valid in a RURI; they exist only in JWT `aud` patterns,
// matched by aud_matches().
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "rcan/result.h"

namespace rcan {

struct Ruri {
  enum class Form { kCanonical, kShorthand, kSdk5, kDiscovered };

  Form form = Form::kCanonical;
  std::string registry;
  std::string manufacturer;
  std::string model;
  std::string version;    // kSdk5 only
  std::string device_id;  // kDiscovered: the IPv4 address
  std::optional<uint16_t> port;
  std::string capability;  // without the leading '/', may contain '/'

  // The canonical string (see the file comment).
  std::string str() const;
  // The robot's identity: the canonical string without port and capability.
  std::string base() const;

  bool operator==(const Ruri& o) const { return str() == o.str(); }
};

// Parses any accepted form. On failure: ErrorCode::kInvalidRuri, `field` names the segment
// (scheme, registry, manufacturer, model, version, device-id, port, capability) and the
// message says which rule it broke.
Result<Ruri> parse_ruri(std::string_view text);

std::string_view ruri_form_name(Ruri::Form f);

// The robot's identity in the SDKs' 5-segment form (rcan-py / rcan-ts RobotURI):
// rcan://<registry>/<manufacturer>/<model>/<version>/<device-id>, with `version` as the version
// segment (a kSdk5 RURI keeps its own). Empty for a discovered RURI, which names no robot.
std::string sdk_form(const Ruri& ruri, std::string_view version = "v1");

// JWT audience matching: `pattern` is a RURI in which any segment may be '*'. Matches when
// every segment of the robot's base RURI equals the pattern's segment or the pattern has
// '*' there. A pattern with a capability matches only that capability of `robot`; a
// pattern without one matches the robot whatever capability it is addressed with.
bool aud_matches(std::string_view pattern, const Ruri& robot);

// Whether a message's `target` addresses the robot `self` (its own identity). The manufacturer,
// model and device id must be the robot's; the registry must be the robot's or `local.rcan`
// (the local-network registry, which the dot shorthand expands to); the SDKs' version segment,
// a port and a capability do not matter. A discovered RURI names an address, not a robot, and
// never matches. On a mismatch `why` (if given) says which segment differs.
bool addresses_robot(const Ruri& target, const Ruri& self, std::string* why = nullptr);

// RRN — "RRN-" + 12 digits canonical; accepted: RRN(-PFX)?-<8..16 digits>, PFX [A-Z0-9]{2,8}.
struct Rrn {
  std::string prefix;  // e.g. "BD" in RRN-BD-000000000042, empty when none
  std::string digits;  // at least 12 (shorter input is zero-padded)
  std::string str() const;
};
Result<Rrn> parse_rrn(std::string_view text);
// The one text form of registration number `n` (>= 0): "RRN-" + `n` in 12 zero-padded digits
// (more when it has more), or "RRN-<PREFIX>-" + the same when `prefix` is set (upper-cased).
// The registry mints RRNs with it; a node without one makes its local RRN with it.
std::string format_rrn(int64_t n, std::string_view prefix = {});

}  // namespace rcan
