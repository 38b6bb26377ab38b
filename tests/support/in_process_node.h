// An in-process node for tests: the node's real services, stages and audit log (in a
// temporary directory), a manual clock and a fake Actuation that records what reaches the
// robot. tests/node/pipeline_test.cpp drives its pipeline, tests/node/routes_test.cpp its HTTP
// route table.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "audit_util.h"
#include "base/clock.h"
#include "node/api/stage_order.h"
#include "node/pipeline/pipeline.h"
#include "node/safety/actuation.h"
#include "node/services/node_services.h"
#include "rcan/audit/audit_log.h"
#include "rcan/crypto/jwt.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan::node::test_node {

constexpr const char* kRuri = "rcan://local.rcan/acme/rover/0a1b2c3d";
constexpr const char* kIssuer = "pipeline-test";

// Records every call; prepare() accepts every known action as a drive, apply() answers "applied".
class FakeActuation final : public Actuation {
 public:
  bool estop_active() const override {
    std::lock_guard<std::mutex> lock(mu_);
    return latched_;
  }
  uint64_t estop_epoch() const override {
    std::lock_guard<std::mutex> lock(mu_);
    return estops_.size();
  }
  // The latch is "durable" at once.
  double estop(const std::string& source, const std::string&, Role, EstopLatchFn on_latch,
               bool) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      latched_ = true;
      estops_.push_back(source);
    }
    if (on_latch) on_latch(true, "");
    return 1.0;
  }
  Status resume(Role role, const std::string&) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (role_level(role) < role_level(Role::kLeasee))
      return Error(ErrorCode::kInsufficientPrivileges, "LEASEE or above");
    latched_ = false;
    ++resumes_;
    return Status::Ok();
  }
  void stop(const std::string&) override {
    std::lock_guard<std::mutex> lock(mu_);
    ++stops_;
  }
  Result<PreparedCommand> prepare(const Message&, const ActionSpec& spec, int64_t deadline_mono_ms,
                                  const std::string& session_id, std::optional<uint64_t>) override {
    PreparedCommand p;
    p.action_name = spec.name;
    p.action = json::Object{{"action", p.action_name}};
    p.deadline_mono_ms = deadline_mono_ms;
    p.session_id = session_id;
    return p;
  }
  Result<json::Value> apply(const PreparedCommand& cmd) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (latched_) return Error(ErrorCode::kCommandRejected, "ESTOP", "", "estop_active");
    applied_.push_back(cmd.action_name);
    return json::Value(json::Object{{"applied", cmd.action_name}});
  }
  void arm_deadman(const std::string&, int64_t) override {}
  void feed_deadman(const std::string&) override {}
  void disarm_deadman(const std::string&) override {}
  Status rearm(const std::string&) override { return Status::Ok(); }
  json::Value status() const override { return json::Object{{"fake", true}}; }
  json::Value telemetry() const override { return json::Object{}; }

  std::vector<std::string> applied() const {
    std::lock_guard<std::mutex> lock(mu_);
    return applied_;
  }
  size_t estops() const {
    std::lock_guard<std::mutex> lock(mu_);
    return estops_.size();
  }
  void latch() {
    std::lock_guard<std::mutex> lock(mu_);
    latched_ = true;
  }

 private:
  mutable std::mutex mu_;
  bool latched_ = false;
  std::vector<std::string> estops_;
  std::vector<std::string> applied_;
  int stops_ = 0;
  int resumes_ = 0;
};

class InProcessNode : public ::testing::Test {
 protected:
  void SetUp() override { build({}); }
  void TearDown() override { shut_down(); }

  // The audit log goes first: its writer may still run a record's callback, which reaches into
  // the services.
  void shut_down() {
    audit_.reset();
    pipeline_.reset();
    services_.reset();
  }

  // (Re)builds the node's services and pipeline; `tune` may change the settings first.
  void build(const std::function<void(NodeSettings&)>& tune) {
    shut_down();
    audit::AuditOptions ao;
    ao.secret = "pipeline-test-chain-secret-0123456789";
    ao.robot_ruri = kRuri;
    ao.max_segment_bytes = 1u << 20;
    ao.preallocate = false;
    auto log = audit::AuditLog::open(dir_.file("audit-" + std::to_string(++builds_)), ao);
    ASSERT_TRUE(log.ok()) << log.error().message;
    audit_ = std::move(log).value();

    auto signing = jwt::SigningKey::ed25519_seed(Bytes(32, 0x5a));
    ASSERT_TRUE(signing.ok());
    signing_ = std::make_unique<jwt::SigningKey>(std::move(signing).value());
    auto verify = signing_->verification_key();
    ASSERT_TRUE(verify.ok());
    AuthOptions auth;
    auth.trust.add(kIssuer, *verify);
    auth.verify.audience = kRuri;
    NodeSettings ns;
    ns.ruri = kRuri;
    ns.name = "pipeline-test";
    if (tune) tune(ns);
    services_ = std::make_unique<NodeServices>(ns, clock_, std::move(auth), actuation(), *audit_);
    pipeline_ = std::make_unique<Pipeline>(*services_, standard_stages(*services_));
  }

  // What the node's services act through: the fake unless a fixture brings its own.
  virtual Actuation& actuation() { return act_; }

  std::string token(const char* role, const char* sub,
                    json::Array scopes = {"status", "chat", "control", "config"}) {
    const int64_t now_s = Clock::system().wall_ms() / 1000;
    auto t = jwt::issue(json::Object{{"iss", kIssuer},
                                     {"sub", sub},
                                     {"aud", kRuri},
                                     {"role", role},
                                     {"scope", std::move(scopes)},
                                     {"iat", now_s},
                                     {"exp", now_s + 3600}},
                        *signing_);
    EXPECT_TRUE(t.ok());
    return t.ok() ? *t : std::string();
  }

  json::Value command(const std::string& action, json::Object params = {},
                      std::optional<std::string> id = std::nullopt) {
    json::Object payload{{"action", action}};
    for (const auto& [k, v] : params) payload.set(k, v);
    return json::Object{{"version", "1.0.0"},
                        {"message_id", id ? *id : new_uuid_v4()},
                        {"type", "COMMAND"},
                        {"timestamp_ms", clock_.wall_ms()},
                        {"payload", std::move(payload)}};
  }

  static std::string error_code(const Outcome& o) {
    const json::Value* p = o.body.get("payload");
    return p ? json::string_field(*p, "error_code") : std::string();
  }
  static std::string reason(const Outcome& o) {
    const json::Value* p = o.body.get("payload");
    return p ? json::string_field(*p, "reason") : std::string();
  }

  // The durable audit records of `event`, oldest first, once there are `expected` of them
  // (refusals are recorded asynchronously) or 5 s have passed.
  std::vector<json::Value> audited(const std::string& event, size_t expected) {
    return audit::testutil::records_of(*audit_, event, expected);
  }

  test::TempDir dir_;
  ManualClock clock_{Clock::system().wall_ms()};
  FakeActuation act_;
  int builds_ = 0;
  std::unique_ptr<jwt::SigningKey> signing_;
  std::unique_ptr<audit::AuditLog> audit_;
  std::unique_ptr<NodeServices> services_;
  std::unique_ptr<Pipeline> pipeline_;
};

}  // namespace rcan::node::test_node
