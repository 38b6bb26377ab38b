// The key tables of docs/CONFIG.md, generated from the block tables (blocks/*.cpp): each row
// there is one row of a block's table, with its type and range from the row's schema, its
// default from the struct member's initializer (or the row's default_text) and its meaning
// from the row's doc text. A generated region of the document is
//
//   <!-- generated: safety watchdog -->
//   | key | type | default | meaning |
//   ...
//   <!-- end generated -->
//
// naming the top-level keys whose tables it holds; the prose around the regions is kept.
// `rcand config-doc --check docs/CONFIG.md` fails when a region differs from the generator's
// output, `--write` rewrites the regions.
#pragma once

#include <string>
#include <string_view>

#include "rcan/result.h"

namespace rcan::config {

// The table of the top-level keys named in `keys` (separated by spaces), in markdown. Error
// for a name that is not a top-level key.
Result<std::string> config_doc_table(std::string_view keys);

// `markdown` with every generated region's table replaced by config_doc_table() of its keys.
// Error for an unterminated region or an unknown key.
Result<std::string> regenerate_config_doc(std::string_view markdown);

}  // namespace rcan::config
