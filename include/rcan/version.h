// The version of this project's software (rcand, rcan, rcan-registry), as project(VERSION) in
// CMakeLists.txt says (configuring fails when the two differ). The protocol's version is
// another thing: RCAN 1.0.0 (seed), in each message's `version`.
#pragma once

#include <string_view>

namespace rcan {

inline constexpr std::string_view kSoftwareVersion = "0.1.0";

}  // namespace rcan
