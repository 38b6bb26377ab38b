// A robot joins its registry (config `registry`, docs/REGISTRY.md §A robot joins its registry).
//
// At start, when registry.key_file is set and no RRN is stored, rcand registers itself: it
// asks the registry for a challenge, signs it with both identity keys (proof of possession),
// and posts its names, keys and endpoint with the registrant key. The registry's RRN and the
// robot's own API key (shown once) are kept under <data-dir>/registry/ (the key 0600); from
// then on the RRN in status, mDNS and watermarks is the registry's. A registry that cannot be
// reached at start does not stop the robot: it serves under its local RRN, keeps trying in the
// background, and adopts the registry's RRN at its next start.
//
// While running, the robot tells the registry where it answers every registry.refresh_s
// (PATCH of its record's endpoints, with its own key).
#pragma once

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "config/config.h"
#include "rcan/audit/audit_log.h"
#include "rcan/crypto/keys.h"
#include "rcan/result.h"

namespace rcan::rcand {

// The RRN a registration stored in `data_dir`, or empty.
std::string stored_registry_rrn(const std::string& data_dir);

// One registration (challenge, proof, POST). Stores and returns the RRN; an already
// registered robot (the registry answers already_existed) keeps the RRN it is given.
Result<std::string> register_with_registry(const config::NodeConfig& cfg,
                                           const keys::RobotKeys& keys, int timeout_ms);

// The background link: registers when still needed, then refreshes the endpoint.
class RegistryLink {
 public:
  RegistryLink(const config::NodeConfig& cfg, const keys::RobotKeys& keys, audit::AuditLog& audit,
               std::string ruri);
  ~RegistryLink();
  RegistryLink(const RegistryLink&) = delete;
  RegistryLink& operator=(const RegistryLink&) = delete;

  void start();
  void stop();
  // What the last exchange with the registry did ("registered", "refreshed", or an error).
  std::string last_result() const;

 private:
  void run();
  bool refresh(const std::string& rrn);
  void record(const std::string& event, const std::string& outcome, const std::string& detail);

  const config::NodeConfig& cfg_;
  const keys::RobotKeys& keys_;
  audit::AuditLog& audit_;
  std::string ruri_;
  std::thread thread_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::string last_;
};

}  // namespace rcan::rcand
