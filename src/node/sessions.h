// SessionTable — control sessions (seed §2.3, §4.3.5, §5.3), the part the node needs now:
//   * claim: a verified principal asks for control. No holder → GRANTED. A holder of a lower
//     role is pre-empted (higher role wins). Same or higher role held by someone else →
//     DENIED with CONTROL_CONFLICT (first claim wins). The same principal re-claiming renews
//     explicitly (never implicitly).
//   * a session lasts its role's TTL (roles.h) from the claim; expired sessions are gone;
//   * release ends it; only its holder (or a higher role) may release it;
//   * handoff (seed §2.3): the holder names a successor; the session ends and the robot is
//     AVAILABLE for a window (30 s) reserved for that successor: other claims are DENIED until
//     the window closes, after which first claim wins again. The successor's role still comes
//     from its own token, lowered to the role the handoff names, never raised.
// The role always comes from the verified token: a body can only ask for a lower role.
#pragma once

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "node/auth.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

struct Session {
  std::string id;
  std::string principal_key;
  std::string sub;
  Role role = Role::kGuest;
  int64_t granted_mono_ms = 0;
  int64_t expires_mono_ms = 0;  // 0 = never (CREATOR)
  int64_t granted_wall_ms = 0;
};

struct Reservation {
  std::string target_sub;
  std::optional<Role> max_role;     // the handoff's target_role (can only lower)
  std::string from_session;
  int64_t until_mono_ms = 0;
};

struct ClaimResult {
  Session session;
  std::optional<Session> preempted;  // the holder this claim displaced
  bool renewed = false;
};

class SessionTable {
 public:
  // Errors: CONTROL_CONFLICT naming the holder's role.
  Result<ClaimResult> claim(const Principal& p, std::optional<Role> requested, int64_t now_mono_ms,
                            int64_t now_wall_ms);
  // Errors: NOT_FOUND (no such session), INSUFFICIENT_PRIVILEGES (not the holder).
  Result<Session> release(const std::string& session_id, const Principal& p, int64_t now_mono_ms);
  // Ends the holder's session and reserves control for `target_sub` until now + window_ms.
  // Errors: NOT_FOUND (no such session), INSUFFICIENT_PRIVILEGES (not the holder).
  Result<Session> handoff(const std::string& session_id, const Principal& p, std::string target_sub,
                          std::optional<Role> target_role, int64_t window_ms, int64_t now_mono_ms);
  std::optional<Reservation> reservation(int64_t now_mono_ms);
  // The live controller, if any (expired ones are dropped first; returned in `expired`).
  std::optional<Session> controller(int64_t now_mono_ms, std::vector<Session>* expired = nullptr);
  std::optional<Session> find(const std::string& session_id, int64_t now_mono_ms);
  json::Value to_json(int64_t now_mono_ms, bool detailed);

 private:
  void expire_locked(int64_t now_mono_ms, std::vector<Session>* expired);
  std::mutex mu_;
  std::optional<Session> holder_;
  std::optional<Reservation> reserved_;
};

}  // namespace rcan::node
