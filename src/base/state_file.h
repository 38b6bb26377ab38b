// Small JSON state files in the node's data directory (leases, ownership, consent, the
// credential cache): written atomically (temporary file, fsync, rename, fsync of the
// directory) with mode 0600, read back at start-up.
#pragma once

#include <string>

#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan {

Status write_state_file(const std::string& path, const json::Value& v);
// NOT_FOUND when absent; SCHEMA_VALIDATION_FAILED when it does not parse.
Result<json::Value> read_state_file(const std::string& path);

}  // namespace rcan
