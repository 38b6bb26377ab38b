// AuditRecord: the one way the node writes an audit record. Start it from the AuditTrail
// (audit_trail.h) with the event and its outcome, say who (a principal, the system, or nobody
// authenticated), add what the record needs, then write it:
//
//   trail.record("STREAM_OPEN").by(principal).message(stream_id).detail("transport", "ws").write();
//   trail.record("PARTITION_MODE").by_system().reason("degraded").write();
//   trail.record("AUTH_FAILED", "blocked").reason("AUTH_INVALID").write();   // anonymous
//
// The robot's RURI, the time and a message id (a fresh one unless given) are filled in; the
// record is appended asynchronously (AuditTrail::write), and `write(cb)` calls `cb` once
// it is durable or has failed. `entry()` reaches the rarer fields (ai, gate flags).
#pragma once

#include <functional>
#include <string>

#include "node/admission/authenticator.h"
#include "rcan/audit/audit_log.h"
#include "rcan/json.h"
#include "rcan/sender_identity.h"

namespace rcan::node {

class AuditTrail;

class AuditRecord {
 public:
  AuditRecord(AuditTrail& trail, audit::AuditEntry e) : trail_(trail), e_(std::move(e)) {}

  // The principal of a verified token: `principal` is its display name, `sub` its subject.
  AuditRecord& by(const Principal& p) {
    e_.principal = p.display();
    e_.sub = p.sub;
    return *this;
  }
  // The node itself (sender_type system).
  AuditRecord& by_system() {
    e_.principal = "system";
    e_.sender_type = "system";
    return *this;
  }
  // A principal known by subject only (a session's holder, a HiTL requester).
  AuditRecord& by_subject(const std::string& sub) {
    e_.principal = sub.empty() ? "anonymous" : sub;
    if (!sub.empty()) e_.sub = sub;
    return *this;
  }
  // The §8.5 sender identity of a message: sender type, subject, cloud provider and function.
  AuditRecord& sender(const SenderIdentity& s) {
    e_.sender_type = std::string(sender_type_name(s.sender_type));
    if (!s.sub.empty()) e_.sub = s.sub;
    if (!s.cloud_provider.empty()) e_.cloud_provider = s.cloud_provider;
    if (!s.function_name.empty()) e_.function_name = s.function_name;
    return *this;
  }
  AuditRecord& message(const std::string& id) {
    if (!id.empty()) e_.message_id = id;
    return *this;
  }
  AuditRecord& reason(std::string r) {
    e_.reason = std::move(r);
    return *this;
  }
  AuditRecord& action(std::string a) {
    if (!a.empty()) e_.action = std::move(a);
    return *this;
  }
  AuditRecord& detail(const std::string& key, json::Value v) {
    e_.detail.set(key, std::move(v));
    return *this;
  }
  audit::AuditEntry& entry() { return e_; }

  // Appends the record (asynchronously); `cb` runs once it is durable or failed.
  void write(std::function<void(Result<audit::Receipt>)> cb = {});

 private:
  AuditTrail& trail_;
  audit::AuditEntry e_;
};

}  // namespace rcan::node
