// The default data directory of a daemon of this project (rcand, rcan-registry): $<env_var>
// (made absolute), else $XDG_DATA_HOME/<app>, else ~/.local/share/<app> (HOME, else the
// password database). Errors: SCHEMA_VALIDATION_FAILED (field "node.data_dir", reason
// missing_key) naming env_var when no home directory is known.
#pragma once

#include <string>
#include <string_view>

#include "rcan/result.h"

namespace rcan {

Result<std::string> user_data_dir(std::string_view app, const char* env_var);

}  // namespace rcan
