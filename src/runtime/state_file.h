// Small JSON state files in the node's data directory (leases, ownership, consent, the
// credential cache): written atomically (temporary file, fsync, rename, fsync of the
// directory) with mode 0600, read back at start-up.
#pragma once

#include <string>

#include "rcan/base/env.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan {

// `v` as one line of JSON, through base::Env::write_file_atomic of `env` (nullptr →
// base::Env::posix()). Errors: INTERNAL, naming the step, the file and errno.
Status write_state_file(const std::string& path, const json::Value& v, base::Env* env = nullptr);
// Read through `env` (nullptr → base::Env::posix()). NOT_FOUND when absent or unreadable;
// SCHEMA_VALIDATION_FAILED when it does not parse (or is over 4 MiB).
Result<json::Value> read_state_file(const std::string& path, base::Env* env = nullptr);

}  // namespace rcan
