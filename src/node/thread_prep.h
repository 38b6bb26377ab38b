// Start-up preparation of a thread that will carry commands (docs/FLEET.md, "first message").
#pragma once

#include <cstddef>

namespace rcan::node {

// Readies the calling thread to run the command pipeline without first-use stalls, as a
// real-time control thread is readied before it is needed: the pages of its stack that a
// command's call chain reaches are touched now, and its CSPRNG state (OpenSSL's per-thread
// generator and the id pool behind new_uuid_v4) is set up now, not inside the first ESTOP.
// Idempotent per thread; never touches more than half of the thread's stack.
void prepare_command_thread(size_t stack_bytes = 192 * 1024);

}  // namespace rcan::node
