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

// What moves control (and what the node announces about it). QUEUE_DROP and LEASE_END are
// announced changes that move no state.
enum class ControlEvent {
  kClaim,
  kRenew,
  kPreempt,
  kQueue,
  kPromote,
  kRelease,
  kExpire,
  kRevoke,
  kHandoff,
  kWindowClose,
  kQueueDrop,
  kLeaseEnd,
};
enum class OwnershipEvent { kTransferRequest, kTransferAccept, kTransferCancel, kTransferExpire };

template <class State, class Event>
struct Transition {
  State from;
  Event event;
  State to;
};
using ControlTransition = Transition<ControlState, ControlEvent>;
using OwnershipTransition = Transition<OwnershipState, OwnershipEvent>;

std::string_view control_state_name(ControlState s);      // "AVAILABLE", "HELD", "RESERVED"
std::string_view ownership_state_name(OwnershipState s);  // "OWNED", "TRANSFER_PENDING"
std::string_view control_event_name(ControlEvent e);      // "CLAIM", "WINDOW_CLOSE", …
std::string_view ownership_event_name(OwnershipEvent e);  // "TRANSFER_REQUEST", …

const std::vector<ControlTransition>& control_transitions();
const std::vector<OwnershipTransition>& ownership_transitions();

// True when (from, event, to) is a row of the table.
bool control_transition_allowed(ControlState from, ControlEvent event, ControlState to);
bool ownership_transition_allowed(OwnershipState from, OwnershipEvent event, OwnershipState to);

// A Mermaid stateDiagram-v2 for a table (one "A --> B : EVENT" line per row, in table order),
// starting in the table's first state.
std::string mermaid(const std::vector<ControlTransition>& table);
std::string mermaid(const std::vector<OwnershipTransition>& table);

}  // namespace rcan::node
