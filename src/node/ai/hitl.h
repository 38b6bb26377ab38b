// HiTL (§16.4) pending items and AUTHORIZE requests: the data, its JSON forms and the
// pending file that lets held commands survive a restart.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rcan/base/env.h"
#include "rcan/json.h"
#include "rcan/result.h"
#include "rcan/roles.h"
#include "rcan/sender_identity.h"

namespace rcan::node {

// One held command.
struct PendingItem {
  std::string message_id;  // the held COMMAND's message_id (the pending id)
  std::string action_type;
  std::string description;
  uint32_t auth_timeout_ms = 30000;
  int64_t created_ms = 0;     // wall clock
  int64_t expires_at_ms = 0;  // wall clock
  bool allow_on_timeout = false;
  std::vector<Role> authorized_roles{Role::kOwner, Role::kCreator};
  std::vector<std::string> notify;
  // Enough to dispatch it later, also after a restart.
  json::Value message;  // the command, seed shape (encode_message)
  std::string issuer, sub;
  Role role = Role::kGuest;
  std::vector<std::string> scopes;
  SenderIdentity sender;
  std::string transport, route;
  json::Object audit_detail;
  bool gate_bypassed = false;
  std::string thought_id;
  std::optional<double> confidence;
  std::string model;

  std::string principal_key() const { return issuer + "\x1f" + sub; }
  // The stored form (pending file).
  json::Value to_json() const;
  static Result<PendingItem> from_json(const json::Value& v);
  // What GET /rcan/v1/pending and PENDING_AUTH show (no token, no full principal detail).
  json::Object public_view(int64_t now_ms) const;
};

// The pending file: {"version":1,"pending":[…]}. Written atomically (temp file, fsync,
// rename, directory fsync) with mode 0600, through base::Env::write_file_atomic of `env`
// (nullptr → base::Env::posix()). Errors: INTERNAL, naming the step, the file and errno.
Status save_pending(const std::string& path, const std::vector<PendingItem>& items,
                    base::Env* env = nullptr);
// A missing file is an empty list. Entries that do not parse are skipped (`skipped` counts them).
Result<std::vector<PendingItem>> load_pending(const std::string& path, size_t* skipped = nullptr);

// An AUTHORIZE, from POST /rcan/v1/authorize or the stream. Accepted forms:
//   {"type":"AUTHORIZE","message_id":…, "payload":{"message_id"|"ref_message_id"|"pending_id"|
//    "thought_id": …, "decision": "approve"|"deny" (also APPROVE, REJECT, reject, DENY),
//    "reason"?}}
//   or the payload members at the top level.
struct AuthorizeRequest {
  std::string authorize_id;  // the AUTHORIZE message's own message_id (generated when absent)
  std::string target;        // the held command's message_id (or thought_id)
  bool approve = false;
  std::string reason;
};
Result<AuthorizeRequest> parse_authorize(const json::Value& body);

}  // namespace rcan::node
