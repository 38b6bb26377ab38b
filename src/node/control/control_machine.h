// The control-session and ownership state machines as data (docs/SESSIONS.md). The code that
// moves between states (sessions.cpp, ownership.cpp) checks every move against these tables,
// and the diagrams in docs/SESSIONS.md are generated from them (`mermaid()`), so the
// documentation cannot drift from the code: a test compares the two.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace rcan::node {

// Control of the robot (seed §2.3, §4.3.5, §5.3, PROFILE.md §5).
enum class ControlState { kAvailable, kHeld, kReserved };
// Ownership (seed §6.2).
enum class OwnershipState { kOwned, kTransferPending };

struct Transition {
  std::string_view from;
  std::string_view event;
  std::string_view to;
};

std::string_view control_state_name(ControlState s);      // "AVAILABLE", "HELD", "RESERVED"
std::string_view ownership_state_name(OwnershipState s);  // "OWNED", "TRANSFER_PENDING"

const std::vector<Transition>& control_transitions();
const std::vector<Transition>& ownership_transitions();

// True when (from, event, to) is a row of the table.
bool control_transition_allowed(ControlState from, std::string_view event, ControlState to);
bool ownership_transition_allowed(OwnershipState from, std::string_view event, OwnershipState to);

// A Mermaid stateDiagram-v2 for a table (one "A --> B : EVENT" line per row, in table order).
std::string mermaid(const std::vector<Transition>& table, std::string_view initial);

}  // namespace rcan::node
