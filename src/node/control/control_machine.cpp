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

const std::vector<Transition>& control_transitions() {
  static const std::vector<Transition> t{
      {"AVAILABLE", "CLAIM", "HELD"},             // first claim wins
      {"HELD", "RENEW", "HELD"},                  // explicit renewal (re-claim or /auth/renew)
      {"HELD", "PREEMPT", "HELD"},                // a higher role takes over
      {"HELD", "QUEUE", "HELD"},                  // same role: the claimant waits, FIFO
      {"HELD", "PROMOTE", "HELD"},                // holder gone, head of the queue takes over
      {"HELD", "RELEASE", "AVAILABLE"},           // RCAN_RELEASE, AVAILABLE for the window
      {"HELD", "EXPIRE", "AVAILABLE"},            // TTL reached without renewal
      {"HELD", "REVOKE", "AVAILABLE"},            // lease ended, ownership transferred
      {"HELD", "HANDOFF", "RESERVED"},            // named successor, window reserved
      {"RESERVED", "CLAIM", "HELD"},              // the named target claims
      {"RESERVED", "WINDOW_CLOSE", "AVAILABLE"},  // nobody came: first claim wins again
  };
  return t;
}

const std::vector<Transition>& ownership_transitions() {
  static const std::vector<Transition> t{
      {"OWNED", "TRANSFER_REQUEST", "TRANSFER_PENDING"},
      {"TRANSFER_PENDING", "TRANSFER_ACCEPT",
       "OWNED"},  // new owner recorded, personal data cleared
      {"TRANSFER_PENDING", "TRANSFER_CANCEL", "OWNED"},
      {"TRANSFER_PENDING", "TRANSFER_EXPIRE", "OWNED"},  // the window passed
  };
  return t;
}

namespace {
bool allowed(const std::vector<Transition>& t, std::string_view from, std::string_view ev,
             std::string_view to) {
  for (const auto& r : t)
    if (r.from == from && r.event == ev && r.to == to) return true;
  return false;
}
}  // namespace

bool control_transition_allowed(ControlState from, std::string_view event, ControlState to) {
  return allowed(control_transitions(), control_state_name(from), event, control_state_name(to));
}

bool ownership_transition_allowed(OwnershipState from, std::string_view event, OwnershipState to) {
  return allowed(ownership_transitions(), ownership_state_name(from), event,
                 ownership_state_name(to));
}

std::string mermaid(const std::vector<Transition>& table, std::string_view initial) {
  std::string s = "stateDiagram-v2\n    [*] --> " + std::string(initial) + "\n";
  for (const auto& r : table)
    s += "    " + std::string(r.from) + " --> " + std::string(r.to) + " : " + std::string(r.event) +
         "\n";
  return s;
}

}  // namespace rcan::node
