// The control policy in-process (node/control/control_service.h): ControlService with a manual
// clock, a real audit log in a temporary directory, the event bus and a fake Actuation. Each
// test calls the operations a route calls, with parsed fields, and checks the answer, the audit
// records written and the events published.
#include "node/control/control_service.h"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "audit_util.h"
#include "base/clock.h"
#include "base/metrics.h"
#include "in_process_node.h"
#include "node/vocabulary/audit_trail.h"
#include "node/vocabulary/event_bus.h"
#include "rcan/audit/audit_log.h"
#include "rcan/json.h"
#include "test_support.h"

namespace rcan::node {
namespace {

constexpr const char* kRobot = "rcan://local.rcan/acme/rover/0a1b2c3d";
constexpr const char* kIss = "control-test";

Principal who(const std::string& sub, Role role) {
  Principal p;
  p.authenticated = true;
  p.issuer = kIss;
  p.sub = sub;
  p.role = role;
  p.scopes = {"status", "control", "config"};
  return p;
}

class ControlServiceTest : public ::testing::Test {
 protected:
  void SetUp() override { build(""); }
  void TearDown() override { tear_down(); }

  void tear_down() {
    if (control_) control_->stop();
    events_.unsubscribe(sub_);
    control_.reset();
    log_.reset();  // its writer may still run a record's callback into the trail
    trail_.reset();
  }

  // A ControlService over a fresh audit log; `state_dir` keeps the control state file.
  void build(const std::string& state_dir) {
    tear_down();
    audit::AuditOptions ao;
    ao.secret = "control-test-chain-secret-0123456789";
    ao.robot_ruri = kRobot;
    ao.preallocate = false;
    auto log = audit::AuditLog::open(dir_.file("audit-" + std::to_string(++builds_)), ao);
    ASSERT_TRUE(log.ok()) << log.error().message;
    log_ = std::move(log).value();
    trail_ = std::make_unique<AuditTrail>(kRobot, clock_, *log_, metrics_, state_dir);
    ControlSettings s;
    s.robot_name = "control-test";
    s.state_dir = state_dir;
    s.heartbeat_timeout_ms = 2000;
    control_ = std::make_unique<ControlService>(s, clock_, *trail_, events_, act_);
    sub_ = events_.subscribe([this](const Event& ev) {
      std::lock_guard<std::mutex> lock(mu_);
      published_.push_back(ev.body);
    });
  }

  // The durable records of `event`, once there are `expected` of them (or after 5 s).
  std::vector<json::Value> audited(const std::string& event, size_t expected = 1) {
    return audit::testutil::records_of(*log_, event, expected);
  }

  // The answer's record written and durable, as a route does before answering.
  static void commit(ControlAnswer& a) {
    ASSERT_TRUE(a.record.has_value());
    a.record->write();
  }

  // The events published with `name` in their "event" (or "type") field.
  std::vector<json::Value> events(const std::string& name) {
    std::lock_guard<std::mutex> lock(mu_);
    std::vector<json::Value> out;
    for (const auto& e : published_)
      if (json::string_field(e, "event") == name || json::string_field(e, "type") == name)
        out.push_back(e);
    return out;
  }

  static std::string detail(const json::Value& rec, const char* key) {
    const json::Value* d = rec.get("detail");
    return d ? json::string_field(*d, key) : std::string();
  }

  test::TempDir dir_;
  ManualClock clock_{1'750'000'000'000};
  Metrics metrics_;
  EventBus events_;
  test_node::FakeActuation act_;
  int builds_ = 0;
  std::unique_ptr<audit::AuditLog> log_;
  std::unique_ptr<AuditTrail> trail_;
  std::unique_ptr<ControlService> control_;
  uint64_t sub_ = 0;
  std::mutex mu_;
  std::vector<json::Value> published_;
};

TEST_F(ControlServiceTest, AClaimIsGrantedAndRecordedWithItsSession) {
  ControlAnswer a = control_->claim(who("alice", Role::kUser), {});
  ASSERT_FALSE(a.error) << a.error->message;
  EXPECT_EQ(a.status, 200);
  ASSERT_TRUE(a.envelope);
  EXPECT_EQ(*a.envelope, MessageType::kGranted);
  const std::string session = json::string_field(a.body, "session_id");
  EXPECT_FALSE(session.empty());
  EXPECT_EQ(json::string_field(a.body, "role"), "USER");
  EXPECT_EQ(a.body.get("expires_in")->as_int(), 3600);
  EXPECT_EQ(a.body.get("heartbeat_timeout_ms")->as_int(), 2000);
  commit(a);
  auto rec = audited("CLAIM");
  ASSERT_EQ(rec.size(), 1u);
  EXPECT_EQ(json::string_field(rec[0], "principal"), "alice");
  EXPECT_EQ(json::string_field(rec[0], "message_id"), session);
  auto state = events("CONTROL_STATE");
  ASSERT_EQ(state.size(), 1u);
  EXPECT_EQ(json::string_field(state[0], "state"), "HELD");
  ASSERT_TRUE(control_->sessions().controller(clock_.mono_ms()));
}

TEST_F(ControlServiceTest, LockdownDeniesNewSessionsButNotTheHoldersRenewal) {
  ControlAnswer held = control_->claim(who("alice", Role::kUser), {});
  ASSERT_FALSE(held.error);
  PartitionOptions po;
  po.issuer_url = "http://127.0.0.1:9/jwks";
  control_->partition().configure(po);
  control_->partition().record(false, clock_.wall_ms());
  ASSERT_EQ(control_->partition().mode(), NetMode::kLockdown);

  ControlAnswer bob = control_->claim(who("bob", Role::kOwner), {});
  ASSERT_TRUE(bob.error);
  EXPECT_EQ(bob.error->code, ErrorCode::kLockdown);
  auto denied = audited("CLAIM_DENIED");
  ASSERT_EQ(denied.size(), 1u);
  EXPECT_EQ(json::string_field(denied[0], "reason"), "LOCKDOWN");
  EXPECT_EQ(json::string_field(denied[0], "principal"), "bob");
  // Every record written while partitioned says it waits for a sync.
  EXPECT_EQ(detail(denied[0], "partition_mode"), "LOCKDOWN");

  ControlAnswer again = control_->claim(who("alice", Role::kUser), {});
  ASSERT_FALSE(again.error) << again.error->message;
  EXPECT_TRUE(again.body.get("renewed")->as_bool());
}

TEST_F(ControlServiceTest, OfflineOnlyCachedPrincipalsStartSessions) {
  PartitionOptions po;
  po.issuer_url = "http://127.0.0.1:9/jwks";
  po.key_ttl_ms = 60'000;
  control_->partition().configure(po);
  control_->partition().record(true, clock_.wall_ms());
  // alice's token is validated while the issuer is reachable; bob's never was.
  Principal alice = who("alice", Role::kUser);
  alice.token_exp = clock_.wall_ms() / 1000 + 3600;
  ControlAnswer first = control_->claim(alice, {});
  ASSERT_FALSE(first.error);
  ASSERT_FALSE(control_->release(alice, "").error);
  control_->partition().record(false, clock_.wall_ms() + 1);
  ASSERT_EQ(control_->partition().mode(), NetMode::kOfflineAutonomous);

  ControlAnswer bob = control_->claim(who("bob", Role::kUser), {});
  ASSERT_TRUE(bob.error);
  EXPECT_EQ(bob.error->code, ErrorCode::kLockdown);
  EXPECT_EQ(json::string_field(audited("CLAIM_DENIED").at(0), "reason"), "OFFLINE_UNCACHED");
  EXPECT_FALSE(control_->claim(alice, {}).error);
}

TEST_F(ControlServiceTest, AHigherRolePreemptsTheHolderWhoIsStoppedAndTold) {
  Principal user = who("alice", Role::kUser);
  ControlAnswer a = control_->claim(user, {});
  ASSERT_FALSE(a.error);
  const std::string displaced = json::string_field(a.body, "session_id");
  commit(a);
  ControlAnswer b = control_->claim(who("olga", Role::kOwner), {});
  ASSERT_FALSE(b.error) << b.error->message;
  EXPECT_EQ(json::string_field(b.body, "role"), "OWNER");
  commit(b);
  auto pre = audited("SESSION_PREEMPTED");
  ASSERT_EQ(pre.size(), 1u);
  EXPECT_EQ(json::string_field(pre[0], "message_id"), displaced);
  EXPECT_EQ(json::string_field(pre[0], "sub"), "alice");
  EXPECT_EQ(detail(pre[0], "by_role"), "OWNER");
  EXPECT_EQ(detail(audited("CLAIM", 2).at(1), "preempted_session"), displaced);
  auto told = events("PREEMPTED");
  ASSERT_EQ(told.size(), 1u);
  EXPECT_EQ(json::string_field(told[0], "session_id"), displaced);
}

TEST_F(ControlServiceTest, TheSameRoleQueuesAndIsPromotedWhenTheHolderReleases) {
  Principal alice = who("alice", Role::kUser), bob = who("bob", Role::kUser);
  ASSERT_FALSE(control_->claim(alice, {}).error);
  ControlAnswer q = control_->claim(bob, {});
  ASSERT_FALSE(q.error);
  EXPECT_EQ(q.status, 409);
  const json::Value* payload = q.body.get("payload");
  ASSERT_NE(payload, nullptr);
  EXPECT_EQ(payload->get("queue_position")->as_int(), 1);
  EXPECT_EQ(json::string_field(*payload, "error_code"), "CONTROL_CONFLICT");
  EXPECT_EQ(audited("CLAIM_QUEUED").size(), 1u);

  ControlAnswer r = control_->release(alice, "");
  ASSERT_FALSE(r.error);
  ASSERT_TRUE(r.envelope);
  EXPECT_EQ(*r.envelope, MessageType::kReleased);
  EXPECT_EQ(audited("RELEASE").size(), 1u);
  control_->tick();
  auto promoted = audited("CLAIM_PROMOTED");
  ASSERT_EQ(promoted.size(), 1u);
  EXPECT_EQ(json::string_field(promoted[0], "sub"), "bob");
  ASSERT_EQ(events("PROMOTED").size(), 1u);
  auto holder = control_->sessions().controller(clock_.mono_ms());
  ASSERT_TRUE(holder);
  EXPECT_EQ(holder->sub, "bob");
}

TEST_F(ControlServiceTest, ASessionExpiresOnTheClockAndItsMotionStops) {
  ControlAnswer a = control_->claim(who("alice", Role::kUser), {});
  ASSERT_FALSE(a.error);
  const std::string session = json::string_field(a.body, "session_id");
  clock_.advance(3599'000);
  control_->tick();
  EXPECT_TRUE(control_->sessions().controller(clock_.mono_ms()));
  clock_.advance(2'000);
  control_->tick();
  EXPECT_FALSE(control_->sessions().controller(clock_.mono_ms()));
  auto expired = audited("SESSION_EXPIRED");
  ASSERT_EQ(expired.size(), 1u);
  EXPECT_EQ(json::string_field(expired[0], "message_id"), session);
  auto ev = events("SESSION_EXPIRED");
  ASSERT_EQ(ev.size(), 1u);
  EXPECT_EQ(json::string_field(ev[0], "session_id"), session);
}

TEST_F(ControlServiceTest, RenewingNeedsTheSessionAndIsRecorded) {
  Principal alice = who("alice", Role::kUser);
  ControlAnswer missing = control_->renew(alice, {});
  ASSERT_TRUE(missing.error);
  EXPECT_EQ(missing.error->code, ErrorCode::kSchemaValidationFailed);
  ControlAnswer a = control_->claim(alice, {});
  RenewRequest r;
  r.session_id = json::string_field(a.body, "session_id");
  ControlAnswer renewed = control_->renew(who("bob", Role::kUser), r);
  ASSERT_TRUE(renewed.error);  // only the holder renews
  EXPECT_EQ(audited("RENEW_DENIED").size(), 1u);
  clock_.advance(1800'000);
  ControlAnswer ok = control_->renew(alice, r);
  ASSERT_FALSE(ok.error) << ok.error->message;
  EXPECT_EQ(ok.body.get("expires_in")->as_int(), 3600);
  commit(ok);
  EXPECT_EQ(audited("CLAIM_RENEWED").size(), 1u);
}

TEST_F(ControlServiceTest, ALeaseEndsOnTheClockAndItsGrantsWithIt) {
  Principal owner = who("olga", Role::kOwner), leasee = who("lee", Role::kLeasee);
  ControlAnswer lease = control_->grant_lease(owner, PrincipalId{kIss, "lee"}, 600);
  ASSERT_FALSE(lease.error) << lease.error->message;
  EXPECT_EQ(lease.status, 201);
  const std::string id = json::string_field(lease.body, "lease_id");
  ASSERT_FALSE(id.empty());
  commit(lease);
  EXPECT_EQ(detail(audited("LEASE_GRANTED").at(0), "leasee"), "lee");
  EXPECT_EQ(events("LEASE_GRANTED").size(), 1u);
  ControlAnswer grant =
      control_->grant_within_lease(leasee, id, PrincipalId{kIss, "uma"}, Role::kUser, 300);
  ASSERT_FALSE(grant.error) << grant.error->message;
  commit(grant);
  EXPECT_EQ(detail(audited("LEASE_ACCESS_GRANTED").at(0), "user_id"), "uma");

  clock_.advance(601'000);
  control_->tick();
  auto ended = audited("LEASE_ENDED");
  ASSERT_EQ(ended.size(), 1u);
  EXPECT_EQ(detail(ended[0], "lease_id"), id);
  EXPECT_EQ(events("LEASE_ENDED").size(), 1u);
  EXPECT_TRUE(control_->sessions().leases(clock_.wall_ms()).empty());
}

TEST_F(ControlServiceTest, AnOwnershipTransferIsRequestedAcceptedAndClearsSessions) {
  Principal olga = who("olga", Role::kOwner), nina = who("nina", Role::kUser);
  ASSERT_FALSE(control_->claim(who("alice", Role::kUser), {}).error);
  TransferRequest req;
  req.action = "request";
  req.new_owner = PrincipalId{kIss, "nina"};
  ControlAnswer asked = control_->transfer(olga, req);
  ASSERT_FALSE(asked.error) << asked.error->message;
  const std::string id = json::string_field(asked.body, "transfer_id");
  commit(asked);
  EXPECT_EQ(detail(audited("TRANSFER_REQUEST").at(0), "to"), "nina");

  TransferRequest wrong;
  wrong.action = "accept";
  wrong.transfer_id = id;
  ControlAnswer refused = control_->transfer(who("mallory", Role::kUser), wrong);
  ASSERT_TRUE(refused.error);
  EXPECT_EQ(detail(audited("TRANSFER_DENIED").at(0), "action"), "accept");

  TransferRequest accept = wrong;
  accept.agreement = "yes";
  ControlAnswer done = control_->transfer(nina, accept);
  ASSERT_FALSE(done.error) << done.error->message;
  EXPECT_EQ(json::string_field(done.body, "step"), "TRANSFER_ACCEPT");
  commit(done);
  auto rec = audited("TRANSFER_ACCEPT");
  ASSERT_EQ(rec.size(), 1u);
  EXPECT_EQ(detail(rec[0], "agreement"), "yes");
  EXPECT_EQ(events("TRANSFER_ACCEPT").size(), 1u);
  EXPECT_FALSE(control_->sessions().controller(clock_.mono_ms()));  // sessions cleared
  EXPECT_EQ(audited("SESSION_REVOKED").size(), 1u);
}

TEST_F(ControlServiceTest, AConsentRequestIsRecordedAndGrantedAsALease) {
  Principal agent = who("agent", Role::kGuest), olga = who("olga", Role::kOwner);
  ConsentRequest c;
  c.sender_type = "cloud_function";
  c.cloud_provider = "firebase";
  c.function_name = "castor-bridge";
  c.scopes = {"control"};
  c.duration_s = 600;
  c.reason = "inspection";
  ConsentRequest added;
  ControlAnswer asked = control_->request_consent(agent, c, "msg-1", &added);
  ASSERT_FALSE(asked.error) << asked.error->message;
  EXPECT_EQ(asked.status, 202);
  EXPECT_EQ(added.requester_sub, "agent");
  ASSERT_NE(asked.body.get("notification"), nullptr);
  commit(asked);
  auto rec = audited("CONSENT_REQUEST");
  ASSERT_EQ(rec.size(), 1u);
  EXPECT_EQ(json::string_field(rec[0], "message_id"), "msg-1");
  EXPECT_EQ(json::string_field(rec[0], "function_name"), "castor-bridge");
  EXPECT_EQ(detail(rec[0], "consent_id"), added.id);
  EXPECT_EQ(events("CONSENT_REQUEST").size(), 1u);
  EXPECT_EQ(control_->consent_requests().as_array().size(), 1u);

  ConsentDecision lease;
  lease.grant = true;
  ConsentDecision forever = lease;
  forever.kind = "forever";
  ControlAnswer bad = control_->decide_consent(olga, added.id, forever);
  ASSERT_TRUE(bad.error);
  ControlAnswer granted = control_->decide_consent(olga, added.id, lease);
  ASSERT_FALSE(granted.error) << granted.error->message;
  commit(granted);
  auto g = audited("CONSENT_GRANTED");
  ASSERT_EQ(g.size(), 1u);
  EXPECT_EQ(detail(g[0], "requester"), "agent");
  EXPECT_FALSE(detail(g[0], "lease_id").empty());
  EXPECT_EQ(events("CONSENT_GRANTED").size(), 1u);
  ASSERT_EQ(control_->sessions().leases(clock_.wall_ms()).size(), 1u);
  EXPECT_EQ(control_->sessions().leases(clock_.wall_ms()).front().leasee.sub, "agent");
}

TEST_F(ControlServiceTest, HandoffReservesControlForTheTarget) {
  Principal alice = who("alice", Role::kUser);
  ControlAnswer a = control_->claim(alice, {});
  HandoffRequest h;
  h.session_id = json::string_field(a.body, "session_id");
  h.target = PrincipalId{"", "bob"};
  ControlAnswer handed = control_->handoff(alice, h);
  ASSERT_FALSE(handed.error) << handed.error->message;
  EXPECT_EQ(*handed.envelope, MessageType::kAvailable);
  commit(handed);
  EXPECT_EQ(detail(audited("HANDOFF").at(0), "target_iss"), kIss);  // the holder's issuer
  EXPECT_EQ(json::string_field(events("AVAILABLE").at(0), "reserved_for"), "bob");
  EXPECT_TRUE(control_->claim(who("carol", Role::kUser), {}).error);
  EXPECT_FALSE(control_->claim(who("bob", Role::kUser), {}).error);
}

TEST_F(ControlServiceTest, TheControlStateFileKeepsLeasesAcrossARestart) {
  const std::string state = dir_.file("state");
  std::filesystem::create_directories(state);
  build(state);
  control_->start([] {});
  ControlAnswer lease =
      control_->grant_lease(who("olga", Role::kOwner), PrincipalId{kIss, "lee"}, 600);
  ASSERT_FALSE(lease.error);
  control_->stop();
  EXPECT_TRUE(std::filesystem::exists(state + "/leases.json"));
  build(state);
  control_->start([] {});
  auto leases = control_->sessions().leases(clock_.wall_ms());
  ASSERT_EQ(leases.size(), 1u);
  EXPECT_EQ(leases.front().leasee.sub, "lee");
}

}  // namespace
}  // namespace rcan::node
