// The single error body of the profile (docs/PROTOCOL.md §Errors), on every transport:
//   {"type":"ERROR","message_id":"<new uuid>","reply_to":"<offending id or null>",
//    "timestamp_ms":<ms>,"payload":{"error_code":"…","error":"…","detail":{…}}}
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "rcan/error_code.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan {

// A fresh random UUID v4 (lower case, 8-4-4-4-12).
std::string new_uuid_v4();
// True for a lower- or upper-case 8-4-4-4-12 hex UUID (any version).
bool is_uuid(std::string_view s);

// Builds the error body. `message_id` empty → a fresh UUID v4. `reply_to` empty → null.
// detail carries `field` and `reason` of the Error when set.
json::Value error_body(const Error& err, std::string_view reply_to, int64_t timestamp_ms,
                       std::string_view message_id = {});

}  // namespace rcan
