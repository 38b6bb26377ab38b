#include "node/control/control_machine.h"

namespace rcan::node {

std::string_view control_state_name(ControlState s) {
  switch (s) {
    case ControlState::kAvailable:
      return "AVAILABLE";
    case ControlState::kHeld:
      return "HELD";
    case ControlState::kReserved:
      return "RESERVED";
  }
  return "AVAILABLE";
}

std::string_view ownership_state_name(OwnershipState s) {
  switch (s) {
    case OwnershipState::kOwned:
      return "OWNED";
    case OwnershipState::kTransferPending:
      return "TRANSFER_PENDING";
  }
  return "OWNED";
}

std::string_view control_event_name(ControlEvent e) {
  switch (e) {
    case ControlEvent::kClaim:
      return "CLAIM";
    case ControlEvent::kRenew:
      return "RENEW";
    case ControlEvent::kPreempt:
      return "PREEMPT";
    case ControlEvent::kQueue:
      return "QUEUE";
    case ControlEvent::kPromote:
      return "PROMOTE";
    case ControlEvent::kRelease:
      return "RELEASE";
    case ControlEvent::kExpire:
      return "EXPIRE";
    case ControlEvent::kRevoke:
      return "REVOKE";
    case ControlEvent::kHandoff:
      return "HANDOFF";
    case ControlEvent::kWindowClose:
      return "WINDOW_CLOSE";
    case ControlEvent::kQueueDrop:
      return "QUEUE_DROP";
    case ControlEvent::kLeaseEnd:
      return "LEASE_END";
  }
  return "CLAIM";
}

std::string_view ownership_event_name(OwnershipEvent e) {
  switch (e) {
    case OwnershipEvent::kTransferRequest:
      return "TRANSFER_REQUEST";
    case OwnershipEvent::kTransferAccept:
      return "TRANSFER_ACCEPT";
    case OwnershipEvent::kTransferCancel:
      return "TRANSFER_CANCEL";
    case OwnershipEvent::kTransferExpire:
      return "TRANSFER_EXPIRE";
  }
  return "TRANSFER_REQUEST";
}

const std::vector<ControlTransition>& control_transitions() {
  using S = ControlState;
  using E = ControlEvent;
  static const std::vector<ControlTransition> t{
      {S::kAvailable, E::kClaim, S::kHeld},            // first claim wins
      {S::kHeld, E::kRenew, S::kHeld},                 // explicit renewal (re-claim, /auth/renew)
      {S::kHeld, E::kPreempt, S::kHeld},               // a higher role takes over
      {S::kHeld, E::kQueue, S::kHeld},                 // same role: the claimant waits, FIFO
      {S::kHeld, E::kPromote, S::kHeld},               // holder gone, head of the queue takes over
      {S::kHeld, E::kRelease, S::kAvailable},          // RCAN_RELEASE, AVAILABLE for the window
      {S::kHeld, E::kExpire, S::kAvailable},           // TTL reached without renewal
      {S::kHeld, E::kRevoke, S::kAvailable},           // lease ended, ownership transferred
      {S::kHeld, E::kHandoff, S::kReserved},           // named successor, window reserved
      {S::kReserved, E::kClaim, S::kHeld},             // the named target claims
      {S::kReserved, E::kWindowClose, S::kAvailable},  // nobody came: first claim wins again
  };
  return t;
}

const std::vector<OwnershipTransition>& ownership_transitions() {
  using S = OwnershipState;
  using E = OwnershipEvent;
  static const std::vector<OwnershipTransition> t{
      {S::kOwned, E::kTransferRequest, S::kTransferPending},
      {S::kTransferPending, E::kTransferAccept, S::kOwned},  // new owner, personal data cleared
      {S::kTransferPending, E::kTransferCancel, S::kOwned},
      {S::kTransferPending, E::kTransferExpire, S::kOwned},  // the window passed
  };
  return t;
}

namespace {

template <class T, class S, class E>
bool allowed(const std::vector<T>& t, S from, E ev, S to) {
  for (const auto& r : t)
    if (r.from == from && r.event == ev && r.to == to) return true;
  return false;
}

template <class T, class StateName, class EventName>
std::string diagram(const std::vector<T>& table, StateName state, EventName event) {
  std::string s = "stateDiagram-v2\n    [*] --> " +
                  std::string(table.empty() ? std::string_view() : state(table.front().from)) +
                  "\n";
  for (const auto& r : table)
    s += "    " + std::string(state(r.from)) + " --> " + std::string(state(r.to)) + " : " +
         std::string(event(r.event)) + "\n";
  return s;
}

}  // namespace

bool control_transition_allowed(ControlState from, ControlEvent event, ControlState to) {
  return allowed(control_transitions(), from, event, to);
}

bool ownership_transition_allowed(OwnershipState from, OwnershipEvent event, OwnershipState to) {
  return allowed(ownership_transitions(), from, event, to);
}

std::string mermaid(const std::vector<ControlTransition>& table) {
  return diagram(table, control_state_name, control_event_name);
}

std::string mermaid(const std::vector<OwnershipTransition>& table) {
  return diagram(table, ownership_state_name, ownership_event_name);
}

}  // namespace rcan::node
