// The token authority's internals, shared by its route files (not an interface).
#pragma once

#include <string>
#include <vector>

#include "registry/api/impl.h"

namespace rcan::registry::api {

// An RFC 6749 §5.2 error body {"error", "error_description"}, Cache-Control: no-store.
transport::HttpResponse oauth_error(int status, const std::string& error,
                                    const std::string& description);
std::string random_b64url(size_t bytes);
std::string random_hex_id(size_t bytes);
// The audience of tokens for a robot (docs/THREATS.md T1): the RURI of the robot its
// registration proved — metadata.ruri when it gave one (rcand does), else
// rcan://<host>/<manufacturer>/<model>/<device_id> — exact (parse_ruri refuses a wildcard) and
// naming the manufacturer, model, device id (and version) its proof of possession signed. A
// record that proved no key, or whose RURI names another robot, gets no token.
Result<std::string> robot_audience(const Robot& r, const std::string& host);
bool grant_covers_target(const Grant& g, const Target& t);
std::vector<std::string> split_words(const std::string& s);

}  // namespace rcan::registry::api
