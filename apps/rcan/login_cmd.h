// rcan token get (OAuth 2.0 client credentials against rcan-registry's token authority,
// docs/REGISTRY.md "Token authority"); `rcan login` registers itself.
#pragma once

#include "cli.h"

namespace rcan::cli {

int token_get_main(const Args& args);

}  // namespace rcan::cli
